//! Analyses of a campaign run in the coordinator on its workers and followed like
//! campaigns: the global sensitivity of a campaign before it is calibrated
//! ([`calib_analysis::sensitivity`]), and the profile likelihoods of a finished one
//! ([`calib_analysis::profile`]).
//!
//! An analysis is named by a hash of what it analyses (the campaign's identity, which
//! covers its data) and how (method, samples, seed): asked again, the same analysis is
//! joined while it runs and answered once it has finished. Its evaluations go through the
//! coordinator's store like a campaign's, so an analysis asked again after a restart
//! simulates nothing new.

use super::{Campaigns, Phase};
use calib_analysis::profile;
use calib_analysis::sensitivity::{self, report, Methods, Settings};
use calib_engine::calibration;
use calib_engine::campaign::{Campaign, CampaignSpec};
use calib_engine::error::{Error, Result};
use calib_engine::store::{hex, unhex32};
use calib_model::content_hash::ContentHasher;
use std::path::{Path, PathBuf};
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
    /// The report (`sensitivity.json`, `profile.json`) once finished.
    pub report: Option<AnalysisReport>,
    /// The sentence that sums it up, once finished.
    pub conclusion: String,
    /// The plots, by file name, once finished.
    pub files: Vec<(String, String)>,
}

/// The report of a finished analysis: the value of the JSON file it wrote.
#[derive(Debug, Clone, PartialEq)]
pub enum AnalysisReport {
    Sensitivity(serde_json::Value),
    Profile(serde_json::Value),
}

impl AnalysisReport {
    pub fn json(&self) -> &serde_json::Value {
        match self {
            AnalysisReport::Sensitivity(json) | AnalysisReport::Profile(json) => json,
        }
    }
}

/// What a finished analysis hands to those who follow it.
struct Finished {
    report: AnalysisReport,
    conclusion: String,
    /// Its SVG plots, by file name.
    files: Vec<(String, String)>,
    /// Evaluations in all, when it could not say beforehand (its `planned` was 0).
    evaluations: Option<u64>,
}

impl Campaigns {
    /// Follow the sensitivity analysis of the campaign `spec` with `settings`, starting it
    /// unless it is under way or done.
    pub fn sensitivity(
        self: &Arc<Self>,
        spec: CampaignSpec,
        settings: Settings,
    ) -> Result<watch::Receiver<AnalysisSnapshot>> {
        settings.check()?;
        let campaign = Campaign::from_spec(spec, &self.source())?;
        if campaign.free.is_empty() {
            return Err(Error::InvalidRequest(
                "campaign.parameters: no free parameter to analyse".into(),
            ));
        }
        let measurement = calibration::load_measurement(&campaign)?;
        // The window and the weights checked against the data now, not once running.
        calib_engine::objective::Objective::new(&campaign, &measurement)?;
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
        let planned = sensitivity::planned(campaign.free.len(), settings) as u64;
        let name = format!("sensitivity {}", campaign.name);
        self.analysis(h.finish(), planned, name, move |this, state, folder| {
            let progress = |done: usize, _planned: usize| {
                state.send_modify(|s| s.evaluations = done as u64);
            };
            let evaluator = this.dispatcher.evaluator();
            let s = sensitivity::analyse_through(
                &campaign,
                &evaluator,
                &*this.store,
                settings,
                &progress,
            )?;
            Ok(Finished {
                report: AnalysisReport::Sensitivity(report::sensitivity_json(&s)),
                conclusion: s.conclusion(),
                files: svg_files(report::write(&s, folder)),
                evaluations: None,
            })
        })
    }

