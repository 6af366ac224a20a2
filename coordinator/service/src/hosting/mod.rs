//! Campaigns submitted to a long-lived coordinator: started at once on its workers, followed
//! while they run, cancelled on request, and kept in its evaluation store.
//!
//! A submitted campaign is a campaign file like any other (the API writes one from its
//! message), resolved by the same loader, run by the same [`calibration::calibrate_with_store`]
//! as `calib calibrate`, so both give the same runs. Its id is the campaign's identity in
//! the store (a hash of the resolved campaign and its data): submitting the same campaign
//! twice starts it once.
//!
//! **Sharing the workers.** Every campaign runs all its runs at once, each asking the
//! worker pool for slots batch by batch; a freed slot goes to whichever waiting batch takes
//! it first, whatever its campaign. A campaign's share is thus the share of the batches it
//! has waiting: two campaigns of the same size split the workers evenly, and no campaign
//! waits for another to finish.
//!
//! **No workers.** A campaign whose batch no worker could do stays running: it waits, with
//! growing pauses (at most [`MAX_PAUSE`]), and resumes from the store when workers are back.

pub mod analyses;
pub mod datasets;
pub mod diagnoses;
pub mod fmus;
pub mod history;
pub mod resume;
mod running;

use calib_analysis::report;
use calib_engine::calibration::{self, Calibration};
use calib_engine::campaign::{Campaign, CampaignSpec};
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::CacheStats;
use calib_engine::evaluator::{Evaluator, Fault, FaultKind, Simulator};
use calib_engine::objective::{Evaluation, Objective};
use calib_engine::optim::problem::Progress;
use calib_engine::store::{
    hex, unhex32, CampaignId, CampaignRecord, CampaignStatus, RunBest, SharedDispatcher, Store,
    StoreError, Stored,
};
use datasets::Datasets;
use fmus::Fmus;
use history::History;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::sync::watch;

/// Longest pause before a campaign without workers tries again, whether it runs live or is
/// resumed from the store ([`resume`]).
pub const MAX_PAUSE: Duration = Duration::from_secs(30);

/// Where a campaign stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    Running,
    Finished,
    Failed,
    Cancelled,
}

impl Phase {
    pub fn ended(self) -> bool {
        self != Phase::Running
    }
}

/// A campaign's whole state at one moment.
#[derive(Debug, Clone, PartialEq)]
pub struct Snapshot {
    pub id: String,
    pub name: String,
    pub phase: Phase,
    /// Evaluations so far (store hits included).
    pub evaluations: u64,
    /// Best objective so far per run, in plan order (`+∞` before a run's first point).
    pub run_best: Vec<f64>,
    pub best_objective: f64,
    pub failure: Option<String>,
    /// What it found (its `result.json`) once finished.
    pub result: Option<calib_engine::outcome::CalibrationOutcome>,
    /// The plots `calib calibrate` writes, by file name (SVG text), once finished here.
    pub plots: Vec<(String, String)>,
    /// The API's `Campaign` message it was submitted with (JSON), when it was.
    pub message: Option<serde_json::Value>,
    /// Names of the free parameters, in the order of a run's point.
    pub free: Vec<String>,
    /// Each run's method, start, best point and objective so far and evaluations, in plan
    /// order (runs yet to evaluate a point have an empty point and `+∞`).
    pub runs: Vec<RunBest>,
    /// Its progress over time.
    pub history: History,
}

impl Snapshot {
    fn running(id: &str, name: &str) -> Self {
        Self {
            id: id.into(),
            name: name.into(),
            phase: Phase::Running,
            evaluations: 0,
            run_best: Vec::new(),
            best_objective: f64::INFINITY,
            failure: None,
            result: None,
            plots: Vec::new(),
            message: None,
            free: Vec::new(),
            runs: Vec::new(),
            history: History::default(),
        }
    }

    /// What the store says of a campaign no thread of this coordinator is running.
    fn from_record(id: &CampaignId, record: &CampaignRecord) -> Self {
        let mut s = Self::running(&hex(id), &record.name);
        s.phase = match record.status {
            CampaignStatus::Running => Phase::Running,
            CampaignStatus::Finished => Phase::Finished,
            CampaignStatus::Failed => Phase::Failed,
            CampaignStatus::Cancelled => Phase::Cancelled,
        };
        s.failure = record.failure.clone();
        s.result = record.result.clone();
        s.run_best = record.runs.iter().map(|r| r.objective).collect();
        s.best_objective = s.run_best.iter().copied().fold(f64::INFINITY, f64::min);
        s.history = History::from_points(record.history.clone());
        // The result's count (the nominal point and the screening included), else the
        // last the campaign's progress told.
        s.evaluations = record
            .result
            .as_ref()
            .map(|r| r.evaluations)
            .or_else(|| record.history.last().map(|p| p.evaluations))
            .unwrap_or_else(|| record.runs.iter().map(|r| r.evaluations as u64).sum());
        s.message = record.message.clone();
        s.free = record.free.clone();
        s.runs = record.runs.clone();
        s
    }
}

