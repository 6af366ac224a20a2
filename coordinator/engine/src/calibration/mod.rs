//! A whole calibration: load the data, score the nominal point, run every method from every
//! start, cluster the minima, pick the best.

mod outcome;

use crate::campaign::Campaign;
use crate::error::{Error, Result};
use crate::evaluator::{CacheStats, Evaluator, Fault, FaultKind};
use crate::measurement::Measurement;
use crate::objective::{Evaluation, Objective};
use crate::optim::multistart::{self, Cluster, RunContext, RunOutcome};
use crate::optim::problem::Progress;
use crate::optim::screening;
use crate::optim::space::UnitBox;
use crate::outcome::CalibrationOutcome;
use crate::store::{
    encoding, hex, unhex32, CampaignId, CampaignRecord, CampaignStatus, MemoryStore, RunBest,
    SharedDispatcher, Store, Stored, StoredEvaluator,
};
use std::time::{Duration, Instant};

/// Radius (unit box, max-norm) within which two runs' optima count as one minimum.
pub const CLUSTER_RADIUS: f64 = 1e-3;

/// Everything a calibration found, for reports and plots.
pub struct Calibration {
    pub campaign: Campaign,
    pub measurement: Measurement,
    pub objective: Objective,
    pub nominal: Evaluation,
    /// Points of the screening batch that placed the starts.
    pub screened: usize,
    pub runs: Vec<RunOutcome>,
    pub clusters: Vec<Cluster>,
    /// Index into `runs` of the best run.
    pub best: usize,
    pub best_evaluation: Evaluation,
    pub stats: CacheStats,
    pub elapsed: Duration,
    /// What it found as `result.json` states it, built once from the fields above when the
    /// calibration ends.
    pub outcome: CalibrationOutcome,
}

impl Calibration {
    pub fn best_run(&self) -> &RunOutcome {
        &self.runs[self.best]
    }

    /// Each run's best point as the store keeps it with the campaign.
    pub fn run_bests(&self) -> Vec<RunBest> {
        self.runs
            .iter()
            .map(|r| RunBest {
                method: r.method.name().into(),
                start: r.start,
                point: r.point.clone(),
                objective: r.objective,
                evaluations: r.evaluations,
                rounds: r.rounds,
            })
            .collect()
    }

    /// Evaluations the optimisers asked for (the nominal point and the screening batch
    /// included).
    pub fn evaluations(&self) -> usize {
        1 + self.screened + self.runs.iter().map(|r| r.evaluations).sum::<usize>()
    }

    /// Batches the calibration waited for one after another: the nominal point, the
    /// screening batch (when it screened), then the runs' rounds as they overlap
    /// ([`multistart::plan_rounds`]: the longest run's, per group of concurrent runs).
    pub fn rounds(&self) -> usize {
        let rounds: Vec<usize> = self.runs.iter().map(|r| r.rounds).collect();
        1 + usize::from(self.screened > 0) + multistart::plan_rounds(&rounds)
    }
}

/// Load the measured columns a campaign maps: those compared with outputs, then those
/// driving inputs.
pub fn load_measurement(campaign: &Campaign) -> Result<Measurement> {
    let mut columns: Vec<&str> = campaign
        .outputs
        .iter()
        .map(|o| o.measured.as_str())
        .collect();
    for i in &campaign.inputs {
        if !columns.contains(&i.measured.as_str()) {
            columns.push(&i.measured);
        }
    }
    Ok(Measurement::load(
        &campaign.measurement_file,
        &campaign.time_column,
        &columns,
    )?)
}

/// Calibrate `campaign`, simulating through `evaluator` behind an evaluation cache that
/// lasts as long as the call.
pub fn calibrate<E: Evaluator>(
    campaign: &Campaign,
    evaluator: E,
    progress: &dyn Progress,
) -> Result<Calibration> {
    calibrate_with_store(campaign, evaluator, &MemoryStore::new(), progress)
}

