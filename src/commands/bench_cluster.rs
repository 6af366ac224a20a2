//! `calib bench --cluster`: what dispatching over gRPC costs and how it scales, measured
//! with workers serving in this process on loopback.
//!
//! - overhead: a batch of `furuta` evaluations over one worker versus in this process, on
//!   the same cores;
//! - scaling: evaluations per second of a ≥ 5 ms model (`hx_highfi`) with one and two
//!   single-slot workers;
//! - the coordinator's own CPU per evaluation: batches of `furuta` evaluations through the
//!   evaluation store to a `calib worker` in another process, the CPU time of this process
//!   (getrusage) divided by the points simulated;
//! - dispatcher capacity: many workers that only sleep, so that what limits the rate is
//!   the coordinator's dispatch, not the simulations.
//!
//! The in-process workers are those of the tests' sandbox (`calib-sandbox`).

use super::bench::Report;
use super::{Failure, Outcome};
use calib_engine::calibration;
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::{Evaluator, LocalEvaluator};
use calib_engine::objective::Objective;
use calib_engine::store::{SledStore, StoredEvaluator};
use calib_model::Run;
use calib_model::{models, SolverOptions};
use calib_sandbox::{NappingCluster, SandboxCluster};
use calib_service::dispatch::RemoteWorkers;
use std::path::Path;
use std::time::{Duration, Instant};

/// A pool over the sandbox workers at `urls`, once every one is up.
fn connect(urls: &[String]) -> Result<RemoteWorkers, Failure> {
    calib_sandbox::connect(urls).map_err(Failure::internal)
}

/// `n` distinct points around the nominal point.
fn points(objective: &Objective, n: usize) -> Vec<Vec<f64>> {
    (0..n)
        .map(|i| {
            objective
                .free
                .iter()
                .flatten()
                .map(|&f| objective.base[f] * (1.0 + 1e-3 * i as f64 / n as f64))
                .collect()
        })
        .collect()
}

/// Points `first..first + n` of a sequence of distinct points around the nominal point
/// (relative steps of 1e-9).
fn points_from(objective: &Objective, first: usize, n: usize) -> Vec<Vec<f64>> {
    (first..first + n)
        .map(|i| {
            objective
                .free
                .iter()
                .flatten()
                .map(|&f| objective.base[f] * (1.0 + 1e-9 * i as f64))
                .collect()
        })
        .collect()
}

/// Median wall time of evaluating `points` with `evaluator`.
fn time_batch(
    evaluator: &dyn Evaluator,
    objective: &Objective,
    points: &[Vec<f64>],
    repeat: usize,
) -> Duration {
    let mut samples: Vec<Duration> = (0..repeat.max(1))
        .map(|_| {
            let start = Instant::now();
            let evaluations = evaluator
                .evaluate(objective, points)
                .unwrap_or_else(|fault| panic!("the bench's workers failed: {fault}"));
            let elapsed = start.elapsed();
            assert!(
                evaluations.iter().all(|e| e.failure.is_none()),
                "{:?}",
                evaluations[0].failure
            );
            elapsed
        })
        .collect();
    samples.sort();
    samples[samples.len() / 2]
}

/// Median wall times of evaluating `points` with `a` and with `b`, the two taken in turn so
/// that both see the same load of a shared machine.
fn time_pair(
    a: &dyn Evaluator,
    b: &dyn Evaluator,
    objective: &Objective,
    points: &[Vec<f64>],
    repeat: usize,
) -> (Duration, Duration) {
    let (mut first, mut second) = (Vec::new(), Vec::new());
    for _ in 0..repeat.max(1) {
        first.push(time_batch(a, objective, points, 1));
        second.push(time_batch(b, objective, points, 1));
    }
    first.sort();
    second.sort();
    (first[first.len() / 2], second[second.len() / 2])
}

