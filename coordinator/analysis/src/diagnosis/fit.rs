//! What a diagnosis keeps of one calibration: the residual, its statistics, the held-out
//! error, the information criteria and the parameters' confidence intervals.

use super::Fit;
use crate::residuals::whiteness::{self, effective_samples, ResidualStats};
use crate::residuals::{jacobian, uncertainty};
use calib_engine::calibration::Calibration;
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::Simulator;
use calib_engine::evidence::runs_at_best;
use calib_engine::objective::Objective;

/// Everything the report needs about one calibration.
pub(super) fn fit_of<E: Simulator>(
    calibration: &Calibration,
    effects: &[String],
    engine: &E,
    holdout: &Objective,
) -> Result<Fit> {
    let campaign = &calibration.campaign;
    let objective = &calibration.objective;
    let best = calibration.best_run();
    let point = best.point.clone();
    let residual_series = residual_at(engine, objective, std::slice::from_ref(&point))?;
    let residual: Vec<ResidualStats> = residual_series
        .iter()
        .map(|r| ResidualStats::of(r))
        .collect();

    // The held-out window, with the same free parameters.
    let (held_out_objective, held_out_rms) = held_out_error(engine, objective, holdout, &point)?;

    let samples = objective.grid.len();
    let pooled: Vec<f64> = residual_series.iter().flatten().copied().collect();
    let rho1 = residual_series
        .iter()
        .map(|r| whiteness::autocorrelation(r, 1)[0])
        .fold(0.0, f64::max);
    let total_samples = pooled.len();
    let n_eff = effective_samples(total_samples, rho1);
    let k = point.len() as f64;
    let sse = best.objective.max(f64::MIN_POSITIVE);
    let log_likelihood_term = n_eff * (sse / total_samples as f64).ln();
    let jacobian = jacobian::parameter_jacobian(engine, objective, &campaign.free, &point)?;
    let (parameters, correlation) = uncertainty::intervals(
        &campaign.free,
        &point,
        &jacobian.columns,
        sse,
        total_samples,
        n_eff,
    );
    Ok(Fit {
        effects: effects.to_vec(),
        parameters,
        correlation,
        objective: best.objective,
        held_out_objective,
        rms: calibration
            .best_evaluation
            .sse
            .iter()
            .map(|s| (s / samples as f64).sqrt())
            .collect(),
        held_out_rms,
        residual,
        effective_samples: n_eff,
        aic: log_likelihood_term + 2.0 * k,
        bic: log_likelihood_term + k * n_eff.ln(),
        evaluations: calibration.evaluations(),
        runs_at_best: runs_at_best(
            &calibration
                .runs
                .iter()
                .map(|r| r.objective)
                .collect::<Vec<_>>(),
        ),
        point,
        free: campaign.free.clone(),
        residual_series,
    })
}

/// The residual series (measured − model) per output at the optimum (`at`, one point),
/// simulated once: what the statistics, the information criteria and the report use.
fn residual_at<E: Simulator>(
    engine: &E,
    objective: &Objective,
    at: &[Vec<f64>],
) -> Result<Vec<Vec<f64>>> {
    let simulated = engine
        .simulate(objective, at)?
        .remove(0)
        .map_err(|e| Error::Optimiser(format!("simulation at the optimum failed: {e}")))?;
    Ok(objective
        .measured
        .iter()
        .zip(&simulated)
        .map(|(w, y)| w.iter().zip(y).map(|(a, b)| a - b).collect())
        .collect())
}

/// The objective and per-output RMS on the held-out window at `point` (the failure penalty
/// and NaN where that simulation fails), which guards the selection against over-fitting.
fn held_out_error<E: Simulator>(
    engine: &E,
    objective: &Objective,
    holdout: &Objective,
    point: &[f64],
) -> Result<(f64, Vec<f64>)> {
    let held = holdout.fixed_at(objective.full_parameters(point));
    let held_out = engine.simulate(&held, &[Vec::new()])?.remove(0);
    Ok(match held_out {
        Ok(values) => {
            let e = held.score(&values);
            let n = held.grid.len() as f64;
            (e.objective, e.sse.iter().map(|s| (s / n).sqrt()).collect())
        }
        Err(_) => (
            calib_engine::objective::FAILURE_PENALTY,
            vec![f64::NAN; objective.outputs.len()],
        ),
    })
}
