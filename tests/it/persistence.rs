//! The evaluation store across runs and processes: repeated campaigns, a coordinator killed
//! with SIGKILL and restarted, model version changes, export and import, resume.

use crate::common::*;
use calib_engine::calibration::{calibrate_with_store, resume_unfinished};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::{Evaluator, Fault, LocalEvaluator};
use calib_engine::objective::{Evaluation, Objective};
use calib_engine::optim::problem::Silent;
use calib_engine::store::{CampaignStatus, MemoryStore, SledStore, Store};
use calib_model::Run;
use calib_model::{Model, ModelInfo, SimulationError, Trajectory};
use serde_json::Value;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Duration;

/// Calibrate `campaign` with the CLI on store `db`, results in `out`; result.json.
fn calibrate_cli(campaign: &Path, db: &Path, out: &Path) -> Value {
    calibrate_json(campaign, db, out, &[])
}

/// What must not change between an interrupted and an uninterrupted run.
fn outcome(result: &Value) -> (Value, Value, Value, Value) {
    (
        result["best"].clone(),
        result["runs"].clone(),
        result["clusters"].clone(),
        result["nominal_objective"].clone(),
    )
}

fn store_stats(db: &Path) -> Value {
    json_of(&calib(&[
        "store",
        "stats",
        "--db",
        db.to_str().unwrap(),
        "--json",
    ]))
}

#[test]
fn a_repeated_campaign_is_served_from_the_store() {
    let dir = tempfile::tempdir().unwrap();
    let search =
        "methods = [\"nelder-mead\", \"powell\"]\nstarts = 2\nmax_evaluations = 150\nseed = 4";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let db = dir.path().join("db");
    let first = calibrate_cli(&campaign, &db, &dir.path().join("out1"));
    let second = calibrate_cli(&campaign, &db, &dir.path().join("out2"));
    let simulated = first["simulated"].as_u64().unwrap();
    assert!(simulated > 50, "{simulated}");
    assert_eq!(second["simulated"], 0);
    assert!(second["cached"].as_u64().unwrap() >= second["evaluations"].as_u64().unwrap());
    assert_eq!(outcome(&first), outcome(&second));

    let stats = store_stats(&db);
    assert_eq!(stats["evaluations"].as_u64().unwrap(), simulated);
    assert_eq!(stats["campaigns"], 1);
    assert_eq!(stats["datasets"], 1);
    assert_eq!(stats["misses"].as_u64().unwrap(), simulated);
    assert!(stats["hits"].as_u64().unwrap() >= second["cached"].as_u64().unwrap());
    assert!(stats["bytes"].as_u64().unwrap() > 0);
}

/// A campaign that runs for a few seconds: differential evolution with a large budget.
const LONG_SEARCH: &str =
    "methods = [\"differential-evolution\"]\nstarts = 2\nmax_evaluations = 3000\nseed = 5";

#[test]
fn a_calibration_killed_with_sigkill_resumes_without_repeating_a_simulation() {
    killed_and_resumed(LONG_SEARCH);
}

/// CMA-ES (large populations, so the campaign lasts a few seconds) killed and resumed: the
/// same runs, rounds included, bit for bit.
#[test]
fn a_cma_es_calibration_killed_with_sigkill_resumes_bit_identically() {
    killed_and_resumed(
        "methods = [\"cma-es\"]\nstarts = 2\nmax_evaluations = 3000\nseed = 5\n\
         cma_population = 48",
    );
}

/// Levenberg–Marquardt (many starts, so the campaign lasts a few seconds) killed and resumed:
/// the same runs, rounds included, bit for bit, its residual entries served from the store.
#[test]
fn a_levenberg_marquardt_calibration_killed_with_sigkill_resumes_bit_identically() {
    killed_and_resumed(
        "methods = [\"levenberg-marquardt\"]\nstarts = 32\nmax_evaluations = 400\nseed = 5",
    );
}