fn objective_of(campaign: &Path) -> Result<Objective, Failure> {
    let campaign = Campaign::load(campaign).map_err(|e| Failure::input(e.to_string()))?;
    let measurement = calibration::load_measurement(&campaign)?;
    Objective::new(&campaign, &measurement).map_err(|e| Failure::input(e.to_string()))
}

/// An `hx_highfi` objective against its own nominal transient (written to a scratch folder).
fn hx_objective() -> Result<Objective, Failure> {
    let model = models::find("hx_highfi").expect("hx_highfi is hosted");
    let info = model.info();
    let grid: Vec<f64> = (0..=300).map(f64::from).collect();
    let trajectory = model
        .simulate(&Run::new(
            &info.default_vector(),
            &grid,
            &[0, 1],
            &SolverOptions::default(),
        ))
        .map_err(|e| Failure::internal(format!("hx_highfi failed: {e}")))?;
    let dir = std::env::temp_dir().join(format!("calib-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| Failure::internal(e.to_string()))?;
    let mut csv = String::from("time,dp,q\n");
    for (i, t) in grid.iter().enumerate() {
        csv += &format!(
            "{t},{},{}\n",
            trajectory.values[0][i], trajectory.values[1][i]
        );
    }
    let write = |name: &str, text: &str| {
        std::fs::write(dir.join(name), text).map_err(|e| Failure::internal(e.to_string()))
    };
    write("hx.csv", &csv)?;
    write(
        "hx.toml",
        r#"
[model]
name = "hx_highfi"
[measurement]
file = "hx.csv"
[[outputs]]
model = "dp_ref"
measured = "dp"
[[outputs]]
model = "Qdot_refTotal"
measured = "q"
[[parameters]]
name = "CF_RefHT"
min = 0.1
max = 5.0
[[parameters]]
name = "CF_Refdp"
min = 0.1
max = 5.0
[window]
start = 50.0
stop = 200.0
"#,
    )?;
    let objective = objective_of(&dir.join("hx.toml"));
    let _ = std::fs::remove_dir_all(&dir);
    objective
}

/// A `calib worker` in a child process on a loopback port, stopped when dropped.
struct ChildWorker {
    child: std::process::Child,
    url: String,
}

impl ChildWorker {
    fn start(slots: usize) -> Result<Self, Failure> {
        use std::io::BufRead;
        let exe = std::env::current_exe().map_err(|e| Failure::internal(e.to_string()))?;
        let mut child = std::process::Command::new(exe)
            .args(["worker", "--listen", "127.0.0.1:0", "--slots"])
            .arg(slots.to_string())
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::null())
            .spawn()
            .map_err(|e| Failure::internal(format!("cannot start a worker process: {e}")))?;
        let mut line = String::new();
        let stdout = child.stdout.take().expect("piped");
        std::io::BufReader::new(stdout)
            .read_line(&mut line)
            .map_err(|e| Failure::internal(e.to_string()))?;
        // "worker listening on 127.0.0.1:PORT (...)"
        let address = line
            .strip_prefix("worker listening on ")
            .and_then(|rest| rest.split_whitespace().next());
        match address {
            Some(address) => Ok(Self {
                url: format!("http://{address}"),
                child,
            }),
            None => {
                let _ = child.kill();
                let _ = child.wait();
                Err(Failure::internal(format!(
                    "the worker process did not say where it listens: {line:?}"
                )))
            }
        }
    }
}

impl Drop for ChildWorker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Figures of the cluster benchmark, as `calib bench --cluster --json` reports them.
pub fn run(repeat: usize, campaign: &Path, thousand: bool, report: &mut Report) -> Outcome {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let furuta = objective_of(campaign)?;
    let in_process_us = grpc_overhead(&furuta, cores, repeat, report)?;
    coordinator_cpu(&furuta, cores, repeat, in_process_us, report)?;
    hx_scaling(repeat, report)?;
    dispatch_capacity(&furuta, thousand, report)?;
    report.figure("dispatch_efficiency_target", 0.9);
    Ok(())
}

/// The gRPC overhead: one worker with a slot per core against this process on every core.
/// Returns the in-process time per evaluation (µs).
fn grpc_overhead(
    furuta: &Objective,
    cores: usize,
    repeat: usize,
    report: &mut Report,
) -> Result<f64, Failure> {
    let batch = points(furuta, 256);
    let workers = SandboxCluster::start(1, cores);
    let remote = connect(&workers.urls())?;
    let evaluator = remote.evaluator();
    // Warm both (the worker caches the measurement, the pools start their threads).
    time_batch(&LocalEvaluator, furuta, &batch, 1);
    time_batch(&evaluator, furuta, &batch, 1);
    let (local, cluster) = time_pair(&LocalEvaluator, &evaluator, furuta, &batch, repeat);
    let per = |d: Duration| d.as_secs_f64() * 1e6 / batch.len() as f64;
    let overhead_ratio = (per(cluster) - per(local)) / per(local);
    report.say(format!(
        "{}: gRPC overhead, batches of {} evaluations, 1 worker x {cores} slots vs this process on {cores} cores:",
        furuta.model.info().name,
        batch.len()
    ));
    report.say(format!(
        "  in process {:.0} us per evaluation, over loopback gRPC {:.0} us  -> overhead {:.0} us per evaluation, {:.2} of the in-process time (target 0.25)",
        per(local),
        per(cluster),
        per(cluster) - per(local),
        overhead_ratio
    ));
    report.figure("furuta_in_process_us", per(local));
    report.figure("furuta_grpc_us", per(cluster));
    report.figure("grpc_overhead_us", per(cluster) - per(local));
    report.figure("grpc_overhead_ratio", overhead_ratio);
    report.figure("grpc_overhead_ratio_target", 0.25);
    drop((evaluator, remote, workers));

    Ok(per(local))
}

/// The coordinator's CPU per evaluation: a worker process of a slot per core, batches of
/// 256 distinct points through the evaluation store (each point simulated and stored once),
/// the CPU of this process over the points it had simulated.
fn coordinator_cpu(
    furuta: &Objective,
    cores: usize,
    repeat: usize,
    in_process_us: f64,
    report: &mut Report,
) -> Outcome {
    let worker = ChildWorker::start(cores)?;
    let remote = connect(std::slice::from_ref(&worker.url))?;
    let db = tempfile_dir("store")?;
    let store = SledStore::open(&db).map_err(|e| Failure::internal(e.to_string()))?;
    StoredEvaluator::with(remote.evaluator(), &store, |stored| -> Outcome {
        // The worker gets the measurement first.
        stored
            .evaluate(furuta, &points_from(furuta, 1 << 20, 1))
            .map_err(|e| Failure::internal(e.to_string()))?;
        let rounds = repeat.max(1);
        let before_cpu = super::cpu::process_cpu();
        let before = stored.stats().simulated;
        let start = Instant::now();
        for round in 0..rounds {
            let batch = points_from(furuta, round * 256, 256);
            stored
                .evaluate(furuta, &batch)
                .map_err(|e| Failure::internal(e.to_string()))?;
        }
        let wall = start.elapsed();
        let cpu = super::cpu::process_cpu() - before_cpu;
        let simulated = stored.stats().simulated - before;
        let us = super::cpu::us_per(cpu, simulated);
        report.say(format!(
            "coordinator CPU per evaluation, batches of 256 through the store to a worker process of {cores} slots:"
        ));
        report.say(format!(
            "  {us:.1} us per evaluation ({:.3} s CPU for {simulated} simulated in {:.2} s; {:.3} of the in-process evaluation; target 10 us)  -> one core feeds {:.0} evaluations/s",
            cpu.as_secs_f64(),
            wall.as_secs_f64(),
            us / in_process_us,
            1e6 / us
        ));
        report.figure("coordinator_cpu_us_per_eval", us);
        report.figure("coordinator_cpu_target_us", 10.0);
        report.figure("coordinator_cpu_ratio_to_evaluation", us / in_process_us);
        Ok(())
    })?;
    drop((store, remote, worker));
    let _ = std::fs::remove_dir_all(&db);

    Ok(())
}

/// Scaling: single-slot workers, a model of ≥ 5 ms per simulation, beside the machine's own
/// scaling in this process.
fn hx_scaling(repeat: usize, report: &mut Report) -> Outcome {
    let hx = hx_objective()?;
    let batch = points(&hx, 64);
    let hx_repeat = repeat.div_ceil(7);
    let mut own = Vec::new();
    for threads in 1..=2usize {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .map_err(|e| Failure::internal(e.to_string()))?;
        let took = pool.install(|| time_batch(&LocalEvaluator, &hx, &batch, hx_repeat));
        own.push(batch.len() as f64 / took.as_secs_f64());
    }
    let mut rates = Vec::new();
    for count in 1..=2usize {
        let workers = SandboxCluster::start(count, 1);
        let remote = connect(&workers.urls())?;
        let took = time_batch(&remote.evaluator(), &hx, &batch, hx_repeat);
        rates.push(batch.len() as f64 / took.as_secs_f64());
    }
    report.say(format!(
        "{}: evaluations per second with single-slot workers ({:.1} ms per evaluation):",
        hx.model.info().name,
        1e3 / rates[0]
    ));
    report.say(format!(
        "  1 worker {:.1}/s, 2 workers {:.1}/s  -> scaling efficiency {:.2}",
        rates[0],
        rates[1],
        rates[1] / (2.0 * rates[0])
    ));
    report.say(format!(
        "  (in process, for reference: 1 thread {:.1}/s, 2 threads {:.1}/s  -> the machine's own scaling {:.2})",
        own[0],
        own[1],
        own[1] / (2.0 * own[0])
    ));
    report.figure("hx_scaling_efficiency_2", rates[1] / (2.0 * rates[0]));
    report.figure("machine_scaling_efficiency_2", own[1] / (2.0 * own[0]));

    Ok(())
}

/// Dispatcher capacity: workers that only sleep. The rate of one such worker (its nap plus
/// the timer's granularity plus one round trip) is the unit of the efficiency.
fn dispatch_capacity(furuta: &Objective, thousand: bool, report: &mut Report) -> Outcome {
    let nap = Duration::from_millis(5);
    let mut single = 0.0;
    let mut counts = vec![1usize, 10, 100];
    if thousand {
        counts.push(1000);
    }
    for count in counts {
        let workers = NappingCluster::start(count, nap, 1)
            .map_err(|e| Failure::internal(format!("cannot start napping workers: {e}")))?;
        let remote = connect(workers.urls())?;
        let batch = points(furuta, 40 * count);
        let took = time_batch(&remote.evaluator(), furuta, &batch, 3);
        let rate = batch.len() as f64 / took.as_secs_f64();
        if count == 1 {
            single = rate;
            report.say(format!(
                "dispatch to single-slot workers that sleep {} ms per evaluation: 1 worker {rate:.0}/s",
                nap.as_millis()
            ));
            report.figure("dispatch_rate_1", rate);
        } else {
            let efficiency = rate / (count as f64 * single);
            report.say(format!(
                "  {count} workers {rate:.0}/s  -> efficiency {efficiency:.2} of {count} x 1 worker"
            ));
            report.figure(&format!("dispatch_rate_{count}"), rate);
            report.figure(&format!("dispatch_efficiency_{count}"), efficiency);
        }
    }
    Ok(())
}

/// A fresh scratch folder under the system's temporary folder.
fn tempfile_dir(what: &str) -> Result<std::path::PathBuf, Failure> {
    let dir = std::env::temp_dir().join(format!("calib-bench-{what}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| Failure::internal(e.to_string()))?;
    Ok(dir)
}