/// Calibrate `campaign`, answering every point the store already holds from it and storing
/// every simulated one durably before the optimiser hears of it. The campaign is recorded
/// as running until it finishes; a re-run of an interrupted campaign replays its
/// deterministic runs from the store, so no stored evaluation is simulated again.
pub fn calibrate_with_store<E: Evaluator>(
    campaign: &Campaign,
    evaluator: E,
    store: &dyn Store,
    progress: &dyn Progress,
) -> Result<Calibration> {
    let measurement = load_measurement(campaign)?;
    calibrate_measured(campaign, measurement, evaluator, store, progress)
}

/// Calibrate `campaign` as [`calibrate_with_store`] does, through `stored`: an evaluator of
/// a dispatcher over `store` that others share (a coordinator's,
/// [`SharedDispatcher`]).
pub fn calibrate_through<S: Stored>(
    campaign: &Campaign,
    stored: &S,
    store: &dyn Store,
    progress: &dyn Progress,
) -> Result<Calibration> {
    let measurement = load_measurement(campaign)?;
    calibrate_stored(campaign, measurement, stored, store, progress)
}

/// Re-run every campaign of `store` marked running (the coordinator calls this when it
/// starts). A campaign that cannot be resumed (its file no longer resolves, its data is
/// gone, the optimiser fails, a worker rejects its requests) is marked failed, logged, and
/// skipped; one stopped by a retryable fault (no worker) stays running for a later call;
/// only a failure of the store itself is returned.
pub fn resume_unfinished<E: Evaluator>(
    store: &dyn Store,
    evaluator: &E,
    progress: &dyn Progress,
) -> Result<Vec<Calibration>> {
    let mut resumed = Vec::new();
    resume_unfinished_each(store, evaluator, progress, |c| resumed.push(c))?;
    Ok(resumed)
}

/// [`resume_unfinished`], handing each campaign to `finished` as soon as it is done (a
/// long-lived coordinator reports one campaign without waiting for the others).
pub fn resume_unfinished_each<E: Evaluator>(
    store: &dyn Store,
    evaluator: &E,
    progress: &dyn Progress,
    finished: impl FnMut(Calibration),
) -> Result<()> {
    resume_unfinished_except(store, evaluator, progress, &|_| false, finished)
}

/// [`resume_unfinished_each`], leaving alone the campaigns `skip` names (those another
/// part of this process is running).
pub fn resume_unfinished_except<E: Evaluator>(
    store: &dyn Store,
    evaluator: &E,
    progress: &dyn Progress,
    skip: &dyn Fn(&CampaignId) -> bool,
    finished: impl FnMut(Calibration),
) -> Result<()> {
    let run = |campaign: &Campaign, measurement: Measurement| {
        calibrate_measured(campaign, measurement, evaluator, store, progress)
    };
    resume_each(store, &run, skip, finished)
}

/// [`resume_unfinished_except`], each campaign through an evaluator of `dispatcher`, one
/// over `store` that others share (a coordinator's).
pub fn resume_unfinished_through<E: Evaluator + ?Sized + 'static>(
    store: &dyn Store,
    dispatcher: &SharedDispatcher<E>,
    progress: &dyn Progress,
    skip: &dyn Fn(&CampaignId) -> bool,
    finished: impl FnMut(Calibration),
) -> Result<()> {
    let run = |campaign: &Campaign, measurement: Measurement| {
        calibrate_stored(
            campaign,
            measurement,
            &dispatcher.evaluator(),
            store,
            progress,
        )
    };
    resume_each(store, &run, skip, finished)
}

/// Calibrates a campaign on its record: how a resume runs each campaign.
type Run<'r> = &'r dyn Fn(&Campaign, Measurement) -> Result<Calibration>;

fn resume_each(
    store: &dyn Store,
    run: Run<'_>,
    skip: &dyn Fn(&CampaignId) -> bool,
    mut finished: impl FnMut(Calibration),
) -> Result<()> {
    for (id, record) in store.campaigns()? {
        if record.status != CampaignStatus::Running || skip(&id) {
            continue;
        }
        tracing::info!(campaign = %record.name, id = %hex(&id), "resuming campaign");
        match resume(store, &id, &record, run) {
            Ok(calibration) => finished(calibration),
            Err(Error::Store(e)) => return Err(Error::Store(e)),
            // No result without workers: it stays marked running for a later resume.
            Err(Error::Fault(fault)) if fault.kind != FaultKind::Rejected => {
                tracing::warn!(campaign = %record.name, error = %fault, "campaign interrupted");
            }
            Err(e) => {
                tracing::warn!(campaign = %record.name, error = %e, "cannot resume campaign");
                mark_failed(store, &id, record, e.to_string())?;
            }
        }
    }
    Ok(())
}

