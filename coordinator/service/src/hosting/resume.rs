//! A coordinator that starts on an evaluation store finishes the campaigns a previous one
//! left running: each is replayed from the store (no stored evaluation is simulated again),
//! the missing points are simulated on the workers, and its `result.json` and plots are
//! written where `calib calibrate` would have put them. A campaign stopped because no
//! worker could do its points stays running, and is resumed again once a worker is up
//! ([`resume_until_finished`]).

use super::Campaigns;
use crate::dispatch::{Health, WorkerPool};
use calib_analysis::report;
use calib_engine::calibration::{self, Calibration};
use calib_engine::error::Result;
use calib_engine::optim::problem::Silent;
use calib_engine::store::{CampaignId, CampaignStatus};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::{Duration, Instant};

// The pauses between two resumes of campaigns that workers keep failing grow to the same
// bound as a live campaign's wait for workers.
use super::MAX_PAUSE;

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

/// Resume every unfinished campaign of the store of `campaigns`, through its dispatcher, and
/// write each one's results as it finishes, leaving alone the campaigns `skip` names
/// (submitted through the Calibration API and running in this coordinator already); the
/// number of campaigns finished. Blocks for as long as the campaigns run: call it on a
/// thread of its own, never on the async runtime.
pub fn resume_campaigns_except(
    campaigns: &Campaigns,
    results: Option<&Path>,
    skip: &dyn Fn(&CampaignId) -> bool,
) -> Result<usize> {
    let mut finished = 0;
    let (store, dispatcher) = (&*campaigns.store, &campaigns.dispatcher);
    calibration::resume_unfinished_through(store, dispatcher, &Silent, skip, |calibration| {
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

/// How a coordinator's resume loop is watched and stopped.
#[derive(Debug, Default)]
pub struct ResumeControl {
    /// Set to end the loop at its next pause.
    pub stop: AtomicBool,
    /// Passes over the store made so far.
    pub passes: AtomicUsize,
}

/// [`resume_campaigns_except`] again and again until the store holds no running campaign: after a
/// pass that left some running (their workers went away), wait until a worker of `pool` is
/// up and a pause has passed (doubling from the probe interval to a minute while passes keep
/// failing), then resume them. Ends early when `control.stop` is set; the number of
/// campaigns finished.
pub fn resume_until_finished(
    campaigns: &Campaigns,
    results: Option<&Path>,
    pool: &WorkerPool,
    control: &ResumeControl,
    skip: &dyn Fn(&CampaignId) -> bool,
) -> Result<usize> {
    let tick = pool.config().probe_interval.max(Duration::from_millis(10));
    let mut pause = tick;
    let mut finished = 0;
    loop {
        finished += resume_campaigns_except(campaigns, results, skip)?;
        control.passes.fetch_add(1, Ordering::SeqCst);
        let running = campaigns
            .store
            .campaigns()?
            .iter()
            .filter(|(id, r)| r.status == CampaignStatus::Running && !skip(id))
            .count();
        if running == 0 {
            return Ok(finished);
        }
        tracing::warn!(
            campaigns = running,
            "campaigns left unfinished: resumed once a worker is up"
        );
        let since = Instant::now();
        loop {
            if control.stop.load(Ordering::SeqCst) {
                return Ok(finished);
            }
            let up = pool.workers().iter().any(|w| w.health == Health::Up);
            if up && since.elapsed() >= pause {
                break;
            }
            std::thread::sleep(tick);
        }
        pause = (pause * 2).min(MAX_PAUSE);
    }
}
