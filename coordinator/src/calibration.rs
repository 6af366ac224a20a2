//! A whole calibration: load the data, score the nominal point, run every method from every
//! start, cluster the minima, pick the best.

use crate::campaign::Campaign;
use crate::error::{Error, Result};
use crate::evaluator::{CacheStats, CachedEvaluator, Evaluator};
use crate::measurement::Measurement;
use crate::objective::{Evaluation, Objective};
use crate::optim::multistart::{self, Cluster, RunContext, RunOutcome};
use crate::optim::problem::Progress;
use crate::optim::space::UnitBox;
use std::time::{Duration, Instant};

/// Radius (unit box, max-norm) within which two runs' optima count as one minimum.
pub const CLUSTER_RADIUS: f64 = 1e-3;

/// Everything a calibration found, for reports and plots.
pub struct Calibration {
    pub campaign: Campaign,
    pub measurement: Measurement,
    pub objective: Objective,
    pub nominal: Evaluation,
    pub runs: Vec<RunOutcome>,
    pub clusters: Vec<Cluster>,
    /// Index into `runs` of the best run.
    pub best: usize,
    pub best_evaluation: Evaluation,
    pub stats: CacheStats,
    pub elapsed: Duration,
}

impl Calibration {
    pub fn best_run(&self) -> &RunOutcome {
        &self.runs[self.best]
    }

    /// Evaluations the optimisers asked for (the nominal point included).
    pub fn evaluations(&self) -> usize {
        1 + self.runs.iter().map(|r| r.evaluations).sum::<usize>()
    }
}

/// Load the measured columns a campaign maps.
pub fn load_measurement(campaign: &Campaign) -> Result<Measurement> {
    let columns: Vec<&str> = campaign
        .outputs
        .iter()
        .map(|o| o.measured.as_str())
        .collect();
    Ok(Measurement::load(
        &campaign.measurement_file,
        &campaign.time_column,
        &columns,
    )?)
}

/// Calibrate `campaign`, simulating through `evaluator` (behind an evaluation cache).
pub fn calibrate<E: Evaluator>(
    campaign: &Campaign,
    evaluator: E,
    progress: &dyn Progress,
) -> Result<Calibration> {
    let started = Instant::now();
    let measurement = load_measurement(campaign)?;
    let objective = Objective::new(campaign, &measurement)?;
    let evaluator = CachedEvaluator::new(evaluator);
    let nominal_point = campaign.nominal();
    let nominal = evaluator
        .evaluate(&objective, std::slice::from_ref(&nominal_point))
        .remove(0);
    progress.evaluated(1, nominal.objective);
    tracing::info!(
        campaign = %campaign.name,
        objective = nominal.objective,
        "nominal point scored"
    );

    let space = UnitBox::new(&campaign.free);
    let mut starts = multistart::start_points(
        &space.to_unit(&nominal_point),
        campaign.search.starts,
        campaign.search.seed,
    );
    // Informed starts (from a diagnosis, say) go right after the nominal point.
    for (i, extra) in campaign.search.extra_starts.iter().enumerate() {
        starts.insert(1 + i, space.to_unit(extra));
    }
    let plan = multistart::plan(&campaign.search.methods, &starts, campaign.search.seed);
    // Tolerances are relative to the nominal objective; a perfect nominal fit keeps 1.
    let scale = if nominal.objective > 0.0 && nominal.failure.is_none() {
        nominal.objective
    } else {
        1.0
    };
    let context = RunContext {
        objective: &objective,
        evaluator: &evaluator,
        space: &space,
        scale,
        max_evaluations: campaign.search.max_evaluations,
        progress,
    };
    let runs = multistart::run_all(&context, &plan).map_err(|e| Error::Optimiser(e.to_string()))?;
    let clusters = multistart::cluster(&runs, &space, CLUSTER_RADIUS);
    let best = clusters
        .first()
        .map(|c| c.best_run)
        .ok_or_else(|| Error::Optimiser("no run produced a result".into()))?;
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
    let best_evaluation = evaluator
        .evaluate(&objective, std::slice::from_ref(&runs[best].point))
        .remove(0);
    Ok(Calibration {
        campaign: campaign.clone(),
        measurement,
        objective,
        nominal,
        runs,
        clusters,
        best,
        best_evaluation,
        stats: evaluator.stats(),
        elapsed: started.elapsed(),
    })
}
