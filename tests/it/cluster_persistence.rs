//! A campaign on workers whose coordinator is killed with SIGKILL: rerun, or picked up by a
//! long-lived `calib coordinator --db`, it finishes with the uninterrupted result, and the
//! workers simulate no stored evaluation again.

use crate::common::cluster::*;
use crate::common::*;
use calib_engine::evaluator::{Evaluator, Fault, LocalEvaluator};
use calib_engine::objective::{Evaluation, Objective};
use calib_engine::store::{CampaignStatus, SledStore, Store};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Runs of the long campaign (one method, two starts) and its population (`max(15, 10 n)`
/// for two free parameters): each run has at most one generation in flight.
const RUNS: u64 = 2;
const POPULATION: u64 = 20;

/// A campaign that runs for a few seconds: differential evolution from two starts.
fn long_campaign(dir: &Path) -> PathBuf {
    let search =
        "methods = [\"differential-evolution\"]\nstarts = 2\nmax_evaluations = 1500\nseed = 5";
    write(dir, "long.toml", &clean_campaign(search))
}

/// `calib calibrate` on the cluster's workers, to completion; result.json.
fn calibrate_on(cluster: &TestCluster, campaign: &Path, db: &Path, out: &Path) -> Value {
    calibrate_json(campaign, db, out, &["--workers", &cluster.workers_arg()])
}

/// Start `calib calibrate` on the cluster's workers and SIGKILL it once it has reported
/// `enough` evaluations (each one stored before it is reported).
fn interrupt(cluster: &TestCluster, campaign: &Path, db: &Path, enough: u64) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
        .args([
            "calibrate",
            campaign.to_str().unwrap(),
            "--db",
            db.to_str().unwrap(),
            "--workers",
            &cluster.workers_arg(),
        ])
        .env("CALIB_PROGRESS", "lines")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (reported, reader) = watch_progress(&mut child);
    await_condition(
        "the calibration to store enough evaluations",
        Duration::from_secs(180),
        || reported.load(Ordering::SeqCst) >= enough,
    );
    child.kill().unwrap(); // SIGKILL on Unix
    let status = child.wait().unwrap();
    assert!(
        !status.success(),
        "the calibration finished before the kill"
    );
    reader.join().unwrap();
}

fn stored_evaluations(db: &Path) -> u64 {
    json_of(&calib(&[
        "store",
        "stats",
        "--db",
        db.to_str().unwrap(),
        "--json",
    ]))["evaluations"]
        .as_u64()
        .unwrap()
}

/// The resumed result is the uninterrupted one: best point and objective bit for bit, and
/// every run alike.
fn assert_same_result(resumed: &Value, fresh: &Value) {
    let bits = |v: &Value| v.as_f64().unwrap().to_bits();
    assert_eq!(
        bits(&resumed["best"]["objective"]),
        bits(&fresh["best"]["objective"])
    );
    let parameters = |v: &Value| -> Vec<(String, u64)> {
        v["best"]["parameters"]
            .as_object()
            .unwrap()
            .iter()
            .map(|(name, value)| (name.clone(), bits(value)))
            .collect()
    };
    assert_eq!(parameters(resumed), parameters(fresh));
    assert_eq!(resumed["runs"], fresh["runs"]);
    assert_eq!(resumed["nominal_objective"], fresh["nominal_objective"]);
}

/// An uninterrupted run on a fresh store, and the same campaign killed on another store:
/// (result, simulations of the killed run counted on the workers, evaluations it stored).
fn fresh_and_interrupted(
    cluster: &TestCluster,
    campaign: &Path,
    dir: &Path,
    db: &Path,
) -> (Value, u64, u64) {
    let fresh = calibrate_on(cluster, campaign, &dir.join("fresh-db"), &dir.join("fresh"));
    let simulated_fresh = fresh["simulated"].as_u64().unwrap();
    assert_eq!(
        cluster.settled_simulations(),
        simulated_fresh,
        "every simulation is counted on the workers"
    );

    let before = cluster.simulations();
    interrupt(cluster, campaign, db, simulated_fresh / 4);
    let simulated_before_kill = cluster.settled_simulations() - before;
    let stored = stored_evaluations(db);
    assert!(stored >= simulated_fresh / 4, "{stored}");
    assert!(stored < simulated_fresh, "{stored} of {simulated_fresh}");
    // Every stored evaluation was simulated once; beyond those, only the points in flight
    // at the kill: a batch is stored once all of it is answered, so at most the batch each
    // run was waiting for (one differential evolution generation).
    assert!(simulated_before_kill >= stored);
    assert!(
        simulated_before_kill - stored <= RUNS * POPULATION,
        "{simulated_before_kill} simulated, {stored} stored"
    );
    (fresh, simulated_before_kill, stored)
}

