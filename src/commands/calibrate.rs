use super::{Failure, Outcome};
use calib_coordinator::calibration;
use calib_coordinator::campaign::Campaign;
use calib_coordinator::dispatch::{self, DispatchConfig, RemoteWorkers};
use calib_coordinator::evaluator::LocalEvaluator;
use calib_coordinator::optim::problem::Progress;
use calib_coordinator::report;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::path::PathBuf;
use std::sync::Mutex;

#[derive(clap::Args)]
pub struct Args {
    /// Campaign file (TOML): model, measurement, outputs, parameters, window, search.
    campaign: PathBuf,
    /// Folder for result.json and the plots [default: results/<campaign name>/ beside the
    /// campaign file].
    #[arg(long)]
    out: Option<PathBuf>,
    /// Print result.json to standard output instead of the summary table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    workers: super::WorkersArgs,
}

/// A progress bar on standard error, drawn only when it is a terminal.
struct Bar {
    bar: ProgressBar,
    best: Mutex<f64>,
}

impl Progress for Bar {
    fn evaluated(&self, count: usize, best_objective: f64) {
        let mut best = self.best.lock().expect("progress lock");
        if best_objective < *best {
            *best = best_objective;
            self.bar.set_message(format!("best {best_objective:.6e}"));
        }
        self.bar.inc(count as u64);
    }
}

pub fn run(args: Args) -> Outcome {
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let runs = campaign.search.methods.len() * campaign.search.starts;
    let budget = (runs * campaign.search.max_evaluations + 1) as u64;
    let bar = ProgressBar::with_draw_target(Some(budget), ProgressDrawTarget::stderr());
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {elapsed_precise} [{bar:30}] {pos}/{len} evaluations (budget) {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let progress = Bar {
        bar,
        best: Mutex::new(f64::INFINITY),
    };
    let result = match &args.workers.workers {
        None => calibration::calibrate(&campaign, LocalEvaluator, &progress),
        Some(list) => {
            let addresses =
                dispatch::parse_list(list).map_err(|e| Failure::input(format!("--workers {e}")))?;
            let config = args.workers.apply(DispatchConfig::new(addresses));
            let wait = config.wait_for_workers;
            let workers = RemoteWorkers::connect(config)?;
            if !workers.wait_until_up(1, wait) {
                progress.bar.finish_and_clear();
                let states: Vec<String> = workers
                    .pool()
                    .workers()
                    .iter()
                    .map(|w| format!("{} ({:?})", w.url, w.health))
                    .collect();
                return Err(Failure::internal(format!(
                    "no worker up after {:.0} s: {}",
                    wait.as_secs_f64(),
                    states.join(", ")
                )));
            }
            calibration::calibrate(&campaign, workers.evaluator(), &progress)
        }
    };
    progress.bar.finish_and_clear();
    let calibration = result?;

    let out = args.out.unwrap_or_else(|| {
        args.campaign
            .parent()
            .unwrap_or(std::path::Path::new("."))
            .join("results")
            .join(&campaign.name)
    });
    let written = report::write(&calibration, &out)?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report::result_json(&calibration)).expect("plain data")
        );
    } else {
        print!("{}", report::table::summary(&calibration));
        for path in written {
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}
