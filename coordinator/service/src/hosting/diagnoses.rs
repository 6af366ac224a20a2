//! Diagnoses of finished campaigns, run in the coordinator on its workers and followed
//! like campaigns: which physical effect the campaign's model lacks ([`calib_analysis::diagnosis`]),
//! and, when asked, what discovery finds outside the effect library
//! ([`calib_analysis::diagnosis::outside`]).

use super::{Campaigns, Phase};
use calib_analysis::diagnosis::outside::{found_outside_the_library, Found};
use calib_analysis::diagnosis::{self, report, Diagnosis};
use calib_engine::campaign::Campaign;
use calib_engine::error::{Error, Result};
use calib_engine::optim::problem::Progress;
use calib_engine::store::engine::StoredEngine;
use calib_engine::store::{hex, unhex32, CampaignId};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use tokio::sync::watch;

/// A diagnosis' whole state at one moment.
#[derive(Debug, Clone)]
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
    /// What discovery found, once finished, when it was asked for.
    pub found: Option<Arc<Found>>,
}

impl Campaigns {
    /// Follow the diagnosis of the finished campaign `id` (followed by discovery when
    /// `discover`), starting it unless it is under way or done; `None` when no campaign has
    /// that id.
    pub fn diagnose(
        self: &Arc<Self>,
        id: &str,
        discover: bool,
    ) -> Result<Option<watch::Receiver<DiagnosisSnapshot>>> {
        let Some(key) = unhex32(id) else {
            return Ok(None);
        };
        let mut diagnoses = self.diagnoses.lock().expect("diagnoses lock");
        if let Some(state) = diagnoses.get(&(key, discover)) {
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
            found: None,
        });
        diagnoses.insert((key, discover), state.clone());
        drop(diagnoses);
        let this = self.clone();
        std::thread::Builder::new()
            .name(format!("diagnosis {}", campaign.name))
            .spawn(move || this.run_diagnosis((key, discover), campaign, state))
            .map_err(|e| Error::Dispatch(format!("cannot start a diagnosis thread: {e}")))?;
        Ok(Some(receiver))
    }

    fn run_diagnosis(
        &self,
        (id, discover): (CampaignId, bool),
        campaign: Campaign,
        state: watch::Sender<DiagnosisSnapshot>,
    ) {
        let progress = Counting {
            state: &state,
            evaluations: AtomicU64::new(0),
        };
        let (engine, evaluator) = (&*self.engine, self.dispatcher.evaluator());
        let stored = StoredEngine::over(&evaluator, &engine);
        let outcome = diagnosis::diagnose_through(&campaign, &stored, &progress).and_then(|d| {
            let found = if discover {
                let found = found_outside_the_library(&d, &stored, &progress);
                if let Some(e) = stored.error() {
                    return Err(e.into());
                }
                Some(found?)
            } else {
                None
            };
            Ok((d, found))
        });
        match outcome {
            Ok((d, found)) => {
                // Apart from the plain diagnosis' folder: both may be asked for.
                let folder = if discover {
                    "diagnosis-discovery"
                } else {
                    "diagnosis"
                };
                let folder = self.results.join(hex(&id)).join(folder);
                let (json, files) = written(&d, found.as_ref(), &folder);
                let refitted: usize = found
                    .iter()
                    .flat_map(|f| &f.refits)
                    .map(|r| r.evaluations)
                    .sum();
                state.send_modify(|s| {
                    s.phase = Phase::Finished;
                    s.evaluations = d.stats.evaluations.requested + refitted as u64;
                    s.report = Some(json);
                    s.files = files;
                    s.found = found.map(Arc::new);
                });
            }
            Err(e) => {
                tracing::error!(campaign = %campaign.name, error = %e, "diagnosis failed");
                // Not kept: asked again, it starts afresh (its evaluations are stored).
                self.diagnoses
                    .lock()
                    .expect("diagnoses lock")
                    .remove(&(id, discover));
                state.send_modify(|s| {
                    s.phase = Phase::Failed;
                    s.failure = Some(e.to_string());
                });
            }
        }
    }
}

/// Write the diagnosis (with what discovery found) into `folder`: diagnosis.json's value,
/// and diagnosis.md and the plots by file name.
fn written(
    d: &Diagnosis,
    found: Option<&Found>,
    folder: &std::path::Path,
) -> (serde_json::Value, Vec<(String, String)>) {
    let mut json = report::diagnosis_json(d);
    if let Some(found) = found {
        json["found_outside_the_library"] = found.json();
    }
    let mut files = Vec::new();
    match report::write(d, folder) {
        Ok(paths) => {
            for path in paths {
                let keep = path.extension().is_some_and(|e| e == "svg" || e == "md");
                if let (true, Ok(mut text)) = (keep, std::fs::read_to_string(&path)) {
                    let name = path.file_name().unwrap_or_default().to_string_lossy();
                    if let (Some(found), "diagnosis.md") = (found, name.as_ref()) {
                        text.push_str(&found.markdown());
                        write_or_log(&path, &text);
                    }
                    files.push((name.into_owned(), text));
                }
            }
            if found.is_some() {
                let text = serde_json::to_string_pretty(&json).expect("plain data") + "\n";
                write_or_log(&folder.join("diagnosis.json"), &text);
            }
        }
        Err(e) => tracing::error!(error = %e, "cannot write the diagnosis"),
    }
    (json, files)
}

fn write_or_log(path: &std::path::Path, text: &str) {
    if let Err(e) = std::fs::write(path, text) {
        tracing::error!(path = %path.display(), error = %e, "cannot write");
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
