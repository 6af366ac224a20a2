//! What a refit leaves, and how well the data pin the discovered effect down: the residual
//! per output (its autocorrelation and Ljung–Box whiteness), and a profile likelihood
//! interval of each of the effect's parameters ([`crate::profile`]: the parameter walked away
//! from the refit's value, the others re-optimised, until the objective rises by the 95%
//! threshold `Δ = χ²₁(0.95)·s²·N/N_eff`).
//!
//! The linearised intervals that warm-start the walk come from central differences of the
//! weighted residuals (which any [`Evaluator`] returns with the objective), a step of
//! [`JACOBIAN_STEP`] of each parameter's search box: the objective of a long record of a
//! lightly damped joint is curved on that scale already.

use crate::profile::walk::{Reoptimisation, DEFAULT_MAX_STEPS};
use crate::profile::{profile_around_with, Around, ParameterProfile, Threshold};
use crate::residuals::uncertainty::intervals;
use crate::residuals::whiteness::{effective_samples, ResidualStats};
use calib_engine::campaign::Campaign;
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::Evaluator;
use calib_engine::objective::Objective;
use calib_engine::optim::space::UnitBox;
use serde::Serialize;

/// Step of the central differences, in each parameter's unit box.
pub const JACOBIAN_STEP: f64 = 1e-5;

/// The residual of one output after the refit.
#[derive(Debug, Clone, Serialize)]
pub struct OutputResidual {
    pub output: String,
    pub rms: f64,
    /// Autocorrelation at lag 1 (one sample).
    pub lag1: f64,
    pub ljung_box: f64,
    pub ljung_box_critical: f64,
    pub white: bool,
}

/// The 95% profile likelihood interval of one parameter, beside the linearised one.
#[derive(Debug, Clone, Serialize)]
pub struct EffectInterval {
    pub name: String,
    pub value: f64,
    /// Ends of the profile interval; `None` on a side that stays under the threshold up to
    /// the parameter's bound (or where the walk stopped).
    pub ci_low: Option<f64>,
    pub ci_high: Option<f64>,
    pub linearised_low: f64,
    pub linearised_high: f64,
    pub evaluations: usize,
}

impl EffectInterval {
    pub fn identifiable(&self) -> bool {
        self.ci_low.is_some() && self.ci_high.is_some()
    }

    /// Whether `value` lies inside the interval (an open side reaches its bound).
    pub fn holds(&self, value: f64) -> bool {
        self.ci_low.is_none_or(|lo| value >= lo) && self.ci_high.is_none_or(|hi| value <= hi)
    }

    fn of(p: &ParameterProfile) -> Self {
        EffectInterval {
            name: p.name.clone(),
            value: p.value,
            ci_low: p.ci_low(),
            ci_high: p.ci_high(),
            linearised_low: p.linearised.ci_low,
            linearised_high: p.linearised.ci_high,
            evaluations: p.low.evaluations + p.high.evaluations,
        }
    }
}

/// The residual, threshold and profile intervals at a refit's point.
#[derive(Debug, Clone)]
pub struct Assessment {
    pub residual: Vec<OutputResidual>,
    pub threshold: Threshold,
    pub intervals: Vec<EffectInterval>,
    /// The lowest objective a profile point reached, and that point (below the refit's
    /// when the refit had stopped short of the minimum).
    pub lowest: (f64, Vec<f64>),
    pub evaluations: usize,
}