#[test]
fn a_cluster_calibration_killed_with_sigkill_resumes_without_repeating_a_simulation() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = long_campaign(dir.path());
    let cluster = TestCluster::start(2, 1);
    let db = dir.path().join("db");
    let (fresh, before_kill, stored) = fresh_and_interrupted(&cluster, &campaign, dir.path(), &db);
    let simulated_fresh = fresh["simulated"].as_u64().unwrap();

    let counted = cluster.simulations();
    let resumed = calibrate_on(&cluster, &campaign, &db, &dir.path().join("resumed"));
    let rerun = cluster.settled_simulations() - counted;
    assert_same_result(&resumed, &fresh);
    assert_eq!(
        resumed["simulated"].as_u64().unwrap(),
        simulated_fresh - stored,
        "every evaluation stored before the kill is served from the store"
    );
    assert_eq!(rerun, simulated_fresh - stored, "counted on the workers");
    println!(
        "killed after {stored} stored ({before_kill} simulated) of {simulated_fresh}; \
         the rerun simulated {rerun}: {} repeated, all in flight at the kill",
        before_kill + rerun - simulated_fresh
    );
}

#[test]
fn a_coordinator_started_on_the_store_finishes_the_campaign_on_its_own() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = long_campaign(dir.path());
    let cluster = TestCluster::start(2, 1);
    let db = dir.path().join("db");
    let (fresh, _, stored) = fresh_and_interrupted(&cluster, &campaign, dir.path(), &db);
    let simulated_fresh = fresh["simulated"].as_u64().unwrap();

    let counted = cluster.simulations();
    let out = dir.path().join("resumed");
    let mut coordinator = Command::new(env!("CARGO_BIN_EXE_calib"))
        .args([
            "coordinator",
            "--listen",
            "127.0.0.1:0",
            "--db",
            db.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
            "--workers",
            &cluster.workers_arg(),
        ])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // The results are written once the campaign is recorded finished.
    let result_file = out.join("clean").join("result.json");
    let mut resumed = Value::Null;
    await_condition(
        "the coordinator to write the resumed campaign's result",
        Duration::from_secs(180),
        || {
            if let Ok(Some(status)) = coordinator.try_wait() {
                panic!("the coordinator exited: {status}");
            }
            match std::fs::read(&result_file).map(|b| serde_json::from_slice::<Value>(&b)) {
                Ok(Ok(value)) => {
                    resumed = value;
                    true
                }
                _ => false,
            }
        },
    );
    coordinator.kill().unwrap();
    coordinator.wait().unwrap();
    let rerun = cluster.settled_simulations() - counted;

    assert_same_result(&resumed, &fresh);
    assert_eq!(
        resumed["simulated"].as_u64().unwrap(),
        simulated_fresh - stored
    );
    assert_eq!(rerun, simulated_fresh - stored, "counted on the workers");
    let store = SledStore::open(&db).unwrap();
    let campaigns = store.campaigns().unwrap();
    assert_eq!(campaigns.len(), 1);
    assert_eq!(campaigns[0].1.status, CampaignStatus::Finished);
    assert_eq!(store.stats().unwrap().evaluations, simulated_fresh);
}

#[test]
fn a_campaign_whose_only_worker_dies_fails_loudly_and_resumes_once_a_worker_is_back() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = long_campaign(dir.path());
    let mut first = TestCluster::start(1, 1);
    let fresh = calibrate_on(
        &first,
        &campaign,
        &dir.path().join("fresh-db"),
        &dir.path().join("fresh"),
    );
    let simulated_fresh = fresh["simulated"].as_u64().unwrap();

    // The only worker dies mid-run: the campaign waits 2 s for one, then fails.
    let db = dir.path().join("db");
    let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
        .args([
            "calibrate",
            campaign.to_str().unwrap(),
            "--db",
            db.to_str().unwrap(),
            "--workers",
            &first.workers_arg(),
            "--wait-for-workers",
            "2",
        ])
        .env("CALIB_PROGRESS", "lines")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (reported, reader) = watch_progress(&mut child);
    await_condition(
        "the calibration to store a quarter of its evaluations",
        Duration::from_secs(180),
        || reported.load(Ordering::SeqCst) >= simulated_fresh / 4,
    );
    first.workers[0].kill();
    let status = child.wait().unwrap();
    let stderr = reader.join().unwrap().join("\n");
    assert_eq!(status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains("error: evaluations stopped: no worker available"),
        "{stderr}"
    );
    // While it waited, it said what for.
    assert!(
        stderr.contains("workers: no worker up, waiting up to 2 s: 0 of 1 up; http://"),
        "{stderr}"
    );
    let stored = stored_evaluations(&db);
    assert!(stored >= simulated_fresh / 4, "{stored}");
    assert!(stored < simulated_fresh, "{stored} of {simulated_fresh}");
    {
        // No penalty was stored in place of the missing points: the campaign is still open.
        let store = SledStore::open(&db).unwrap();
        let campaigns = store.campaigns().unwrap();
        assert_eq!(campaigns.len(), 1);
        assert_eq!(campaigns[0].1.status, CampaignStatus::Running);
    }

    // A worker is back (another one, elsewhere): the rerun simulates exactly what is missing
    // and ends where the uninterrupted run did.
    let second = TestCluster::start(1, 1);
    let resumed = calibrate_on(&second, &campaign, &db, &dir.path().join("resumed"));
    assert_same_result(&resumed, &fresh);
    assert_eq!(
        resumed["simulated"].as_u64().unwrap(),
        simulated_fresh - stored,
        "no stored evaluation is simulated again"
    );
    assert_eq!(second.settled_simulations(), simulated_fresh - stored);
    assert_eq!(stored_evaluations(&db), simulated_fresh);
    println!(
        "stopped after {stored} of {simulated_fresh} stored; the rerun simulated {}",
        simulated_fresh - stored
    );
}

