//! `calib bench store`: how fast the evaluation store persists, and how fast a campaign
//! resumes from it.

use super::{Failure, Outcome};
use calib_engine::calibration::{self, Calibration};
use calib_engine::campaign::{Campaign, Method};
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::objective::Evaluation;
use calib_engine::optim::problem::Silent;
use calib_engine::store::{evaluation_key_from, MemoryStore, SledStore, Store};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    /// Evaluations written by each persistence measurement.
    #[arg(long, default_value_t = 20_000)]
    evaluations: usize,
    /// Campaign of the resume measurement (run as differential evolution from 5 starts
    /// with a budget of 2,500 each: about 10,000 evaluations). The default ships with calib;
    /// docs/performance.md's figures use `examples/furuta_real.toml`, the real record beside
    /// the repository.
    #[arg(long, default_value = "examples/furuta.toml")]
    campaign: PathBuf,
}

/// A folder removed when dropped.
pub(super) struct Scratch(pub(super) PathBuf);

impl Scratch {
    pub(super) fn new(name: &str) -> Result<Self, Failure> {
        let path = std::env::temp_dir().join(format!("calib-bench-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&path);
        std::fs::create_dir_all(&path)
            .map_err(|e| Failure::internal(format!("cannot create {}: {e}", path.display())))?;
        Ok(Self(path))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn store_failure(e: impl std::fmt::Display) -> Failure {
    Failure::internal(e.to_string())
}

/// An evaluation of the usual size (two outputs).
fn evaluation(i: usize) -> Evaluation {
    Evaluation {
        objective: i as f64 * 1e-3,
        sse: vec![i as f64 * 4e-4, i as f64 * 6e-4],
        failure: None,
        residuals: Vec::new(),
    }
}

/// Persist `total` evaluations from `writers` threads in batches of `batch`; the rate,
/// the flushes made and the median latency of a put.
fn persist(
    dir: &Path,
    writers: usize,
    batch: usize,
    total: usize,
) -> Result<(f64, u64, Duration), Failure> {
    let store = SledStore::open(dir).map_err(store_failure)?;
    let per_writer = total / writers / batch;
    let started = Instant::now();
    let latencies = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..writers)
            .map(|w| {
                let store = &store;
                scope.spawn(move || -> Result<Vec<Duration>, Failure> {
                    let mut latencies = Vec::with_capacity(per_writer);
                    for b in 0..per_writer {
                        let entries: Vec<_> = (0..batch)
                            .map(|j| {
                                let i = (w * per_writer + b) * batch + j;
                                (evaluation_key_from(&[0; 32], &[i as f64]), evaluation(i))
                            })
                            .collect();
                        let put = Instant::now();
                        store.put_evaluations(&entries).map_err(store_failure)?;
                        latencies.push(put.elapsed());
                    }
                    Ok(latencies)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().expect("writer thread"))
            .collect::<Result<Vec<_>, _>>()
    })?;
    let elapsed = started.elapsed();
    let mut latencies: Vec<Duration> = latencies.into_iter().flatten().collect();
    latencies.sort();
    let written = writers * per_writer * batch;
    Ok((
        written as f64 / elapsed.as_secs_f64(),
        store.flushes(),
        latencies[latencies.len() / 2],
    ))
}

fn timed<T>(f: impl FnOnce() -> T) -> (Duration, T) {
    let started = Instant::now();
    let value = f();
    (started.elapsed(), value)
}

pub fn run(args: Args) -> Outcome {
    println!(
        "sled store, {} evaluations per case (2 outputs each), every put flushed before it returns:",
        args.evaluations
    );
    for (writers, batch) in [(1, 1), (1, 20), (8, 1), (8, 20)] {
        let dir = Scratch::new("persist")?;
        let (rate, flushes, latency) = persist(&dir.0, writers, batch, args.evaluations)?;
        println!(
            "  {writers} writer(s), batches of {batch:>2}: {rate:>9.0} evaluations/s  \
             ({flushes} flushes, median put {:.2} ms)",
            latency.as_secs_f64() * 1e3
        );
    }

    let mut campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    campaign.search.methods = vec![Method::DifferentialEvolution];
    campaign.search.starts = 5;
    campaign.search.max_evaluations = 2500;
    let in_memory_run = || {
        timed(|| {
            calibration::calibrate_with_store(
                &campaign,
                LocalEvaluator,
                &MemoryStore::new(),
                &Silent,
            )
        })
    };
    let (in_memory, result) = in_memory_run();
    let reference = result?;
    let dir = Scratch::new("resume")?;
    let (first, fresh) = {
        let store = SledStore::open(&dir.0).map_err(store_failure)?;
        let (t, result) =
            timed(|| calibration::calibrate_with_store(&campaign, LocalEvaluator, &store, &Silent));
        (t, result?)
    };
    // A new process would open the store again: so does the replay.
    let (replay, resumed) = timed(|| -> Result<Calibration, Failure> {
        let store = SledStore::open(&dir.0).map_err(store_failure)?;
        Ok(calibration::calibrate_with_store(
            &campaign,
            LocalEvaluator,
            &store,
            &Silent,
        )?)
    });
    let resumed = resumed?;
    // The machine is shared: the faster of two in-memory runs around the sled one.
    let in_memory = in_memory.min(in_memory_run().0);
    if resumed.best_run().point != reference.best_run().point || resumed.stats.simulated != 0 {
        return Err(Failure::internal(
            "the replay from the store differs from the original run",
        ));
    }
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "{}: differential evolution x 5 starts, {} evaluations ({} simulated):",
        campaign.name,
        fresh.evaluations(),
        fresh.stats.simulated
    );
    println!(
        "  in memory {:.0} ms, persisting to sled {:.0} ms ({:+.1}%), resume from the store {:.0} ms \
         ({} simulated, {:.0} evaluations/s, {:.0}x faster than computing)",
        ms(in_memory),
        ms(first),
        (first.as_secs_f64() / in_memory.as_secs_f64() - 1.0) * 100.0,
        ms(replay),
        resumed.stats.simulated,
        resumed.stats.requested as f64 / replay.as_secs_f64(),
        first.as_secs_f64() / replay.as_secs_f64()
    );
    Ok(())
}
