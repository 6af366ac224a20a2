use super::{Failure, Outcome};
use calib_coordinator::campaign::Campaign;
use calib_coordinator::evaluator::LocalEvaluator;
use calib_coordinator::sensitivity::{self, report, Methods, Settings, DEFAULT_SAMPLES};
use calib_coordinator::store::SledStore;
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
}

pub fn run(args: Args) -> Outcome {
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let db = args
        .db
        .clone()
        .unwrap_or_else(|| super::calibrate::default_db(&args.campaign));
    let store = SledStore::open(&db).map_err(|e| Failure::internal(e.to_string()))?;
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
