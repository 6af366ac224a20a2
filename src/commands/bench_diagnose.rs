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
    #[arg(long, conflicts_with = "random")]
    matrix: bool,
    #[command(flatten)]
    cells: super::bench_matrix::MatrixArgs,
    /// Instead: N records drawn at random (effects, sizes, noise, start angle, search
    /// settings; see docs/diagnosis.md), diagnosed, and the confusion matrix, the
    /// false-positive rate on clean records and the cost printed (`--jobs` at a time).
    #[arg(long, value_name = "N")]
    random: Option<usize>,
    /// The seed of the random records; keep one for tuning and others never tuned on.
    #[arg(long, default_value_t = 1, requires = "random")]
    seed: u64,
    /// The first random record's index (to run part of a benchmark).
    #[arg(long, default_value_t = 0, requires = "random")]
    from: usize,
    /// Only the random records of these kinds (comma-separated: clean, single, double,
    /// cogging); each keeps its index, so its draw is the one the whole benchmark makes.
    #[arg(long, value_delimiter = ',', value_parser = ["clean", "single", "double", "cogging"], requires = "random")]
    kinds: Vec<String>,
    /// Only list the random records (index, kind, what each holds, search settings),
    /// diagnosing nothing.
    #[arg(long, requires = "random")]
    list: bool,
    /// Also write each random record's outcome as JSON to this file.
    #[arg(long, value_name = "FILE", requires = "random")]
    json: Option<PathBuf>,
    /// Keep each random record and its campaign in this folder (`record<i>.csv`,
    /// `record<i>.toml`), to diagnose one again with `calib diagnose`.
    #[arg(long, value_name = "DIR", requires = "random")]
    keep: Option<PathBuf>,
}

pub fn run(args: Args) -> Outcome {
    if args.matrix {
        return super::bench_matrix::run(args.cells);
    }
    if let Some(count) = args.random {
        return super::bench_random::run(super::bench_random::RandomArgs {
            count,
            seed: args.seed,
            from: args.from,
            only: args.kinds,
            list: args.list,
            keep: args.keep,
            jobs: args.cells.jobs,
            json: args.json,
            repo: PathBuf::from("."),
        });
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