/// What runs a coordinator's campaigns and diagnoses: objective evaluations and
/// trajectories, on its workers.
pub trait Engine: Evaluator + Simulator {}

impl<T: Evaluator + Simulator + ?Sized> Engine for T {}

/// A campaign running in this coordinator.
struct Live {
    cancel: AtomicBool,
    state: watch::Sender<Snapshot>,
}

/// The campaigns of one coordinator.
pub struct Campaigns {
    store: Arc<dyn Store>,
    engine: Arc<dyn Engine>,
    /// The one dispatcher every hosted campaign's evaluations go through: a point one
    /// campaign has in flight is simulated once for all, one writer stores every answer.
    dispatcher: SharedDispatcher<dyn Engine>,
    datasets: Datasets,
    /// Uploaded FMUs, when this coordinator takes them.
    fmus: Option<Fmus>,
    /// `<results>/<id>/` holds each finished campaign's result.json and plots.
    results: PathBuf,
    live: Mutex<HashMap<CampaignId, Arc<Live>>>,
    keys: Mutex<HashMap<String, CampaignId>>,
    /// Held while a record is read, changed and written back here.
    records: Mutex<()>,
    /// By campaign, and whether discovery follows the diagnosis.
    diagnoses: Mutex<HashMap<(CampaignId, bool), watch::Sender<diagnoses::DiagnosisSnapshot>>>,
    analyses: Mutex<HashMap<[u8; 32], watch::Sender<analyses::AnalysisSnapshot>>>,
}

impl Campaigns {
    pub fn new(
        store: Arc<dyn Store>,
        engine: Arc<dyn Engine>,
        datasets: Datasets,
        results: PathBuf,
    ) -> Self {
        Self {
            dispatcher: SharedDispatcher::start(engine.clone(), store.clone()),
            store,
            engine,
            datasets,
            fmus: None,
            results,
            live: Mutex::new(HashMap::new()),
            keys: Mutex::new(HashMap::new()),
            records: Mutex::new(()),
            diagnoses: Mutex::new(HashMap::new()),
            analyses: Mutex::new(HashMap::new()),
        }
    }

    /// The campaign `key` (`id` as the client gave it) once it has finished, for what is
    /// done to finished campaigns only (`verb` it: diagnose, profile); `None` when the store
    /// has no such campaign, an error naming its phase when it has not finished.
    pub(crate) fn finished(
        &self,
        key: &CampaignId,
        id: &str,
        verb: &str,
    ) -> Result<Option<Campaign>> {
        let live_phase = self
            .live
            .lock()
            .expect("live lock")
            .get(key)
            .map(|l| l.state.borrow().phase);
        if let Some(phase) = live_phase.filter(|p| *p != Phase::Finished) {
            return Err(Error::InvalidRequest(format!(
                "id: campaign `{id}` has not finished ({phase:?}); {verb} it once it has"
            )));
        }
        let Some(record) = self.store.campaign(key)? else {
            return Ok(None);
        };
        if record.status != CampaignStatus::Finished {
            return Err(Error::InvalidRequest(format!(
                "id: campaign `{id}` has not finished ({:?}); {verb} it once it has",
                record.status
            )));
        }
        Ok(Some(Campaign::parse(&record.spec, &record.source)?))
    }

    /// Whether this coordinator runs campaign `id` (the store's resume leaves it alone).
    pub fn is_live(&self, id: &CampaignId) -> bool {
        self.live.lock().expect("live lock").contains_key(id)
    }

    pub fn datasets(&self) -> &Datasets {
        &self.datasets
    }

    /// Take uploaded FMUs, kept in `fmus`.
    pub fn with_fmus(mut self, fmus: Fmus) -> Self {
        self.fmus = Some(fmus);
        self
    }

    /// The uploaded FMUs; an error when this coordinator takes none.
    pub fn fmus(&self) -> Result<&Fmus> {
        self.fmus
            .as_ref()
            .ok_or_else(|| Error::InvalidRequest("fmu: this server keeps no uploaded FMUs".into()))
    }

    /// Where campaign files written for submitted campaigns are said to be (errors name it).
    pub fn source(&self) -> PathBuf {
        self.datasets.folder().join("submitted-campaign.toml")
    }

    /// `message` as a client may read it: the files this coordinator writes for submitted
    /// campaigns and uploads named as what they are, not by their paths on this machine.
    pub fn public(&self, message: &str) -> String {
        let source = self.source().display().to_string();
        let folder = format!("{}/", self.datasets.folder().display());
        let results = format!("{}/", self.results.display());
        let mut message = message
            .replace(&format!("{source}: "), "")
            .replace(&source, "the campaign")
            .replace(&folder, "dataset ")
            .replace(&results, "results ");
        if let Some(fmus) = &self.fmus {
            message = message.replace(&format!("{}/", fmus.folder().display()), "FMU ");
        }
        message
    }