    /// Follow the profile likelihoods of the finished campaign `id` around its best point,
    /// starting them unless they are under way or done; `None` when no campaign has that id.
    pub fn profile(
        self: &Arc<Self>,
        id: &str,
        settings: profile::Settings,
    ) -> Result<Option<watch::Receiver<AnalysisSnapshot>>> {
        settings.check()?;
        let Some(campaign_key) = unhex32(id) else {
            return Ok(None);
        };
        let Some(campaign) = self.finished(&campaign_key, id, "profile")? else {
            return Ok(None);
        };
        let mut h = ContentHasher::new(b"calib.profile.v1\0");
        h.bytes(&campaign_key)
            .count(settings.max_steps)
            .count(settings.parameters.len());
        for name in &settings.parameters {
            h.text(name);
        }
        let name = format!("profile {}", campaign.name);
        let receiver = self.analysis(h.finish(), 0, name, move |this, _state, folder| {
            let (engine, evaluator) = (&*this.engine, this.dispatcher.evaluator());
            let p =
                profile::profile_through(&campaign, &engine, &evaluator, &*this.store, &settings)?;
            let conclusions = p.conclusions();
            Ok(Finished {
                report: AnalysisReport::Profile(profile::report::profile_json(&p)),
                conclusion: if conclusions.is_empty() {
                    "Every profiled parameter is identifiable: its profile crosses the \
                     threshold on both sides."
                        .into()
                } else {
                    conclusions.join(" ")
                },
                files: svg_files(profile::report::write(&p, folder)),
                evaluations: Some(p.stats.evaluations.requested),
            })
        })?;
        Ok(Some(receiver))
    }

    /// Follow the analysis `id` this coordinator started; `None` when it has none so named.
    pub fn watch_analysis(&self, id: &str) -> Option<watch::Receiver<AnalysisSnapshot>> {
        let key = unhex32(id)?;
        let analyses = self.analyses.lock().expect("analyses lock");
        analyses.get(&key).map(|s| s.subscribe())
    }

    /// Follow the analysis `key`, starting `work` on a thread of its own (`name`) unless it
    /// is under way or done. `work` writes its files into the folder it is given
    /// (`<results>/analyses/<key>/`). A failed analysis is not kept: asked again, it starts
    /// afresh (its evaluations are stored).
    fn analysis(
        self: &Arc<Self>,
        key: [u8; 32],
        planned: u64,
        name: String,
        work: impl FnOnce(&Campaigns, &watch::Sender<AnalysisSnapshot>, &Path) -> Result<Finished>
            + Send
            + 'static,
    ) -> Result<watch::Receiver<AnalysisSnapshot>> {
        let mut analyses = self.analyses.lock().expect("analyses lock");
        if let Some(state) = analyses.get(&key) {
            return Ok(state.subscribe());
        }
        let (state, receiver) = watch::channel(AnalysisSnapshot {
            id: hex(&key),
            phase: Phase::Running,
            evaluations: 0,
            planned,
            failure: None,
            report: None,
            conclusion: String::new(),
            files: Vec::new(),
        });
        analyses.insert(key, state.clone());
        drop(analyses);
        let this = self.clone();
        let thread = name.clone();
        let run = move || {
            let folder = this.results.join("analyses").join(hex(&key));
            match work(&this, &state, &folder) {
                Ok(done) => state.send_modify(|s| {
                    s.phase = Phase::Finished;
                    if let Some(evaluations) = done.evaluations {
                        s.evaluations = evaluations;
                        s.planned = evaluations;
                    }
                    s.report = Some(done.report);
                    s.conclusion = done.conclusion;
                    s.files = done.files;
                }),
                Err(e) => {
                    tracing::error!(analysis = %name, error = %e, "analysis failed");
                    this.analyses.lock().expect("analyses lock").remove(&key);
                    state.send_modify(|s| {
                        s.phase = Phase::Failed;
                        s.failure = Some(e.to_string());
                    });
                }
            }
        };
        std::thread::Builder::new()
            .name(thread)
            .spawn(run)
            .map_err(|e| Error::Dispatch(format!("cannot start an analysis thread: {e}")))?;
        Ok(receiver)
    }
}

/// The SVG files a report wrote, by file name, with their text; none (and the reason
/// logged) when it could not write them.
fn svg_files(written: Result<Vec<PathBuf>>) -> Vec<(String, String)> {
    let paths = match written {
        Ok(paths) => paths,
        Err(e) => {
            tracing::error!(error = %e, "cannot write the analysis' files");
            return Vec::new();
        }
    };
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
