//! A coordinator that starts on an evaluation store finishes the campaigns a previous one
//! left running: each is replayed from the store (no stored evaluation is simulated again),
//! the missing points are simulated on the workers, and its `result.json` and plots are
//! written where `calib calibrate` would have put them.

use crate::calibration::{self, Calibration};
use crate::error::Result;
use crate::evaluator::Evaluator;
use crate::optim::problem::Silent;
use crate::report;
use crate::store::Store;
use std::path::{Path, PathBuf};

/// Where the results of a resumed campaign go: `<results>/<name>/` when `results` is given,
/// else `results/<name>/` beside the campaign file, as `calib calibrate` does by default.
pub fn result_folder(calibration: &Calibration, results: Option<&Path>) -> PathBuf {
    let name = &calibration.campaign.name;
    match results {
        Some(folder) => folder.join(name),
        None => calibration
            .campaign
            .source
            .as_deref()
            .and_then(Path::parent)
            .unwrap_or(Path::new("."))
            .join("results")
            .join(name),
    }
}

/// Resume every unfinished campaign of `store` through `evaluator` and write each one's
/// results as it finishes; the number of campaigns finished. Blocks for as long as the
/// campaigns run: call it on a thread of its own, never on the async runtime.
pub fn resume_campaigns<E: Evaluator>(
    store: &dyn Store,
    evaluator: &E,
    results: Option<&Path>,
) -> Result<usize> {
    let mut finished = 0;
    calibration::resume_unfinished_each(store, evaluator, &Silent, |calibration| {
        finished += 1;
        let folder = result_folder(&calibration, results);
        let best = calibration.best_run();
        match report::write(&calibration, &folder) {
            Ok(_) => tracing::info!(
                campaign = %calibration.campaign.name,
                objective = best.objective,
                simulated = calibration.stats.simulated,
                cached = calibration.stats.cached,
                results = %folder.display(),
                "resumed campaign finished"
            ),
            // The result stays in the store (`calib store export`): only the files are lost.
            Err(e) => tracing::error!(
                campaign = %calibration.campaign.name,
                objective = best.objective,
                error = %e,
                "resumed campaign finished, but its results cannot be written"
            ),
        }
    })?;
    Ok(finished)
}