/// Calibrate the clean campaign of `search` once on a fresh store, then again on another
/// store killed (SIGKILL) a quarter of the way and resumed: the same outcome, and nothing
/// stored simulated again.
fn killed_and_resumed(search: &str) {
    let dir = tempfile::tempdir().unwrap();
    let campaign = write(dir.path(), "long.toml", &clean_campaign(search));
    let fresh = calibrate_cli(
        &campaign,
        &dir.path().join("fresh-db"),
        &dir.path().join("a"),
    );
    let simulated_fresh = fresh["simulated"].as_u64().unwrap();

    // Start the same campaign on another store and kill it once it has stored a good part.
    let db = dir.path().join("db");
    let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
        .args([
            "calibrate",
            campaign.to_str().unwrap(),
            "--db",
            db.to_str().unwrap(),
            "--out",
            dir.path().join("b").to_str().unwrap(),
        ])
        .env("CALIB_PROGRESS", "lines")
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (reported, reader) = watch_progress(&mut child);
    let enough = simulated_fresh / 4;
    await_condition(
        "the child to store a quarter of the campaign",
        Duration::from_secs(120),
        || reported.load(Ordering::SeqCst) >= enough,
    );
    child.kill().unwrap(); // SIGKILL on Unix
    let status = child.wait().unwrap();
    assert!(!status.success(), "the child finished before the kill");
    reader.join().unwrap();

    let stored = store_stats(&db)["evaluations"].as_u64().unwrap();
    assert!(
        stored >= enough.min(reported.load(Ordering::SeqCst)) / 2,
        "{stored}"
    );
    assert!(stored < simulated_fresh, "{stored} of {simulated_fresh}");

    let resumed = calibrate_cli(&campaign, &db, &dir.path().join("b"));
    assert_eq!(outcome(&resumed), outcome(&fresh));
    assert_eq!(
        resumed["simulated"].as_u64().unwrap(),
        simulated_fresh - stored,
        "every evaluation stored before the kill is served from the store"
    );
    println!(
        "killed after {stored} of {simulated_fresh} evaluations; the rerun simulated {}",
        resumed["simulated"]
    );
}