fn resume(
    store: &dyn Store,
    id: &CampaignId,
    record: &CampaignRecord,
    run: Run<'_>,
) -> Result<Calibration> {
    let campaign = Campaign::parse(&record.spec, &record.source)?;
    let hash = unhex32(&record.dataset).ok_or_else(|| {
        Error::InvalidRequest(format!("dataset hash `{}` is malformed", record.dataset))
    })?;
    let measurement = match store.dataset(&hash)? {
        Some(bytes) => encoding::decode_measurement(&bytes, campaign.measurement_file.clone())?,
        None => load_measurement(&campaign)?,
    };
    let now = campaign.identity(&measurement.content_hash());
    if &now != id {
        // The campaign resolves differently today (a model changed version): it runs as a
        // new campaign, and the old record is closed.
        mark_failed(
            store,
            id,
            record.clone(),
            format!("superseded by campaign {}", hex(&now)),
        )?;
    }
    run(&campaign, measurement)
}

fn mark_failed(
    store: &dyn Store,
    id: &CampaignId,
    mut record: CampaignRecord,
    why: String,
) -> Result<()> {
    record.status = CampaignStatus::Failed;
    record.failure = Some(why);
    Ok(store.put_campaign(id, &record)?)
}

fn calibrate_measured<E: Evaluator>(
    campaign: &Campaign,
    measurement: Measurement,
    evaluator: E,
    store: &dyn Store,
    progress: &dyn Progress,
) -> Result<Calibration> {
    StoredEvaluator::with(evaluator, store, |stored| {
        calibrate_stored(campaign, measurement, stored, store, progress)
    })
}

fn calibrate_stored<S: Stored>(
    campaign: &Campaign,
    measurement: Measurement,
    stored: &S,
    store: &dyn Store,
    progress: &dyn Progress,
) -> Result<Calibration> {
    let started = Instant::now();
    let objective = Objective::new(campaign, &measurement)?;
    let dataset = measurement.content_hash();
    if store.dataset(&dataset)?.is_none() {
        store.put_dataset(&dataset, &encoding::encode_measurement(&measurement))?;
    }
    let id = campaign.identity(&dataset);
    let mut record = running_record(campaign, &dataset, store, &id)?;
    store.put_campaign(&id, &record)?;
    tracing::info!(campaign = %campaign.name, id = %hex(&id), "campaign running");
    let outcome = search(campaign, &objective, stored, progress);
    stored.release(&objective);
    let (stats, error) = (stored.stats(), stored.error());
    if let Some(e) = error {
        return Err(e.into());
    }
    let (nominal, screened, runs, clusters, best, best_evaluation) =
        found_or_failed(campaign, outcome, store, &id, &record)?;
    let mut calibration = Calibration {
        campaign: campaign.clone(),
        measurement,
        objective,
        nominal,
        screened,
        runs,
        clusters,
        best,
        best_evaluation,
        stats,
        elapsed: started.elapsed(),
        outcome: CalibrationOutcome::default(),
    };
    calibration.outcome = CalibrationOutcome::of(&calibration);
    record.status = CampaignStatus::Finished;
    record.runs = calibration.run_bests();
    record.result = Some(calibration.outcome.clone());
    store.put_campaign(&id, &record)?;
    Ok(calibration)
}

