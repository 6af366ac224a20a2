use super::{Failure, Outcome};
use calib_analysis::profile::{self, report, walk::DEFAULT_MAX_STEPS, Settings};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::store::SledStore;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Campaign file (TOML). Its best point comes from the store when the campaign has run
    /// there; otherwise it is calibrated first.
    campaign: PathBuf,
    /// Profile only this free parameter (repeat for several) [default: every one].
    #[arg(long = "parameter", value_name = "NAME")]
    parameters: Vec<String>,
    /// Most steps on each side of a profile before it is left open.
    #[arg(long, value_name = "N", default_value_t = DEFAULT_MAX_STEPS)]
    max_steps: usize,
    /// Print profile.json to standard output instead of the table.
    #[arg(long)]
    json: bool,
    /// Results folder: profile.json and the plots go to DIR/<campaign name>/profile/
    /// [default: results/ beside the campaign file].
    #[arg(long, value_name = "DIR")]
    out: Option<PathBuf>,
    #[command(flatten)]
    workers: super::WorkersArgs,
    /// Evaluation store (as `calib calibrate --db`): the campaign's best point is read from
    /// it, and points it holds are not simulated again [default: results/.calib-db beside
    /// the campaign file].
    #[arg(long, value_name = "DIR")]
    db: Option<PathBuf>,
}

pub fn run(args: Args) -> Outcome {
    let campaign = Campaign::load(&args.campaign).map_err(|e| Failure::input(e.to_string()))?;
    let settings = Settings {
        parameters: args.parameters.clone(),
        max_steps: args.max_steps,
    };
    settings.check().map_err(Failure::from)?;
    let db = args
        .db
        .clone()
        .unwrap_or_else(|| super::calibrate::default_db(&args.campaign));
    let store = SledStore::open(&db).map_err(|e| Failure::internal(e.to_string()))?;
    let result = match &args.workers.workers {
        None => profile::profile(&campaign, &LocalEvaluator, &store, &settings),
        Some(list) => {
            let status = super::workers::print_status;
            let workers = args.workers.connect_reporting(list, &status)?;
            super::workers::while_watching(&workers, &status, || {
                profile::profile(&campaign, &workers.evaluator(), &store, &settings)
            })
        }
    }?;
    let dir = super::calibrate::results_root(&args.campaign, args.out.as_deref())
        .join(&campaign.name)
        .join("profile");
    let written = report::write(&result, &dir)?;
    if args.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&report::profile_json(&result)).expect("plain data")
        );
    } else {
        print!("{}", report::table(&result));
        for path in written {
            println!("wrote {}", path.display());
        }
    }
    Ok(())
}
