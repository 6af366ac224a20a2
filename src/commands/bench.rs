//! `calib bench`: speed figures, measured in one run and printed as medians and ratios.
//!
//! Timings are never asserted by tests (machines are shared and noisy); this command is where
//! speed is measured. The reference figures are those of the seed's tool chain (scipy's
//! Nelder–Mead over `solve_ivp`) measured on the same kind of machine.

use super::{Failure, Outcome};
use calib_engine::calibration;
use calib_engine::campaign::{Campaign, Method};
use calib_engine::evaluator::{Evaluator, Fault, LocalEvaluator};
use calib_engine::objective::{Evaluation, Objective};
use calib_engine::optim::problem::Silent;
use calib_model::Run;
use calib_model::{models, SolverOptions};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The seed's tool chain: one evaluation, and one calibration of the two frictions.
const SEED_EVALUATION: Duration = Duration::from_millis(300);
const SEED_CALIBRATION: Duration = Duration::from_secs(25);

/// Targets for one 300 s heat-exchanger simulation: what each evaluation of a campaign
/// calibrating `hx_lowfi` (and each record of `hx_highfi`) may cost.
const HX_TARGETS: [(&str, Duration); 2] = [
    ("hx_lowfi", Duration::from_millis(2)),
    ("hx_highfi", Duration::from_millis(15)),
];

/// What a benchmark found: lines for people (on standard output, or on standard error under
/// `--json`) and named figures for machines (one JSON object on standard output).
pub struct Report {
    json: bool,
    figures: serde_json::Map<String, serde_json::Value>,
}

impl Report {
    pub fn new(json: bool) -> Self {
        Self {
            json,
            figures: serde_json::Map::new(),
        }
    }

    /// A line for people.
    pub fn say(&self, line: impl AsRef<str>) {
        if self.json {
            eprintln!("{}", line.as_ref());
        } else {
            println!("{}", line.as_ref());
        }
    }

    /// A figure for machines.
    pub fn figure(&mut self, name: &str, value: f64) {
        self.figures
            .insert(name.to_string(), serde_json::json!(value));
    }

    /// Print the figures as JSON when asked to.
    pub fn finish(self) {
        if self.json {
            println!(
                "{}",
                serde_json::to_string_pretty(&serde_json::Value::Object(self.figures))
                    .expect("plain data")
            );
        }
    }
}

#[derive(clap::Args)]
pub struct Args {
    /// Repetitions of each measurement (the median is reported).
    #[arg(long, default_value_t = 21)]
    repeat: usize,
    /// Campaign of the calibration benchmarks. The default ships with calib; the figures of
    /// docs/performance.md use `examples/furuta_real.toml`, the real record beside the
    /// repository.
    #[arg(long, default_value = "examples/furuta.toml")]
    campaign: PathBuf,
    /// Measure dispatch over gRPC instead: overhead per evaluation, scaling with workers,
    /// and the dispatcher's capacity (workers serve in this process, on loopback).
    #[arg(long)]
    cluster: bool,
    /// With `--cluster`: also measure dispatch to 1,000 sleeping workers.
    #[arg(long)]
    thousand: bool,
    /// Print the figures as one JSON object on standard output (the lines for people go to
    /// standard error).
    #[arg(long)]
    json: bool,
    #[command(subcommand)]
    suite: Option<Suite>,
}

/// Benchmarks run on request only.
#[derive(clap::Subcommand)]
enum Suite {
    /// The evaluation store: persisted evaluations per second, time to resume a campaign.
    Store(super::bench_store::Args),
    /// A whole diagnosis (calibrate, rank, refit, select), single node.
    Diagnose(super::bench_diagnose::Args),
    /// The cost of a model run as an FMU against the same equations built in.
    Fmu(super::bench_fmu::Args),
    /// What one run of a command model costs beside the command's own time.
    Command(super::bench_command::Args),
    /// Search methods compared: rounds and evaluations to the optimum, runs reaching it,
    /// wall time on 1 to 512 simulated workers.
    Search(super::bench_search::Args),
}

fn median(mut samples: Vec<Duration>) -> Duration {
    samples.sort();
    samples[samples.len() / 2]
}