/// Assess `campaign` at `point` (objective `best`): residuals, linearised intervals, and the
/// profiles of the free parameters `which`, every evaluation through `evaluator`.
pub fn assess<E: Evaluator>(
    campaign: &Campaign,
    point: &[f64],
    best: f64,
    which: &[usize],
    evaluator: &E,
) -> Result<Assessment> {
    let measurement = calib_engine::calibration::load_measurement(campaign)?;
    let objective = Objective::new(campaign, &measurement)?;
    let local = residuals_and_jacobian(campaign, &objective, point, evaluator)?;
    let samples: usize = local.residual.iter().map(Vec::len).sum();
    let rho1 = local
        .residual
        .iter()
        .map(|r| ResidualStats::of(r).autocorrelation[0])
        .fold(0.0, f64::max);
    let n_eff = effective_samples(samples, rho1);
    let (linearised, correlation) = intervals(
        &campaign.free,
        point,
        &local.columns,
        best.max(f64::MIN_POSITIVE),
        samples,
        n_eff,
    );
    let threshold = Threshold::new(best, samples, campaign.free.len(), n_eff);
    let around = Around {
        objective: &objective,
        free: &campaign.free,
        point,
        best_objective: best,
        threshold: threshold.delta,
        linearised: &linearised,
        correlation: &correlation,
    };
    let profiles = profile_around_with(
        &around,
        which,
        evaluator,
        DEFAULT_MAX_STEPS,
        Reoptimisation::rough(),
    )?;
    let lowest = profiles
        .iter()
        .flat_map(|p| p.low.points.iter().chain(&p.high.points))
        .map(|p| (p.objective, p.point.clone()))
        .fold((best, point.to_vec()), |a, b| if b.0 < a.0 { b } else { a });
    Ok(Assessment {
        residual: named_residuals(campaign, &objective, &local.residual),
        threshold,
        intervals: profiles.iter().map(EffectInterval::of).collect(),
        lowest,
        evaluations: local.evaluations
            + profiles
                .iter()
                .map(|p| p.low.evaluations + p.high.evaluations)
                .sum::<usize>(),
    })
}

/// The weighted residual at a point and its Jacobian.
struct Local {
    /// Per output, every experiment's in turn.
    residual: Vec<Vec<f64>>,
    /// Columns of the stacked residual's Jacobian, per free parameter.
    columns: Vec<Vec<f64>>,
    evaluations: usize,
}

/// The weighted residual at `point` and its Jacobian by central differences.
fn residuals_and_jacobian<E: Evaluator>(
    campaign: &Campaign,
    objective: &Objective,
    point: &[f64],
    evaluator: &E,
) -> Result<Local> {
    let space = UnitBox::new(&campaign.free);
    let unit = space.to_unit(point);
    let mut points = vec![point.to_vec()];
    for i in 0..point.len() {
        for direction in [1.0, -1.0] {
            let mut u = unit.clone();
            u[i] = (u[i] + direction * JACOBIAN_STEP).clamp(0.0, 1.0);
            points.push(space.to_physical(&u));
        }
    }
    let with = objective.with_residuals();
    let evaluated = evaluator.evaluate(&with, &points)?;
    let failed = |k: usize| {
        Error::Optimiser(format!(
            "the refit's point or a neighbour could not be simulated: {}",
            evaluated[k].failure.clone().unwrap_or_default()
        ))
    };
    let residual_at = |k: usize| -> Result<&Vec<f64>> {
        let e = &evaluated[k];
        if e.failure.is_some() || e.residuals.is_empty() {
            return Err(failed(k));
        }
        Ok(&e.residuals)
    };
    let stacked = residual_at(0)?;
    let mut columns = Vec::with_capacity(point.len());
    for i in 0..point.len() {
        let (up, down) = (residual_at(1 + 2 * i)?, residual_at(2 + 2 * i)?);
        let step = points[1 + 2 * i][i] - points[2 + 2 * i][i];
        // The residual is `sqrt(k)·(y − w)`: its derivative is the weighted model's.
        columns.push(
            up.iter()
                .zip(down)
                .map(|(a, b)| if step != 0.0 { (a - b) / step } else { 0.0 })
                .collect(),
        );
    }
    let mut per_output = Vec::new();
    let mut at = 0;
    for part in objective.experiments() {
        for series in &part.measured {
            per_output.push(stacked[at..at + series.len()].to_vec());
            at += series.len();
        }
    }
    Ok(Local {
        residual: per_output,
        columns,
        evaluations: points.len(),
    })
}

/// Each output's residual statistics, named by its model output (and its experiment's name
/// where the campaign has several).
fn named_residuals(
    campaign: &Campaign,
    objective: &Objective,
    residual: &[Vec<f64>],
) -> Vec<OutputResidual> {
    let names: Vec<String> = campaign
        .experiments()
        .iter()
        .zip(objective.experiments())
        .flat_map(|(e, _)| {
            e.outputs.iter().map(move |o| {
                if e.name.is_empty() {
                    o.model.clone()
                } else {
                    format!("{}@{}", o.model, e.name)
                }
            })
        })
        .collect();
    names
        .into_iter()
        .zip(residual)
        .map(|(output, r)| {
            let s = ResidualStats::of(r);
            OutputResidual {
                output,
                rms: s.rms,
                lag1: s.autocorrelation[0],
                ljung_box: s.ljung_box,
                ljung_box_critical: s.ljung_box_critical,
                white: s.white,
            }
        })
        .collect()
}