/// The record of a campaign that starts running: what a client submitted it with stays with
/// it, and its progress until this run's.
fn running_record(
    campaign: &Campaign,
    dataset: &[u8; 32],
    store: &dyn Store,
    id: &CampaignId,
) -> Result<CampaignRecord> {
    let earlier = store.campaign(id)?;
    Ok(CampaignRecord {
        name: campaign.name.clone(),
        spec: campaign.spec.clone(),
        source: campaign.source.clone().unwrap_or_default(),
        dataset: hex(dataset),
        status: CampaignStatus::Running,
        runs: Vec::new(),
        result: None,
        failure: None,
        message: earlier.as_ref().and_then(|r| r.message.clone()),
        free: campaign.free.iter().map(|p| p.name.clone()).collect(),
        history: earlier.map(|r| r.history).unwrap_or_default(),
    })
}

/// What the search found, or the campaign marked failed (every simulation failed, or the
/// search could not run) and the error; a fault (no result for some points) leaves it
/// running, so that a rerun or a coordinator on this store resumes it once workers are back.
fn found_or_failed(
    campaign: &Campaign,
    outcome: Result<Found>,
    store: &dyn Store,
    id: &CampaignId,
    record: &CampaignRecord,
) -> Result<Found> {
    match outcome {
        // The best point failed, so every point did: no fit to report, only why.
        Ok(found) if found.5.failure.is_some() => {
            let e = Error::EverySimulationFailed {
                why: found
                    .0
                    .failure
                    .clone()
                    .or(found.5.failure)
                    .unwrap_or_default(),
            };
            mark_failed(store, id, record.clone(), e.to_string())?;
            Err(e)
        }
        Ok(found) => Ok(found),
        Err(Error::Fault(fault)) => {
            // A cancellation is the user's decision, not the cluster's failure.
            if fault.kind == FaultKind::Cancelled {
                tracing::info!(campaign = %campaign.name, "campaign stopped: {fault}");
            } else {
                tracing::error!(campaign = %campaign.name, error = %fault, "campaign interrupted");
            }
            Err(Error::Fault(fault))
        }
        Err(e) => {
            mark_failed(store, id, record.clone(), e.to_string())?;
            Err(e)
        }
    }
}

type Found = (
    Evaluation,
    usize,
    Vec<RunOutcome>,
    Vec<Cluster>,
    usize,
    Evaluation,
);

/// Score the nominal point, run every method from every start, cluster, score the best.
fn search(
    campaign: &Campaign,
    objective: &Objective,
    evaluator: &dyn Evaluator,
    progress: &dyn Progress,
) -> Result<Found> {
    let (nominal_point, nominal) = score_nominal(campaign, objective, evaluator, progress)?;

    let space = UnitBox::new(&campaign.free);
    let nominal_unit = space.to_unit(&nominal_point);
    let scales = screening::screening_scales(&space, &nominal_unit);
    // The nominal point, then informed starts (from a diagnosis, say), then the rest.
    let mut starts = vec![nominal_unit.clone()];
    starts.extend(
        campaign
            .search
            .extra_starts
            .iter()
            .map(|x| space.to_unit(x)),
    );
    let (further, screened) = further_starts(
        campaign,
        objective,
        evaluator,
        progress,
        (&space, &scales),
        &starts,
    )?;
    starts.extend(further);
    let plan = multistart::plan(&campaign.search.methods, &starts, campaign.search.seed);
    progress.planned(
        &plan
            .iter()
            .map(|r| (r.method.name().to_string(), r.start))
            .collect::<Vec<_>>(),
    );
    let scale = tolerance_scale(&nominal);
    let context = RunContext {
        objective,
        evaluator,
        space: &space,
        scale,
        max_evaluations: campaign.search.max_evaluations,
        progress,
        screening: &scales,
        stall: campaign.search.stall,
        cma_population: campaign.search.cma_population,
    };
    let runs = multistart::run_all(&context, &plan).map_err(optimiser_error)?;
    let clusters = multistart::cluster(&runs, &space, CLUSTER_RADIUS);
    let best = clusters
        .first()
        .map(|c| c.best_run)
        .ok_or_else(|| Error::Optimiser("no run produced a result".into()))?;
    log_runs(campaign, &runs);
    let best_evaluation = evaluator
        .evaluate(objective, std::slice::from_ref(&runs[best].point))?
        .remove(0);
    Ok((nominal, screened, runs, clusters, best, best_evaluation))
}