    /// The campaign `spec` resolved, its measurement loaded, and both checked against
    /// each other (the window and the weights against the data), as [`Campaigns::submit`]
    /// checks a campaign before starting it; nothing is started.
    pub fn check(
        &self,
        spec: CampaignSpec,
    ) -> Result<(Campaign, calib_engine::measurement::Measurement)> {
        let campaign = Campaign::from_spec(spec, &self.source())?;
        let measurement = calibration::load_measurement(&campaign)?;
        Objective::new(&campaign, &measurement)?;
        Ok((campaign, measurement))
    }

    /// Start the campaign `spec` (its measurement a dataset of this coordinator), unless it
    /// is known already; its id, and whether it was started now.
    pub fn submit(
        self: &Arc<Self>,
        spec: CampaignSpec,
        idempotency_key: Option<&str>,
    ) -> Result<(String, bool)> {
        self.submit_message(spec, idempotency_key, None)
    }

    /// [`Campaigns::submit`], keeping with the campaign the API's `message` (JSON) it was
    /// written from, unless the campaign has one already: what a client reopening it edits.
    pub fn submit_message(
        self: &Arc<Self>,
        spec: CampaignSpec,
        idempotency_key: Option<&str>,
        message: Option<serde_json::Value>,
    ) -> Result<(String, bool)> {
        let mut keys = self.keys.lock().expect("keys lock");
        if let Some(id) = idempotency_key.and_then(|k| keys.get(k)) {
            return Ok((hex(id), false));
        }
        let (campaign, measurement) = self.check(spec)?;
        let id = campaign.identity(&measurement.content_hash());
        if let Some(k) = idempotency_key {
            keys.insert(k.to_string(), id);
        }
        drop(keys);
        let dataset = measurement.content_hash();
        let keep = |message: Option<serde_json::Value>| match message {
            Some(m) => self.keep_message(&id, &campaign, &dataset, m),
            None => Ok(()),
        };
        let mut live = self.live.lock().expect("live lock");
        if let Some(running) = live.get(&id) {
            let phase = running.state.borrow().phase;
            if phase == Phase::Running && running.cancel.load(Ordering::SeqCst) {
                return Err(Error::InvalidRequest(format!(
                    "campaign `{}` ({}) is stopping after a cancel; submit it again once it \
                     has stopped",
                    campaign.name,
                    hex(&id)
                )));
            }
            if !Self::runs_again(phase) {
                keep(message)?;
                return Ok((hex(&id), false));
            }
        } else if let Some(record) = self.store.campaign(&id)? {
            // Finished before, or left running by an earlier coordinator, which
            // `resume_submitted` started again when this one started.
            let phase = Snapshot::from_record(&id, &record).phase;
            if !Self::runs_again(phase) {
                keep(message)?;
                return Ok((hex(&id), false));
            }
        }
        keep(message)?;
        self.start(&mut live, id, campaign)?;
        Ok((hex(&id), true))
    }

    /// Record `message` as what campaign `id` was submitted with, unless its record has one.
    fn keep_message(
        &self,
        id: &CampaignId,
        campaign: &Campaign,
        dataset: &CampaignId,
        message: serde_json::Value,
    ) -> Result<()> {
        let _guard = self.records.lock().expect("records lock");
        let record = match self.store.campaign(id)? {
            Some(record) if record.message.is_some() => return Ok(()),
            Some(record) => record,
            // Not run yet: recorded as running, as the calibration records it when it starts.
            None => CampaignRecord {
                name: campaign.name.clone(),
                spec: campaign.spec.clone(),
                source: campaign.source.clone().unwrap_or_default(),
                dataset: hex(dataset),
                status: CampaignStatus::Running,
                runs: Vec::new(),
                result: None,
                failure: None,
                message: None,
                free: campaign.free.iter().map(|p| p.name.clone()).collect(),
                history: Vec::new(),
            },
        };
        self.store.put_campaign(
            id,
            &CampaignRecord {
                message: Some(message),
                ..record
            },
        )?;
        Ok(())
    }

    /// Whether a campaign submitted again in `phase` starts again: a cancelled or failed
    /// campaign does (under its id, replaying from the store what it had evaluated), a
    /// running or finished one is the answer already.
    fn runs_again(phase: Phase) -> bool {
        matches!(phase, Phase::Cancelled | Phase::Failed)
    }

