//! Analyses of a campaign run in the coordinator on its workers and followed like
//! campaigns: the global sensitivity of a campaign before it is calibrated
//! ([`crate::sensitivity`]), and the profile likelihoods of a finished one
//! ([`crate::profile`]).
//!
//! An analysis is named by a hash of what it analyses (the campaign's identity, which
//! covers its data) and how (method, samples, seed): asked again, the same analysis is
//! joined while it runs and answered once it has finished. Its evaluations go through the
//! coordinator's store like a campaign's, so an analysis asked again after a restart
//! simulates nothing new.

use super::{Campaigns, Phase};
use crate::calibration;
use crate::campaign::Campaign;
use crate::error::{Error, Result};
use crate::profile;
use crate::sensitivity::{self, report, Methods, Settings};
use crate::store::{hex, unhex32, CampaignStatus};
use calib_worker::content_hash::ContentHasher;
use std::sync::Arc;
use tokio::sync::watch;

/// An analysis' whole state at one moment.
#[derive(Debug, Clone, PartialEq)]
pub struct AnalysisSnapshot {
    pub id: String,
    /// `Running`, `Finished` or `Failed`.
    pub phase: Phase,
    pub evaluations: u64,
    pub planned: u64,
    pub failure: Option<String>,
    /// The report (`sensitivity.json`) once finished.
    pub report: Option<serde_json::Value>,
    /// The sentence that sums it up, once finished.
    pub conclusion: String,
    /// The plots, by file name, once finished.
    pub files: Vec<(String, String)>,
}

impl Campaigns {
    /// Follow the sensitivity analysis of the campaign file `spec` with `settings`,
    /// starting it unless it is under way or done.
    pub fn sensitivity(
        self: &Arc<Self>,
        spec: &str,
        settings: Settings,
    ) -> Result<watch::Receiver<AnalysisSnapshot>> {
        let campaign = Campaign::parse(spec, &self.source())?;
        if campaign.free.is_empty() {
            return Err(Error::InvalidRequest(
                "campaign.parameters: no free parameter to analyse".into(),
            ));
        }
        let measurement = calibration::load_measurement(&campaign)?;
        let identity = campaign.identity(&measurement.content_hash());
        let mut h = ContentHasher::new(b"calib.sensitivity.v1\0");
        h.bytes(&identity)
            .text(match settings.methods {
                Methods::Morris => "morris",
                Methods::Sobol => "sobol",
                Methods::Both => "both",
            })
            .count(settings.samples)
            .bytes(&settings.seed.to_le_bytes());
        let key = h.finish();
        let mut analyses = self.analyses.lock().expect("analyses lock");
        if let Some(state) = analyses.get(&key) {
            return Ok(state.subscribe());
        }
        let (state, receiver) = watch::channel(AnalysisSnapshot {
            id: hex(&key),
            phase: Phase::Running,
            evaluations: 0,
            planned: sensitivity::planned(campaign.free.len(), settings) as u64,
            failure: None,
            report: None,
            conclusion: String::new(),
            files: Vec::new(),
        });
        analyses.insert(key, state.clone());
        drop(analyses);
        let this = self.clone();
        std::thread::Builder::new()
            .name(format!("sensitivity {}", campaign.name))
            .spawn(move || this.run_sensitivity(key, campaign, settings, state))
            .map_err(|e| Error::Dispatch(format!("cannot start an analysis thread: {e}")))?;
        Ok(receiver)
    }

    /// Follow the profile likelihoods of the finished campaign `id` around its best point,
    /// starting them unless they are under way or done; `None` when no campaign has that id.
    pub fn profile(
        self: &Arc<Self>,
        id: &str,
        settings: profile::Settings,
    ) -> Result<Option<watch::Receiver<AnalysisSnapshot>>> {
        let Some(campaign_key) = unhex32(id) else {
            return Ok(None);
        };
        let Some(record) = self.store.campaign(&campaign_key)? else {
            return Ok(None);
        };
        let running = self.is_live(&campaign_key)
            && self
                .live
                .lock()
                .expect("live lock")
                .get(&campaign_key)
                .is_some_and(|l| l.state.borrow().phase != Phase::Finished);
        if running || record.status != CampaignStatus::Finished {
            return Err(Error::InvalidRequest(format!(
                "id: campaign `{id}` has not finished; profile it once it has"
            )));
        }
        let campaign = Campaign::parse(&record.spec, &record.source)?;
        let mut h = ContentHasher::new(b"calib.profile.v1\0");
        h.bytes(&campaign_key)
            .count(settings.max_steps)
            .count(settings.parameters.len());
        for name in &settings.parameters {
            h.text(name);
        }
        let key = h.finish();
        let mut analyses = self.analyses.lock().expect("analyses lock");
        if let Some(state) = analyses.get(&key) {
            return Ok(Some(state.subscribe()));
        }
        let (state, receiver) = watch::channel(AnalysisSnapshot {
            id: hex(&key),
            phase: Phase::Running,
            evaluations: 0,
            planned: 0,
            failure: None,
            report: None,
            conclusion: String::new(),
            files: Vec::new(),
        });
        analyses.insert(key, state.clone());
        drop(analyses);
        let this = self.clone();
        std::thread::Builder::new()
            .name(format!("profile {}", campaign.name))
            .spawn(move || this.run_profile(key, campaign, settings, state))
            .map_err(|e| Error::Dispatch(format!("cannot start an analysis thread: {e}")))?;
        Ok(Some(receiver))
    }