/// The campaign's nominal point and its evaluation, which every run is compared with.
fn score_nominal(
    campaign: &Campaign,
    objective: &Objective,
    evaluator: &dyn Evaluator,
    progress: &dyn Progress,
) -> Result<(Vec<f64>, Evaluation)> {
    let nominal_point = campaign.nominal();
    let nominal = evaluator
        .evaluate(objective, std::slice::from_ref(&nominal_point))?
        .remove(0);
    progress.evaluated(1, nominal.objective);
    tracing::info!(
        campaign = %campaign.name,
        objective = nominal.objective,
        "nominal point scored"
    );
    Ok((nominal_point, nominal))
}

/// The objective scale the optimisers' tolerances are relative to.
fn tolerance_scale(nominal: &Evaluation) -> f64 {
    // Tolerances are relative to the nominal objective; a perfect nominal fit keeps 1.
    if nominal.objective > 0.0 && nominal.failure.is_none() {
        nominal.objective
    } else {
        1.0
    }
}

/// Logs (at debug level) where each run started and what it reached.
fn log_runs(campaign: &Campaign, runs: &[RunOutcome]) {
    for (i, run) in runs.iter().enumerate() {
        tracing::debug!(
            campaign = %campaign.name,
            run = i,
            method = %run.method,
            start = run.start,
            objective = run.objective,
            evaluations = run.evaluations,
            "run finished"
        );
    }
}

/// The starts after the nominal and informed ones (`taken`, unit box): the best distinct
/// points of a screening batch ([`screening`]), or plain quasi-random points when the
/// campaign asks for no screening; and the number of points screened.
fn further_starts(
    campaign: &Campaign,
    objective: &Objective,
    evaluator: &dyn Evaluator,
    progress: &dyn Progress,
    (space, scales): (&UnitBox, &[Option<f64>]),
    taken: &[Vec<f64>],
) -> Result<(Vec<Vec<f64>>, usize)> {
    let search = &campaign.search;
    let wanted = search.starts.saturating_sub(1);
    let dim = space.dim();
    let count = search
        .screening
        .unwrap_or_else(|| screening::default_count(search.starts, dim));
    if wanted == 0 {
        return Ok((Vec::new(), 0));
    }
    if count == 0 {
        let plain = multistart::start_points(&taken[0], search.starts, search.seed);
        return Ok((plain[1..].to_vec(), 0));
    }
    let sample = screening::screening_sample(dim, count, search.seed);
    let units: Vec<Vec<f64>> = sample
        .iter()
        .map(|s| screening::to_unit(s, scales))
        .collect();
    let points: Vec<Vec<f64>> = units.iter().map(|u| space.to_physical(u)).collect();
    let evaluations = evaluator.evaluate(objective, &points)?;
    let best = evaluations
        .iter()
        .map(|e| e.objective)
        .filter(|f| f.is_finite())
        .fold(f64::INFINITY, f64::min);
    progress.evaluated(count, best);
    let screened: Vec<(Vec<f64>, f64)> = sample
        .into_iter()
        .zip(&evaluations)
        .map(|(s, e)| {
            let failed = e.failure.is_some() || !e.objective.is_finite();
            (s, if failed { f64::INFINITY } else { e.objective })
        })
        .collect();
    let taken: Vec<Vec<f64>> = taken
        .iter()
        .map(|u| screening::to_screening(u, scales))
        .collect();
    let radius = screening::critical_distance(count, dim);
    let chosen = screening::select(&screened, &taken, wanted, radius);
    tracing::info!(
        campaign = %campaign.name,
        screened = count,
        starts = chosen.len(),
        best = best,
        "screening batch scored"
    );
    Ok((
        chosen.into_iter().map(|i| units[i].clone()).collect(),
        count,
    ))
}

/// An optimiser's error: the evaluator's fault when that is what stopped it.
pub fn optimiser_error(e: argmin::core::Error) -> Error {
    match e.downcast::<Fault>() {
        Ok(fault) => Error::Fault(fault),
        Err(e) => Error::Optimiser(e.to_string()),
    }
}
