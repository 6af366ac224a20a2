//! `calib bench diagnose`: wall time of a whole diagnosis, single-node.

use super::{Failure, Outcome};
use calib_analysis::diagnosis::diagnose;
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    /// Repetitions (the median is reported).
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Campaign to diagnose.
    #[arg(long, default_value = "examples/furuta_viscous_arm.toml")]
    campaign: PathBuf,
    /// Instead: the robustness matrix, records of every effect (from the independent
    /// simulator) diagnosed under every search setting (bounds, methods, starts), printed as
    /// a table of the effect selected and the objective over the noise floor per cell.
    #[arg(long)]
    matrix: bool,
    #[command(flatten)]
    cells: super::bench_matrix::MatrixArgs,
}

pub fn run(args: Args) -> Outcome {
    if args.matrix {
        return super::bench_matrix::run(args.cells);
    }
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let mut samples: Vec<Duration> = Vec::new();
    let mut last = None;
    for _ in 0..args.repeat.max(1) {
        let started = Instant::now();
        last = Some(diagnose(&campaign, &LocalEvaluator, &Silent)?);
        samples.push(started.elapsed());
    }
    samples.sort();
    let median = samples[samples.len() / 2];
    let d = last.expect("at least one repetition");
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "{}: whole diagnosis, single node, {cores} cores: median {:.2} s (target 10 s)",
        campaign.name,
        median.as_secs_f64()
    );
    println!(
        "  baseline {:.4e} -> {:.4e} with {:?}; {} candidates ranked, {} refits",
        d.baseline.objective,
        d.final_fit.objective,
        d.selected,
        d.candidates.len(),
        d.refits.len()
    );
    Ok(())
}
