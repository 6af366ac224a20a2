//! Diagnoses of finished campaigns, run in the coordinator on its workers and followed
//! like campaigns: which physical effect the campaign's model lacks ([`crate::diagnosis`]).

use super::{Campaigns, Phase};
use crate::campaign::Campaign;
use crate::diagnosis::{self, report};
use crate::error::{Error, Result};
use crate::optim::problem::Progress;
use crate::store::{hex, unhex32, CampaignId};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use tokio::sync::watch;

/// A diagnosis' whole state at one moment.
#[derive(Debug, Clone, PartialEq)]
pub struct DiagnosisSnapshot {
    pub campaign_id: String,
    /// `Running`, `Finished` or `Failed`.
    pub phase: Phase,
    pub evaluations: u64,
    pub failure: Option<String>,
    /// `diagnosis.json` once finished.
    pub report: Option<serde_json::Value>,
    /// diagnosis.md and the plots, by file name, once finished.
    pub files: Vec<(String, String)>,
}

impl Campaigns {
    /// Follow the diagnosis of the finished campaign `id`, starting it unless it is under
    /// way or done; `None` when no campaign has that id.
    pub fn diagnose(
        self: &Arc<Self>,
        id: &str,
    ) -> Result<Option<watch::Receiver<DiagnosisSnapshot>>> {
        let Some(key) = unhex32(id) else {
            return Ok(None);
        };
        let mut diagnoses = self.diagnoses.lock().expect("diagnoses lock");
        if let Some(state) = diagnoses.get(&key) {
            return Ok(Some(state.subscribe()));
        }
        let Some(campaign) = self.finished(&key, id, "diagnose")? else {
            return Ok(None);
        };
        let (state, receiver) = watch::channel(DiagnosisSnapshot {
            campaign_id: hex(&key),
            phase: Phase::Running,
            evaluations: 0,
            failure: None,
            report: None,
            files: Vec::new(),
        });
        diagnoses.insert(key, state.clone());
        drop(diagnoses);
        let this = self.clone();
        std::thread::Builder::new()
            .name(format!("diagnosis {}", campaign.name))
            .spawn(move || this.run_diagnosis(key, campaign, state))
            .map_err(|e| Error::Dispatch(format!("cannot start a diagnosis thread: {e}")))?;
        Ok(Some(receiver))
    }

    fn run_diagnosis(
        &self,
        id: CampaignId,
        campaign: Campaign,
        state: watch::Sender<DiagnosisSnapshot>,
    ) {
        let progress = Counting {
            state: &state,
            evaluations: AtomicU64::new(0),
        };
        let engine = &*self.engine;
        match diagnosis::diagnose_with_store(&campaign, &engine, &*self.store, &progress) {
            Ok(d) => {
                let folder = self.results.join(hex(&id)).join("diagnosis");
                let mut files = Vec::new();
                match report::write(&d, &folder) {
                    Ok(paths) => {
                        for path in paths {
                            let keep = path.extension().is_some_and(|e| e == "svg" || e == "md");
                            if let (true, Ok(text)) = (keep, std::fs::read_to_string(&path)) {
                                let name = path.file_name().unwrap_or_default().to_string_lossy();
                                files.push((name.into_owned(), text));
                            }
                        }
                    }
                    Err(e) => tracing::error!(error = %e, "cannot write the diagnosis"),
                }
                let json = report::diagnosis_json(&d);
                state.send_modify(|s| {
                    s.phase = Phase::Finished;
                    s.evaluations = d.stats.evaluations.requested;
                    s.report = Some(json);
                    s.files = files;
                });
            }
            Err(e) => {
                tracing::error!(campaign = %campaign.name, error = %e, "diagnosis failed");
                // Not kept: asked again, it starts afresh (its evaluations are stored).
                self.diagnoses.lock().expect("diagnoses lock").remove(&id);
                state.send_modify(|s| {
                    s.phase = Phase::Failed;
                    s.failure = Some(e.to_string());
                });
            }
        }
    }
}

/// Counts a diagnosis' evaluations into its state.
struct Counting<'a> {
    state: &'a watch::Sender<DiagnosisSnapshot>,
    evaluations: AtomicU64,
}

impl Progress for Counting<'_> {
    fn evaluated(&self, count: usize, _best_objective: f64) {
        let total = self.evaluations.fetch_add(count as u64, Ordering::SeqCst) + count as u64;
        self.state.send_modify(|s| s.evaluations = total);
    }
}