#[test]
fn an_exported_store_imported_elsewhere_serves_the_campaign() {
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\"]\nstarts = 2\nmax_evaluations = 120\nseed = 2";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let (db, copy) = (dir.path().join("db"), dir.path().join("copy"));
    let first = calibrate_cli(&campaign, &db, &dir.path().join("out1"));

    let exported = calib(&["store", "export", "--db", db.to_str().unwrap()]);
    assert!(exported.status.success(), "{exported:?}");
    assert!(exported
        .stdout
        .starts_with(br#"{"format":"calib-store","version":1}"#));
    let imported = calib_with_input(
        &["store", "import", "--db", copy.to_str().unwrap()],
        &exported.stdout,
    );
    assert!(imported.status.success(), "{imported:?}");
    assert_eq!(
        store_stats(&copy)["evaluations"],
        store_stats(&db)["evaluations"]
    );

    let again = calibrate_cli(&campaign, &copy, &dir.path().join("out2"));
    assert_eq!(again["simulated"], 0);
    assert_eq!(outcome(&first), outcome(&again));

    // A damaged export is refused as bad input.
    let cut = &exported.stdout[..exported.stdout.len() - 40];
    let refused = calib_with_input(
        &[
            "store",
            "import",
            "--db",
            dir.path().join("x").to_str().unwrap(),
        ],
        cut,
    );
    assert_eq!(refused.status.code(), Some(2), "{refused:?}");
}

#[test]
fn a_store_in_use_is_reported() {
    let dir = tempfile::tempdir().unwrap();
    let _held = SledStore::open(&dir.path().join("db")).unwrap();
    let out = calib(&[
        "store",
        "stats",
        "--db",
        dir.path().join("db").to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("in use by another process"),
        "{out:?}"
    );
}

/// The furuta model under the next version number (same physics).
struct NextVersion {
    inner: &'static dyn Model,
    info: ModelInfo,
}

impl Model for NextVersion {
    fn info(&self) -> &ModelInfo {
        &self.info
    }
    fn simulate(&self, run: &Run) -> Result<Trajectory, SimulationError> {
        self.inner.simulate(run)
    }
}

fn small_campaign(dir: &Path) -> Campaign {
    let search = "methods = [\"nelder-mead\"]\nstarts = 1\nmax_evaluations = 60";
    Campaign::load(&write(dir, "small.toml", &clean_campaign(search))).unwrap()
}

#[test]
fn a_new_model_version_misses_the_old_entries() {
    let dir = tempfile::tempdir().unwrap();
    let store = MemoryStore::new();
    let mut campaign = small_campaign(dir.path());
    let first = calibrate_with_store(&campaign, LocalEvaluator, &store, &Silent).unwrap();
    assert!(first.stats.simulated > 0);

    let mut info = campaign.model.info().clone();
    info.version += 1;
    campaign.model = Box::leak(Box::new(NextVersion {
        inner: campaign.model,
        info,
    }));
    let bumped = calibrate_with_store(&campaign, LocalEvaluator, &store, &Silent).unwrap();
    // Everything is simulated again (the only points served from the store are the
    // campaign's own repeats, as in the first run).
    assert_eq!(bumped.stats.simulated, first.stats.simulated);
    assert_eq!(bumped.stats.cached, first.stats.cached);
    let stats = store.stats().unwrap();
    assert_eq!(stats.evaluations, 2 * first.stats.simulated);
    assert_eq!(stats.campaigns, 2);
}

/// Simulates like [`LocalEvaluator`] until it has simulated `limit` points, then crashes,
/// as a process killed mid-campaign would.
struct CrashesAfter {
    limit: usize,
    done: AtomicUsize,
}

impl Evaluator for CrashesAfter {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        if self.done.fetch_add(points.len(), Ordering::SeqCst) >= self.limit {
            panic!("simulated crash");
        }
        LocalEvaluator.evaluate(objective, points)
    }
}

#[test]
fn unfinished_campaigns_resume_from_the_store_even_when_their_data_moved() {
    let dir = tempfile::tempdir().unwrap();
    // The campaign reads its own copy of the data, removed before the resume.
    let data = dir.path().join("record.csv");
    std::fs::copy(repo().join("examples/data/furuta_clean.csv"), &data).unwrap();
    let search = "methods = [\"nelder-mead\", \"powell\"]\nstarts = 2\nmax_evaluations = 100";
    let text = clean_campaign(search).replace(
        &repo()
            .join("examples/data/furuta_clean.csv")
            .display()
            .to_string(),
        &data.display().to_string(),
    );
    let campaign = Campaign::load(&write(dir.path(), "moving.toml", &text)).unwrap();

    let reference =
        calibrate_with_store(&campaign, LocalEvaluator, &MemoryStore::new(), &Silent).unwrap();

    let db = dir.path().join("db");
    {
        let store = SledStore::open(&db).unwrap();
        let crashing = CrashesAfter {
            limit: 60,
            done: AtomicUsize::new(0),
        };
        let crashed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            calibrate_with_store(&campaign, &crashing, &store, &Silent)
        }));
        assert!(crashed.is_err(), "the campaign should have crashed");
    }
    std::fs::remove_file(&data).unwrap();

    let store = SledStore::open(&db).unwrap();
    let stored = store.stats().unwrap().evaluations;
    assert!(stored >= 60, "{stored}");
    let campaigns = store.campaigns().unwrap();
    assert_eq!(campaigns.len(), 1);
    assert_eq!(campaigns[0].1.status, CampaignStatus::Running);

    let resumed = resume_unfinished(&store, &LocalEvaluator, &Silent).unwrap();
    assert_eq!(resumed.len(), 1);
    let c = &resumed[0];
    assert_eq!(c.stats.simulated, reference.stats.simulated - stored);
    assert_eq!(c.best_run().point, reference.best_run().point);
    for (a, b) in c.runs.iter().zip(&reference.runs) {
        assert_eq!(a.objective.to_bits(), b.objective.to_bits());
        assert_eq!(a.evaluations, b.evaluations);
    }
    let record = &store.campaigns().unwrap()[0].1;
    assert_eq!(record.status, CampaignStatus::Finished);
    assert_eq!(record.runs.len(), 4);
    assert!(record.result.is_some());

    // Nothing is left to resume.
    assert!(resume_unfinished(&store, &LocalEvaluator, &Silent)
        .unwrap()
        .is_empty());
}