fn time<T>(repeat: usize, mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut samples = Vec::with_capacity(repeat);
    let mut last = None;
    for _ in 0..repeat.max(1) {
        let start = Instant::now();
        last = Some(f());
        samples.push(start.elapsed());
    }
    (median(samples), last.expect("at least one repetition"))
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

pub fn run(args: Args) -> Outcome {
    let mut report = Report::new(args.json);
    if args.cluster {
        super::bench_cluster::run(args.repeat, &args.campaign, args.thousand, &mut report)?;
        report.finish();
        return Ok(());
    }
    match args.suite {
        Some(Suite::Store(store)) => return super::bench_store::run(store),
        Some(Suite::Diagnose(diagnose)) => return super::bench_diagnose::run(diagnose),
        Some(Suite::Fmu(fmu)) => return super::bench_fmu::run(fmu),
        Some(Suite::Command(command)) => return super::bench_command::run(command),
        Some(Suite::Search(search)) => return super::bench_search::run(search),
        None => {}
    }
    furuta(args.repeat, &mut report)?;
    hx(args.repeat, &mut report)?;

    calibrations(&args, &mut report)?;
    report.finish();
    Ok(())
}

/// One 40 s simulation of the Furuta pendulum, against the seed's.
fn furuta(repeat: usize, report: &mut Report) -> Outcome {
    let model = models::find("furuta").expect("furuta is hosted");
    let params = model.info().default_vector();
    let grid: Vec<f64> = (0..=4000).map(|i| i as f64 * 0.01).collect();
    let options = SolverOptions::default();
    let (sim, trajectory) = time(repeat * 10, || {
        model
            .simulate(&Run::new(&params, &grid, &[0, 1], &options))
            .map_err(|e| Failure::internal(format!("simulation failed: {e}")))
    });
    let stats = trajectory?.stats;
    report.say(format!(
        "furuta, one 40 s simulation (rtol {:e}, 4001 output points):",
        options.rtol
    ));
    report.say(format!(
        "  median {:.3} ms  ({} steps, {} rejected, {} events, {} rhs)  seed: {:.0} ms  -> {:.0}x faster",
        ms(sim),
        stats.accepted_steps,
        stats.rejected_steps,
        stats.events,
        stats.rhs_evaluations,
        ms(SEED_EVALUATION),
        SEED_EVALUATION.as_secs_f64() / sim.as_secs_f64()
    ));
    report.figure("furuta_ms", ms(sim));
    report.figure(
        "furuta_speedup_vs_seed",
        SEED_EVALUATION.as_secs_f64() / sim.as_secs_f64(),
    );

    Ok(())
}

/// Evaluates on the threads of one pool (the bench's single core), whichever thread asks.
struct OnPool<'a>(&'a rayon::ThreadPool);

impl Evaluator for OnPool<'_> {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        self.0
            .install(|| LocalEvaluator.evaluate(objective, points))
    }
}

/// One Nelder–Mead calibration on one core, and the campaign's full multistart on every
/// core.
fn calibrations(args: &Args, report: &mut Report) -> Outcome {
    let mut campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let single = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| Failure::internal(e.to_string()))?;
    let full = campaign.search.clone();
    campaign.search.methods = vec![Method::NelderMead];
    campaign.search.starts = 1;
    let (nm, result) = time(args.repeat.div_ceil(4), || {
        calibration::calibrate(&campaign, OnPool(&single), &Silent)
    });
    let c = result?;
    let run = c.best_run();
    report.say(format!(
        "{}: one Nelder-Mead calibration from the nominal point, one core:",
        campaign.name
    ));
    report.say(format!(
        "  median {:.1} ms  ({} evaluations, {} rounds, {} iterations, objective {:.4} -> {:.4})  seed: {:.0} s  -> {:.0}x faster",
        ms(nm),
        run.evaluations,
        run.rounds,
        run.iterations,
        c.nominal.objective,
        run.objective,
        SEED_CALIBRATION.as_secs_f64(),
        SEED_CALIBRATION.as_secs_f64() / nm.as_secs_f64()
    ));
    report.figure("nelder_mead_calibration_ms", ms(nm));

    campaign.search = full;
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let (multi, result) = time(3, || {
        calibration::calibrate(&campaign, LocalEvaluator, &Silent)
    });
    let c = result?;
    report.say(format!(
        "{}: full multistart ({} methods x {} starts), {} cores:",
        campaign.name,
        campaign.search.methods.len(),
        campaign.search.starts,
        cores
    ));
    report.say(format!(
        "  median {:.1} ms  ({} evaluations, {} simulated, {} rounds, best objective {:.4})",
        ms(multi),
        c.evaluations(),
        c.stats.simulated,
        c.rounds(),
        c.best_run().objective
    ));
    report.figure("multistart_calibration_ms", ms(multi));
    report.figure("multistart_rounds", c.rounds() as f64);
    Ok(())
}

/// One 300 s simulation of each heat-exchanger model, both calibrated outputs on a 1 s grid.
fn hx(repeat: usize, report: &mut Report) -> Outcome {
    let options = models::find("hx_lowfi")
        .expect("the hx models are hosted")
        .default_options();
    let grid: Vec<f64> = (0..=300).map(f64::from).collect();
    report.say(format!(
        "heat exchanger, one 300 s simulation (rtol {:e}, dp_ref and Qdot_refTotal, 301 output points):",
        options.rtol
    ));
    for (name, target) in HX_TARGETS {
        let model = models::find(name).expect("the hx models are hosted");
        let info = model.info();
        let params = info.default_vector();
        let outputs: Vec<usize> = ["dp_ref", "Qdot_refTotal"]
            .iter()
            .map(|o| info.output_index(o).expect("hx output"))
            .collect();
        let (sim, trajectory) = time(repeat, || {
            model
                .simulate(&Run::new(&params, &grid, &outputs, &options))
                .map_err(|e| Failure::internal(format!("{name} failed: {e}")))
        });
        let stats = trajectory?.stats;
        report.say(format!(
            "  {name:9} median {:.2} ms  ({} steps, {} rejected, {} rhs)  target: {:.0} ms  -> {:.2} of it, {}",
            ms(sim),
            stats.accepted_steps,
            stats.rejected_steps,
            stats.rhs_evaluations,
            ms(target),
            ms(sim) / ms(target),
            if sim <= target { "met" } else { "missed" }
        ));
        report.figure(&format!("{name}_ms"), ms(sim));
        report.figure(&format!("{name}_target_ms"), ms(target));
        report.figure(&format!("{name}_ratio_to_target"), ms(sim) / ms(target));
    }
    Ok(())
}