    /// Start again every campaign submitted to this API that an earlier coordinator left
    /// running, as live campaigns: replayed from the store, they simulate only what it
    /// lacks, and clients watching them see their progress and result as for any campaign.
    /// (Other campaigns the store holds unfinished, from `calib calibrate`, are finished by
    /// the server's resume of the store.) How many were started.
    pub fn resume_submitted(self: &Arc<Self>) -> Result<usize> {
        let mut started = 0;
        for (id, record) in self.store.campaigns()? {
            if record.status != CampaignStatus::Running || record.source != self.source() {
                continue;
            }
            // A campaign that no longer resolves to its id (its data gone, a model of
            // another version) is left to the store's resume, which says why and closes it.
            let Ok(campaign) = Campaign::parse(&record.spec, &record.source) else {
                continue;
            };
            let Ok(measurement) = calibration::load_measurement(&campaign) else {
                continue;
            };
            if campaign.identity(&measurement.content_hash()) != id {
                continue;
            }
            let mut live = self.live.lock().expect("live lock");
            if live.contains_key(&id) {
                continue;
            }
            tracing::info!(campaign = %campaign.name, id = %hex(&id), "resuming submitted campaign");
            self.start(&mut live, id, campaign)?;
            started += 1;
        }
        Ok(started)
    }

    /// What the store says of campaign `id`, its failure as a client may read it.
    fn stored(&self, id: &CampaignId, record: &CampaignRecord) -> Snapshot {
        let mut snapshot = Snapshot::from_record(id, record);
        snapshot.failure = snapshot.failure.map(|f| self.public(&f));
        snapshot
    }

    fn parse_id(id: &str) -> Option<CampaignId> {
        unhex32(id)
    }

    /// The campaign `id` now, if this coordinator knows it.
    pub fn get(&self, id: &str) -> Result<Option<Snapshot>> {
        let Some(key) = Self::parse_id(id) else {
            return Ok(None);
        };
        if let Some(live) = self.live.lock().expect("live lock").get(&key) {
            return Ok(Some(live.state.borrow().clone()));
        }
        Ok(self
            .store
            .campaign(&key)?
            .map(|record| self.stored(&key, &record)))
    }

    /// The campaign file campaign `id` was run from, if the store holds it.
    pub fn spec(&self, id: &str) -> Result<Option<String>> {
        let Some(key) = Self::parse_id(id) else {
            return Ok(None);
        };
        Ok(self.store.campaign(&key)?.map(|record| record.spec))
    }

    /// Follow the campaign `id`: a receiver of its state while this coordinator runs it,
    /// else its state from the store.
    pub fn watch(&self, id: &str) -> Result<Option<Watched>> {
        let Some(key) = Self::parse_id(id) else {
            return Ok(None);
        };
        if let Some(live) = self.live.lock().expect("live lock").get(&key) {
            return Ok(Some(Watched::Live(live.state.subscribe())));
        }
        Ok(self
            .store
            .campaign(&key)?
            .map(|record| Watched::Stored(Box::new(self.stored(&key, &record)))))
    }

    /// Every campaign known, in id order.
    pub fn list(&self) -> Result<Vec<Snapshot>> {
        let live = self.live.lock().expect("live lock");
        let mut all: Vec<(CampaignId, Snapshot)> = self
            .store
            .campaigns()?
            .into_iter()
            .map(|(id, record)| match live.get(&id) {
                Some(l) => (id, l.state.borrow().clone()),
                None => (id, self.stored(&id, &record)),
            })
            .collect();
        for (id, l) in live.iter() {
            if !all.iter().any(|(known, _)| known == id) {
                all.push((*id, l.state.borrow().clone()));
            }
        }
        all.sort_by_key(|(id, _)| *id);
        Ok(all.into_iter().map(|(_, s)| s).collect())
    }

    /// Stop dispatching the campaign `id`; its state, if it is known.
    pub fn cancel(&self, id: &str) -> Result<Option<Snapshot>> {
        let Some(key) = Self::parse_id(id) else {
            return Ok(None);
        };
        if let Some(live) = self.live.lock().expect("live lock").get(&key) {
            live.cancel.store(true, Ordering::SeqCst);
            return Ok(Some(live.state.borrow().clone()));
        }
        let Some(record) = self.store.campaign(&key)? else {
            return Ok(None);
        };
        if record.status == CampaignStatus::Running {
            // Left running by an earlier coordinator and not resumed here yet.
            self.mark(&key, CampaignStatus::Cancelled, None)?;
        }
        self.get(id)
    }
}

/// A campaign followed: live, or as the store holds it.
pub enum Watched {
    Live(watch::Receiver<Snapshot>),
    Stored(Box<Snapshot>),
}

/// The folder beside `store` that holds uploaded datasets and results, by default.
pub fn default_folder(store: Option<&Path>) -> PathBuf {
    match store {
        Some(db) => db
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."))
            .join("calib-api"),
        None => std::env::temp_dir().join(format!("calib-api-{}", std::process::id())),
    }
}
