use super::{Failure, Outcome};
use calib_analysis::sensitivity::{self, local, report, Methods, Settings, DEFAULT_SAMPLES};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::outcome::CalibrationOutcome;
use calib_engine::store::SledStore;
use std::path::PathBuf;

/// Which analysis to run.
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
enum Method {
    /// Morris elementary effects (μ*, σ): `samples` trajectories of parameters + 1 points.
    Morris,
    /// Sobol first-order and total indices: a Saltelli design of `samples` base samples,
    /// samples · (parameters + 2) points.
    Sobol,
}

#[derive(clap::Args)]
pub struct Args {
    /// Campaign file (TOML): its free parameters are varied over their bounds, on their
    /// scale.
    campaign: PathBuf,
    /// Analysis to run [default: both].
    #[arg(long, value_enum)]
    method: Option<Method>,
    /// Base samples of the Sobol design and trajectories of the Morris design.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_SAMPLES)]
    samples: usize,
    /// Seed of the designs and of the bootstrap.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Print sensitivity.json to standard output instead of the table.
    #[arg(long)]
    json: bool,
    /// Results folder: sensitivity.json and the bar charts go to
    /// DIR/<campaign name>/sensitivity/ [default: results/ beside the campaign file].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    #[command(flatten)]
    workers: super::WorkersArgs,
    /// Evaluation store (as `calib calibrate --db`): points it holds are not simulated
    /// again [default: results/.calib-db beside the campaign file].
    #[arg(long, value_name = "DIR")]
    db: Option<PathBuf>,
    /// A calibration's result.json: also take the local sensitivity of each output to each
    /// parameter at its best point, so that a parameter is called fixable only when it is
    /// negligible both over the bounds and at the fit [default: the result the store holds
    /// for this campaign, when `calib calibrate` recorded one there].
    #[arg(long, value_name = "RESULT.json", conflicts_with = "no_fit")]
    at: Option<PathBuf>,
    /// Judge over the bounds alone, even where the store holds a result of the campaign.
    #[arg(long)]
    no_fit: bool,
}

pub fn run(args: Args) -> Outcome {
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let db = args
        .db
        .clone()
        .unwrap_or_else(|| super::calibrate::default_db(&args.campaign));
    let store = SledStore::open(&db).map_err(|e| Failure::internal(e.to_string()))?;
    // The fit's point first: a result that does not fit the campaign is refused before the
    // designs run.
    let fit = match fit_result(&args, &campaign, &store)? {
        Some((outcome, source)) => {
            let point = local::best_point(&campaign, &outcome, &source)
                .map_err(|e| Failure::input(e.to_string()))?;
            Some((point, outcome.best.objective, source))
        }
        None => None,
    };
    let settings = Settings {
        methods: match args.method {
            None => Methods::Both,
            Some(Method::Morris) => Methods::Morris,
            Some(Method::Sobol) => Methods::Sobol,
        },
        samples: args.samples,
        seed: args.seed,
    };
    // Progress on standard error, a line per slice of the designs.
    let progress = |done: usize, planned: usize| {
        if done > 0 {
            eprintln!("sensitivity: {done} of {planned} evaluations");
        }
    };
    let result = match &args.workers.workers {
        None => {
            sensitivity::analyse_reporting(&campaign, LocalEvaluator, &store, settings, &progress)
        }
        Some(list) => {
            let status = super::workers::print_status;
            let workers = args.workers.connect_reporting(list, &status)?;
            super::workers::while_watching(&workers, &status, || {
                sensitivity::analyse_reporting(
                    &campaign,
                    workers.evaluator(),
                    &store,
                    settings,
                    &progress,
                )
            })
        }
    }?;
    let mut result = result;
    if let Some((point, objective, source)) = fit {
        let at_fit = match &args.workers.workers {
            None => local::at_fit(&campaign, &LocalEvaluator, &point, objective, source),
            Some(list) => {
                let workers = args.workers.connect(list)?;
                local::at_fit(&campaign, &workers.evaluator(), &point, objective, source)
            }
        }?;
        result.at_fit = Some(at_fit);
    }
    let dir = super::calibrate::results_root(&args.campaign, args.out.as_deref())
        .join(&campaign.name)
        .join("sensitivity");
    let written = report::write(&result, &dir)?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report::sensitivity_json(&result)).expect("plain data")
        );
    } else {
        print!("{}", report::table(&result));
        for path in written {
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}

/// The calibration result whose best point the local sensitivities are taken at, and how
/// to name it: `--at`'s file, else the store's result of the campaign, unless `--no-fit`.
fn fit_result(
    args: &Args,
    campaign: &Campaign,
    store: &SledStore,
) -> Result<Option<(CalibrationOutcome, String)>, Failure> {
    if args.no_fit {
        return Ok(None);
    }
    if let Some(path) = &args.at {
        let outcome = local::read_result(path).map_err(|e| Failure::input(e.to_string()))?;
        return Ok(Some((outcome, path.display().to_string())));
    }
    let stored = local::stored_result(campaign, store)?;
    Ok(stored.map(|o| (o, format!("the stored calibration of {}", campaign.name))))
}
