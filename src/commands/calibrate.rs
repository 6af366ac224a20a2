use super::{Failure, Outcome};
use calib_analysis::report;
use calib_engine::calibration;
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Progress;
use calib_engine::store::SledStore;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    /// Campaign file (TOML): model, measurement, outputs, parameters, window, search
    /// (`methods`: nelder-mead, powell, differential-evolution, levenberg-marquardt).
    campaign: PathBuf,
    /// Results folder: result.json and the plots go to DIR/<campaign name>/ [default:
    /// results/ beside the campaign file], as `calib coordinator --out` puts them.
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    /// Print result.json to standard output instead of the summary table.
    #[arg(long)]
    json: bool,
    #[command(flatten)]
    workers: super::WorkersArgs,
    /// Evaluation store (a folder, created when absent): every simulated point is kept
    /// there, so an interrupted campaign resumes where it stopped and a repeated one
    /// simulates nothing [default: results/.calib-db beside the campaign file].
    #[arg(long, value_name = "DIR")]
    db: Option<PathBuf>,
    /// Print on standard error the CPU time this process spent (user + system) per point it
    /// had simulated: with `--workers`, the coordinator's own cost per evaluation.
    #[arg(long)]
    cpu: bool,
}

/// Set to `lines` to report progress as plain lines on standard error (for scripts and
/// tests) instead of a progress bar.
pub const PROGRESS_ENV: &str = "CALIB_PROGRESS";

/// The folder holding one `<name>/` per campaign: `out` (`--out`) when given, else
/// `results/` beside the campaign file.
pub fn results_root(campaign: &Path, out: Option<&Path>) -> PathBuf {
    match out {
        Some(out) => out.to_path_buf(),
        None => campaign.parent().unwrap_or(Path::new(".")).join("results"),
    }
}

/// The store a campaign uses when `--db` is not given.
pub fn default_db(campaign: &Path) -> PathBuf {
    results_root(campaign, None).join(".calib-db")
}

/// A progress bar on standard error, drawn only when it is a terminal: the best objective
/// so far, and what the workers are waited for while none is up.
struct Bar {
    bar: ProgressBar,
    /// Best objective, workers status.
    message: Mutex<(f64, String)>,
}

impl Bar {
    fn show(&self, message: &(f64, String)) {
        let (best, status) = message;
        let mut text = if best.is_finite() {
            format!("best {best:.6e}")
        } else {
            String::new()
        };
        if !status.is_empty() {
            text.push_str(&format!("  [{status}]"));
        }
        self.bar.set_message(text);
    }

    fn set_status(&self, status: &str) {
        let mut message = self.message.lock().expect("progress lock");
        message.1 = status.to_string();
        self.show(&message);
    }
}

impl Progress for Bar {
    fn evaluated(&self, count: usize, best_objective: f64) {
        let mut message = self.message.lock().expect("progress lock");
        if best_objective < message.0 {
            message.0 = best_objective;
            self.show(&message);
        }
        self.bar.inc(count as u64);
    }
}

/// Progress as lines on standard error, at most ten a second (the first at once): every
/// evaluation counted in a line is already stored.
struct Lines {
    state: Mutex<(u64, f64, Option<Instant>)>,
}

impl Progress for Lines {
    fn evaluated(&self, count: usize, best_objective: f64) {
        let mut state = self.state.lock().expect("progress lock");
        state.0 += count as u64;
        state.1 = state.1.min(best_objective);
        let due = state
            .2
            .is_none_or(|last| last.elapsed() >= Duration::from_millis(100));
        if due {
            state.2 = Some(Instant::now());
            eprintln!("progress: {} evaluations, best {:.6e}", state.0, state.1);
        }
    }
}

pub fn run(args: Args) -> Outcome {
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let db = args
        .db
        .clone()
        .unwrap_or_else(|| default_db(&args.campaign));
    let store = SledStore::open(&db).map_err(|e| Failure::internal(e.to_string()))?;
    let lines = std::env::var(PROGRESS_ENV).is_ok_and(|v| v == "lines");
    let runs = campaign.search.methods.len() * campaign.search.starts;
    let budget = (runs * campaign.search.max_evaluations + 1) as u64;
    let target = if lines {
        ProgressDrawTarget::hidden()
    } else {
        ProgressDrawTarget::stderr()
    };
    let bar = ProgressBar::with_draw_target(Some(budget), target);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {elapsed_precise} [{bar:30}] {pos}/{len} evaluations (budget) {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    );
    let bar = Bar {
        bar,
        message: Mutex::new((f64::INFINITY, String::new())),
    };
    let line_progress = Lines {
        state: Mutex::new((0, f64::INFINITY, None)),
    };
    let progress: &dyn Progress = if lines { &line_progress } else { &bar };
    // What the workers are waited for: on the bar when it is drawn, else as lines.
    let drawn = !lines && std::io::stderr().is_terminal();
    let status = |line: &str| {
        if drawn {
            bar.set_status(line);
        } else {
            super::workers::print_status(line);
        }
    };
    let result = match &args.workers.workers {
        None => calibration::calibrate_with_store(&campaign, LocalEvaluator, &store, progress),
        Some(list) => match args.workers.connect_reporting(list, &status) {
            Ok(workers) => {
                status("");
                super::workers::while_watching(&workers, &status, || {
                    calibration::calibrate_with_store(
                        &campaign,
                        workers.evaluator(),
                        &store,
                        progress,
                    )
                })
            }
            Err(failure) => {
                bar.bar.finish_and_clear();
                return Err(failure);
            }
        },
    };
    bar.bar.finish_and_clear();
    let result = result?;
    if args.cpu {
        let cpu = super::cpu::process_cpu();
        eprintln!(
            "coordinator CPU: {:.3} s for {} simulated points: {:.1} us per simulated point",
            cpu.as_secs_f64(),
            result.stats.simulated,
            super::cpu::us_per(cpu, result.stats.simulated)
        );
    }
    report_result(&args, &campaign, &result)
}

fn report_result(
    args: &Args,
    campaign: &Campaign,
    calibration: &calibration::Calibration,
) -> Outcome {
    let out = results_root(&args.campaign, args.out.as_deref()).join(&campaign.name);
    let written = report::write(calibration, &out)?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report::result_json(calibration)).expect("plain data")
        );
    } else {
        print!("{}", report::table::summary(calibration));
        for path in written {
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}