/// Evaluates in this process until `limit` points were asked for, then every batch is a
/// fault: the workers went away.
struct WorkersLostAfter {
    limit: usize,
    done: std::sync::atomic::AtomicUsize,
}

impl Evaluator for WorkersLostAfter {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        if self.done.fetch_add(points.len(), Ordering::SeqCst) >= self.limit {
            return Err(Fault::unavailable("no worker available"));
        }
        LocalEvaluator.evaluate(objective, points)
    }
}

#[test]
fn a_coordinator_resumes_a_faulted_campaign_again_once_a_worker_registers() {
    use calib_engine::calibration::calibrate_with_store;
    use calib_engine::campaign::Campaign;
    use calib_engine::optim::problem::Silent;
    use calib_engine::store::MemoryStore;
    use calib_service::dispatch::DispatchConfig;
    use calib_service::server::{serve_coordinator, CoordinatorConfig};

    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\", \"powell\"]\nstarts = 2\nmax_evaluations = 100";
    let campaign =
        Campaign::load(&write(dir.path(), "clean.toml", &clean_campaign(search))).unwrap();
    let reference =
        calibrate_with_store(&campaign, LocalEvaluator, &MemoryStore::new(), &Silent).unwrap();
    let db = dir.path().join("db");
    let stored = {
        let store = SledStore::open(&db).unwrap();
        let lost = WorkersLostAfter {
            limit: 60,
            done: Default::default(),
        };
        let error = calibrate_with_store(&campaign, &lost, &store, &Silent).err();
        assert!(
            matches!(error, Some(calib_engine::Error::Fault(_))),
            "{:?}",
            error.map(|e| e.to_string())
        );
        store.stats().unwrap().evaluations
    };
    assert!(
        stored >= 60 && stored < reference.stats.simulated,
        "{stored}"
    );

    // A coordinator on the store with no worker: its first pass stops on the fault.
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let out = dir.path().join("out");
    let mut dispatch = DispatchConfig::new(Vec::new());
    dispatch.probe_interval = Duration::from_millis(100);
    dispatch.wait_for_workers = Duration::from_millis(300);
    dispatch.heartbeat = Duration::from_secs(1);
    let mut config = CoordinatorConfig::new("127.0.0.1:0".parse().unwrap(), dispatch);
    config.store = Some(db.clone());
    config.results = Some(out.clone());
    let coordinator = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        serve_coordinator(listener, config).unwrap()
    });
    await_condition(
        "the first resume to stop for want of workers",
        Duration::from_secs(30),
        || coordinator.resume_passes() >= 1,
    );
    let result_file = out.join("clean").join("result.json");
    assert!(!result_file.exists());

    // A worker registers: the campaign is resumed and finishes with the reference result.
    let worker = TestWorker::start_registered(1, &format!("http://{}", coordinator.address()));
    let mut resumed = Value::Null;
    await_condition(
        "the coordinator to finish the campaign on the registered worker",
        Duration::from_secs(120),
        || match std::fs::read(&result_file).map(|b| serde_json::from_slice::<Value>(&b)) {
            Ok(Ok(value)) => {
                resumed = value;
                true
            }
            _ => false,
        },
    );
    let bits = |v: &Value| v.as_f64().unwrap().to_bits();
    assert_eq!(
        bits(&resumed["best"]["objective"]),
        reference.best_run().objective.to_bits()
    );
    assert_eq!(
        resumed["simulated"].as_u64().unwrap(),
        reference.stats.simulated - stored
    );
    assert_eq!(worker.simulations(), reference.stats.simulated - stored);
    await_condition(
        "the second pass to end with nothing left to resume",
        Duration::from_secs(10),
        || coordinator.resume_passes() >= 2,
    );
    runtime.block_on(coordinator.shutdown());
}
