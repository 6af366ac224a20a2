//! `calib bench --cluster`: what dispatching over gRPC costs and how it scales, measured
//! with workers serving in this process on loopback.
//!
//! - overhead: a batch of `furuta` evaluations over one worker versus in this process, on
//!   the same cores;
//! - scaling: evaluations per second of a ≥ 5 ms model (`hx_highfi`) with one and two
//!   single-slot workers;
//! - dispatcher capacity: many workers that only sleep, so that what limits the rate is
//!   the coordinator's dispatch, not the simulations.
//!
//! The workers are those of the tests' sandbox (`calib-sandbox`).

use super::{Failure, Outcome};
use calib_coordinator::calibration;
use calib_coordinator::campaign::Campaign;
use calib_coordinator::dispatch::RemoteWorkers;
use calib_coordinator::evaluator::{Evaluator, LocalEvaluator};
use calib_coordinator::objective::Objective;
use calib_sandbox::{NappingCluster, SandboxCluster};
use calib_worker::{models, SolverOptions};
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
                .map(|&f| objective.base[f] * (1.0 + 1e-3 * i as f64 / n as f64))
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
        .simulate(
            &info.default_vector(),
            &grid,
            &[0, 1],
            &SolverOptions::default(),
        )
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

pub fn run(repeat: usize, campaign: &Path) -> Outcome {
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());

    // Overhead: one worker with a slot per core against this process on every core.
    let furuta = objective_of(campaign)?;
    let batch = points(&furuta, 256);
    let local = time_batch(&LocalEvaluator, &furuta, &batch, repeat);
    let workers = SandboxCluster::start(1, cores);
    let remote = connect(&workers.urls())?;
    let evaluator = remote.evaluator();
    let cluster = time_batch(&evaluator, &furuta, &batch, repeat);
    let per = |d: Duration| d.as_secs_f64() * 1e6 / batch.len() as f64;
    println!(
        "{}: gRPC overhead, batches of {} evaluations, 1 worker x {cores} slots vs this process on {cores} cores:",
        furuta.model.info().name,
        batch.len()
    );
    println!(
        "  in process {:.0} us per evaluation, over loopback gRPC {:.0} us  -> overhead {:.0} us per evaluation",
        per(local),
        per(cluster),
        per(cluster) - per(local)
    );
    drop((evaluator, remote, workers));

    // Scaling: single-slot workers, a model of ≥ 5 ms per simulation.
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
    println!(
        "{}: evaluations per second with single-slot workers ({:.1} ms per evaluation):",
        hx.model.info().name,
        1e3 / rates[0]
    );
    println!(
        "  1 worker {:.1}/s, 2 workers {:.1}/s  -> scaling efficiency {:.2}",
        rates[0],
        rates[1],
        rates[1] / (2.0 * rates[0])
    );
    println!(
        "  (in process, for reference: 1 thread {:.1}/s, 2 threads {:.1}/s  -> the machine's own scaling {:.2})",
        own[0],
        own[1],
        own[1] / (2.0 * own[0])
    );

    // Dispatcher capacity: workers that only sleep. The rate of one such worker (its nap
    // plus the timer's granularity plus one round trip) is the unit of the efficiency.
    let nap = Duration::from_millis(5);
    let mut single = 0.0;
    for count in [1usize, 10, 100] {
        let workers = NappingCluster::start(count, nap, 1)
            .map_err(|e| Failure::internal(format!("cannot start napping workers: {e}")))?;
        let remote = connect(workers.urls())?;
        let batch = points(&furuta, 40 * count);
        let took = time_batch(&remote.evaluator(), &furuta, &batch, 3);
        let rate = batch.len() as f64 / took.as_secs_f64();
        if count == 1 {
            single = rate;
            println!(
                "dispatch to single-slot workers that sleep {} ms per evaluation: 1 worker {rate:.0}/s",
                nap.as_millis()
            );
        } else {
            println!(
                "  {count} workers {rate:.0}/s  -> efficiency {:.2} of {count} x 1 worker",
                rate / (count as f64 * single)
            );
        }
    }
    Ok(())
}