/// The ways a store's files get damaged: each applied to a copy of a store a small run
/// made, by name.
fn damage(db: &Path, how: &str) {
    let log = db.join("db");
    match how {
        "log truncated to nothing" => {
            std::fs::File::options()
                .write(true)
                .open(&log)
                .unwrap()
                .set_len(0)
                .unwrap();
        }
        "log truncated in the middle" => {
            let len = std::fs::metadata(&log).unwrap().len();
            std::fs::File::options()
                .write(true)
                .open(&log)
                .unwrap()
                .set_len(len / 2)
                .unwrap();
        }
        "log overwritten with random bytes" => {
            use rand::{RngCore, SeedableRng};
            let len = std::fs::metadata(&log).unwrap().len() as usize;
            let mut bytes = vec![0u8; len];
            rand_chacha::ChaCha8Rng::seed_from_u64(27).fill_bytes(&mut bytes);
            std::fs::write(&log, bytes).unwrap();
        }
        "config missing" => std::fs::remove_file(db.join("conf")).unwrap(),
        "blobs missing" => std::fs::remove_dir_all(db.join("blobs")).unwrap(),
        "snapshot overwritten with random bytes" => {
            use rand::{RngCore, SeedableRng};
            for entry in std::fs::read_dir(db).unwrap() {
                let path = entry.unwrap().path();
                if path
                    .file_name()
                    .unwrap()
                    .to_str()
                    .unwrap()
                    .starts_with("snap.")
                {
                    let mut bytes = vec![0u8; 64];
                    rand_chacha::ChaCha8Rng::seed_from_u64(13).fill_bytes(&mut bytes);
                    std::fs::write(&path, bytes).unwrap();
                }
            }
        }
        other => panic!("unknown damage {other}"),
    }
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(from).unwrap() {
        let entry = entry.unwrap();
        let target = to.join(entry.file_name());
        if entry.file_type().unwrap().is_dir() {
            copy_dir(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), &target).unwrap();
        }
    }
}

/// What a damage does to a store, as sled 0.34 reads it.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Damage {
    /// sled cannot read it: every command stops with exit code 1, naming the store.
    Unreadable,
    /// sled rebuilds what is missing (its config, an empty blob folder): every evaluation
    /// is still there, and a campaign is served from it.
    Rebuilt,
}

/// Every command on a damaged store stops with exit code 1 and a message naming the
/// store and what to do, never with a crash (sled panics on some of these); a damage sled
/// repairs by itself loses nothing. Each damage's outcome is stated: none may pass as the
/// other.
#[test]
fn a_damaged_store_is_an_error_that_says_what_to_do() {
    let dir = tempfile::tempdir().unwrap();
    // A store over a few of sled's segments, with a snapshot that later writes outdate:
    // on such a store sled 0.34 panics when the log is cut.
    let search = "methods = [\"differential-evolution\"]\nstarts = 3\nmax_evaluations = 8000";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let search =
        "methods = [\"differential-evolution\"]\nstarts = 1\nmax_evaluations = 3000\nseed = 9";
    let later = write(dir.path(), "later.toml", &clean_campaign(search));
    let made = dir.path().join("made");
    let first = calibrate_cli(&campaign, &made, &dir.path().join("out"));
    store_stats(&made);
    calibrate_cli(&later, &made, &dir.path().join("out"));
    let whole = store_stats(&made)["evaluations"].clone();
    for (index, (how, expected)) in [
        ("log truncated to nothing", Damage::Unreadable),
        ("log truncated in the middle", Damage::Unreadable),
        ("log overwritten with random bytes", Damage::Unreadable),
        ("config missing", Damage::Rebuilt),
        ("blobs missing", Damage::Rebuilt),
        ("snapshot overwritten with random bytes", Damage::Unreadable),
    ]
    .into_iter()
    .enumerate()
    {
        let db = dir.path().join(format!("damaged{index}"));
        copy_dir(&made, &db);
        damage(&db, how);
        let db_arg = db.to_str().unwrap();
        let out = dir.path().join(format!("out{index}"));
        if expected == Damage::Rebuilt {
            assert_eq!(store_stats(&db)["evaluations"], whole, "{how}");
            let again = calibrate_cli(&campaign, &db, &out);
            assert_eq!(again["simulated"], 0, "{how}: served from the store");
            assert_eq!(outcome(&again), outcome(&first), "{how}");
            continue;
        }
        for args in [
            vec!["store", "stats", "--db", db_arg],
            vec!["store", "export", "--db", db_arg],
            vec![
                "calibrate",
                campaign.to_str().unwrap(),
                "--db",
                db_arg,
                "--out",
                out.to_str().unwrap(),
            ],
        ] {
            let run = calib(&args);
            let stderr = String::from_utf8_lossy(&run.stderr);
            eprintln!(
                "{how}, {}: {:?} {stderr}",
                args[..2].join(" "),
                run.status.code()
            );
            assert_eq!(run.status.code(), Some(1), "{how}, {args:?}: {stderr}");
            assert!(!stderr.contains("panicked"), "{how}, {args:?}: {stderr}");
            assert!(
                !stderr.contains("RUST_BACKTRACE"),
                "{how}, {args:?}: {stderr}"
            );
            assert!(
                stderr.contains(&format!("the store at {db_arg} is damaged")),
                "{how}, {args:?}: {stderr}"
            );
            assert!(stderr.contains("backup"), "{how}, {args:?}: {stderr}");
        }
    }
}