    fn run_profile(
        &self,
        key: [u8; 32],
        campaign: Campaign,
        settings: profile::Settings,
        state: watch::Sender<AnalysisSnapshot>,
    ) {
        let engine = &*self.engine;
        match profile::profile(&campaign, &engine, &*self.store, &settings) {
            Ok(p) => {
                let folder = self.results.join("analyses").join(hex(&key));
                let files = match profile::report::write(&p, &folder) {
                    Ok(paths) => svg_files(paths),
                    Err(e) => {
                        tracing::error!(error = %e, "cannot write the profiles");
                        Vec::new()
                    }
                };
                let json = profile::report::profile_json(&p);
                let conclusions = p.conclusions();
                state.send_modify(|snapshot| {
                    snapshot.phase = Phase::Finished;
                    snapshot.evaluations = p.stats.evaluations.requested;
                    snapshot.planned = snapshot.evaluations;
                    snapshot.report = Some(json);
                    snapshot.conclusion = if conclusions.is_empty() {
                        "Every profiled parameter is identifiable: its profile crosses the \
                         threshold on both sides."
                            .into()
                    } else {
                        conclusions.join(" ")
                    };
                    snapshot.files = files;
                });
            }
            Err(e) => {
                tracing::error!(campaign = %campaign.name, error = %e, "profile failed");
                self.analyses.lock().expect("analyses lock").remove(&key);
                state.send_modify(|s| {
                    s.phase = Phase::Failed;
                    s.failure = Some(e.to_string());
                });
            }
        }
    }

    /// Follow the analysis `id` this coordinator started; `None` when it has none so named.
    pub fn watch_analysis(&self, id: &str) -> Option<watch::Receiver<AnalysisSnapshot>> {
        let key = unhex32(id)?;
        let analyses = self.analyses.lock().expect("analyses lock");
        analyses.get(&key).map(|s| s.subscribe())
    }

    fn run_sensitivity(
        &self,
        key: [u8; 32],
        campaign: Campaign,
        settings: Settings,
        state: watch::Sender<AnalysisSnapshot>,
    ) {
        let engine = &*self.engine;
        let progress = |done: usize, _planned: usize| {
            state.send_modify(|s| s.evaluations = done as u64);
        };
        let analysed =
            sensitivity::analyse_reporting(&campaign, engine, &*self.store, settings, &progress);
        match analysed {
            Ok(s) => {
                let folder = self.results.join("analyses").join(hex(&key));
                let files = match report::write(&s, &folder) {
                    Ok(paths) => svg_files(paths),
                    Err(e) => {
                        tracing::error!(error = %e, "cannot write the sensitivity analysis");
                        Vec::new()
                    }
                };
                let json = report::sensitivity_json(&s);
                state.send_modify(|snapshot| {
                    snapshot.phase = Phase::Finished;
                    snapshot.report = Some(json);
                    snapshot.conclusion = s.conclusion();
                    snapshot.files = files;
                });
            }
            Err(e) => {
                tracing::error!(campaign = %campaign.name, error = %e, "sensitivity analysis failed");
                // Not kept: asked again, it starts afresh (its evaluations are stored).
                self.analyses.lock().expect("analyses lock").remove(&key);
                state.send_modify(|s| {
                    s.phase = Phase::Failed;
                    s.failure = Some(e.to_string());
                });
            }
        }
    }
}

/// The SVG files among `paths`, by file name, with their text.
fn svg_files(paths: Vec<std::path::PathBuf>) -> Vec<(String, String)> {
    paths
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "svg"))
        .filter_map(|p| {
            let text = std::fs::read_to_string(&p).ok()?;
            let name = p.file_name()?.to_string_lossy().into_owned();
            Some((name, text))
        })
        .collect()
}
