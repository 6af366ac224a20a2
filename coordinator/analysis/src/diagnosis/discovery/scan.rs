//! The harmonic scan: a periodic torque `a·sin(k·q) + b·cos(k·q)` on a joint, looked for in
//! the outputs rather than in the torque.
//!
//! The regression of [`super::discover`] reads the missing torque off the record by inverse
//! dynamics, which needs the joint to move freely: a joint that sticks for long stretches
//! leaves too few usable samples, and a baseline far from the truth makes the torque residual
//! mostly its own friction error. The scan needs neither. From the diagnosis's final fit it
//! asks, for every multiple `k` in [`MULTIPLES`] of each joint's own angle, how much of the
//! residual a sine and a cosine of `k·q` would remove together with the free parameters, to
//! first order (a score test: one Gauss–Newton step, two finite-difference columns per `k`,
//! C. R. Rao 1948). From a fit far from the truth (a joint held stuck by a friction the
//! harmonic would let go) that first order barely tells one `k` from the next, so every `k`
//! is then refitted from its linear estimate (one local Nelder–Mead run of the free
//! parameters and the harmonic's sine and cosine), and the `k` whose refit fits best (as
//! many parameters each: the information criterion ranks them as the objective does) is
//! proposed, when it also predicts the held-out window better than the fit without it. The
//! proposal is refitted as any other ([`super::refit_discovered`]).

use super::proposal::{DiscoveredEffect, EffectParameter, FoundHarmonic, FoundTerm};
use super::with_discovered;
use crate::diagnosis::refit::local_refit;
use calib_engine::calibration::calibrate;
use calib_engine::campaign::Campaign;
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::Evaluator;
use calib_engine::measurement::Measurement;
use calib_engine::objective::Objective;
use calib_engine::optim::problem::Silent;
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use std::ops::RangeInclusive;

/// The multiples of a joint's angle the scan tries.
pub const MULTIPLES: RangeInclusive<usize> = 2..=40;

/// The torque amplitude of the finite differences [N·m]: well inside the linear range of a
/// pendulum's response, far above the integrator's error.
const STEP: f64 = 1e-4;

/// What the scan found on one joint and multiple.
#[derive(Debug, Clone, Serialize)]
pub struct Scanned {
    pub joint: String,
    pub multiple: usize,
    /// Share of the residual sum of squares (after what the free parameters can remove) that
    /// the harmonic removes to first order.
    pub share: f64,
    /// The objective of its refit, on the fitted and the held-out window.
    pub objective: f64,
    pub held_out_objective: f64,
    /// Where its refit ended: the free parameters, then the sine's and cosine's amplitudes.
    #[serde(skip)]
    pub point: Vec<f64>,
}

/// The scan's outcome: every multiple's refit, the best, and whether it is proposed.
#[derive(Debug, Clone, Serialize)]
pub struct HarmonicScan {
    /// The fit scanned from, on the fitted and the held-out window.
    pub objective: f64,
    pub held_out_objective: f64,
    pub scanned: Vec<Scanned>,
    /// The joint and multiple whose refit fits best.
    pub best: Option<Scanned>,
    /// The proposal, when the best fits the fitted window and predicts the held-out one
    /// better than the fit scanned from (and, once refitted, leaves nothing but noise).
    #[serde(skip)]
    pub proposal: Option<DiscoveredEffect>,
    /// The best's refit over the noise floor, when that refit left more than noise and the
    /// best was therefore not proposed: a search over 78 harmonics finds one that fits a
    /// little better by chance, so only one that explains the record is proposed.
    pub withheld: Option<f64>,
}

/// The formula of a harmonic of `k` times `joint`'s angle with parameters `a1`, `b1`.
fn formula(joint: &str, k: usize) -> (String, String) {
    (
        format!("sin({k} * {joint}.phi)"),
        format!("cos({k} * {joint}.phi)"),
    )
}

fn effect_of(joint: &str, k: usize, a: f64, b: f64, half: f64) -> DiscoveredEffect {
    let (sine, cosine) = formula(joint, k);
    let bound = (a.hypot(b) + half) * 4.0 + STEP;
    let parameter = |name: &str, value: f64| EffectParameter {
        name: name.into(),
        nominal: value,
        min: -bound,
        max: bound,
    };
    let term = |function: &str, parameter: &str, value: f64| FoundTerm {
        function: function.into(),
        parameter: parameter.into(),
        estimate: value,
        ci_low: value - half,
        ci_high: value + half,
    };
    let amplitude = a.hypot(b);
    DiscoveredEffect {
        name: format!("harmonic.{joint}"),
        place: joint.into(),
        formula: format!("a1 * {sine} + b1 * {cosine}"),
        parameters: vec![parameter("a1", a), parameter("b1", b)],
        terms: vec![term(&sine, "a1", a), term(&cosine, "b1", b)],
        harmonics: vec![FoundHarmonic {
            angle: format!("{joint}.phi"),
            multiple: k,
            amplitude,
            ci_low: (amplitude - half).max(0.0),
            ci_high: amplitude + half,
            phase: b.atan2(a),
        }],
    }
}

/// The weighted residuals of `objective` at each of `points`.
fn residuals<E: Evaluator>(
    evaluator: &E,
    objective: &Objective,
    points: &[Vec<f64>],
) -> Result<Vec<DVector<f64>>> {
    let answers = evaluator.evaluate(objective, points)?;
    answers
        .into_iter()
        .map(|e| match e.failure {
            Some(why) => Err(Error::InvalidRequest(format!(
                "the scan's simulation failed: {why}"
            ))),
            None if e.residuals.is_empty() => Err(Error::InvalidRequest(
                "the scan's evaluation returned no residuals".into(),
            )),
            None => Ok(DVector::from_vec(e.residuals)),
        })
        .collect()
}

/// What a scan starts from: the diagnosis's campaign (fitted window) with its final fit's
/// free parameters, where they ended, and the held-out window's campaign.
pub struct ScanStart<'a> {
    pub campaign: &'a Campaign,
    pub holdout: &'a Campaign,
    pub measurement: &'a Measurement,
    pub point: &'a [f64],
    /// Independent samples of the final fit's residual.
    pub effective_samples: f64,
}

/// A harmonic's first-order estimate: its joint, multiple, share of the residual, the sine's
/// and cosine's amplitudes and their 95% half-width.
type Linear = (String, usize, f64, f64, f64, f64);

/// The residual at `from`'s point, and the residual and a projection off what the free
/// parameters can remove (their forward-difference columns).
struct Projected {
    residual: DVector<f64>,
    basis: DMatrix<f64>,
}

impl Projected {
    fn off(&self, v: &DVector<f64>) -> DVector<f64> {
        v - &self.basis * (self.basis.transpose() * v)
    }
}

fn projected<E: Evaluator>(from: &ScanStart, evaluator: &E) -> Result<Projected> {
    let (campaign, point) = (from.campaign, from.point);
    let objective = Objective::new(campaign, from.measurement)?.with_residuals();
    let mut points = vec![point.to_vec()];
    let steps: Vec<f64> = campaign
        .free
        .iter()
        .zip(point)
        .map(|(p, v)| {
            let h = 1e-6 * (p.max - p.min).max(v.abs());
            if v + h > p.max {
                -h
            } else {
                h
            }
        })
        .collect();
    for (i, h) in steps.iter().enumerate() {
        let mut x = point.to_vec();
        x[i] += h;
        points.push(x);
    }
    let answers = residuals(evaluator, &objective, &points)?;
    let r0 = answers[0].clone();
    let jacobian = DMatrix::from_fn(r0.len(), steps.len(), |row, i| {
        (answers[i + 1][row] - r0[row]) / steps[i]
    });
    Ok(Projected {
        residual: r0,
        basis: jacobian.qr().q(),
    })
}

/// Each (joint, multiple)'s columns, concurrently.
fn columns<E: Evaluator>(
    from: &ScanStart,
    tried: &[(String, usize)],
    r0: &DVector<f64>,
    evaluator: &E,
) -> Result<Vec<(DVector<f64>, DVector<f64>)>> {
    let point = from.point;
    std::thread::scope(|scope| {
        let handles: Vec<_> = tried
            .iter()
            .map(|(joint, k)| {
                scope.spawn(move || -> Result<(DVector<f64>, DVector<f64>)> {
                    let zero = effect_of(joint, *k, 0.0, 0.0, 0.0);
                    let trial = with_discovered(from.campaign, point, &zero)?;
                    let objective = Objective::new(&trial, from.measurement)?.with_residuals();
                    let at = |a: f64, b: f64| point.iter().copied().chain([a, b]).collect();
                    let answers =
                        residuals(evaluator, &objective, &[at(STEP, 0.0), at(0.0, STEP)])?;
                    Ok(((&answers[0] - r0) / STEP, (&answers[1] - r0) / STEP))
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    })
}

/// The first-order estimate of every harmonic in `tried` (a score test beside the free
/// parameters).
fn linear<E: Evaluator>(
    from: &ScanStart,
    tried: &[(String, usize)],
    evaluator: &E,
) -> Result<(Vec<Linear>, f64)> {
    let projection = projected(from, evaluator)?;
    let r = projection.off(&projection.residual);
    let rss = r.norm_squared();
    let mut linear = Vec::new();
    let columns = columns(from, tried, &projection.residual, evaluator)?;
    for ((joint, k), (sine, cosine)) in tried.iter().zip(columns) {
        let x = DMatrix::from_columns(&[projection.off(&sine), projection.off(&cosine)]);
        let Some(inverse) = (x.transpose() * &x).try_inverse() else {
            continue;
        };
        let beta = &inverse * (x.transpose() * &r);
        let removed = (x.transpose() * &r).dot(&beta);
        let share = if rss > 0.0 { removed / rss } else { 0.0 };
        // The residual moves by the columns times the amplitudes: the torque that removes
        // `removed` is minus the least-squares coefficients.
        let variance = (rss - removed).max(0.0) / from.effective_samples.max(3.0);
        let half = 1.96 * (variance * inverse[(0, 0)].max(inverse[(1, 1)])).sqrt();
        linear.push((joint.clone(), *k, share, -beta[0], -beta[1], half));
    }
    Ok((linear, projection.residual.norm_squared()))
}

/// Every harmonic refitted from its first-order estimate (one local Nelder–Mead run of the
/// free parameters with it), concurrently.
fn refitted<E: Evaluator>(
    from: &ScanStart,
    linear: &[Linear],
    evaluator: &E,
) -> Result<Vec<Scanned>> {
    let point = from.point;
    std::thread::scope(|scope| {
        let handles: Vec<_> = linear
            .iter()
            .map(|(joint, k, share, a, b, half)| {
                scope.spawn(move || -> Result<Scanned> {
                    let effect = effect_of(joint, *k, *a, *b, half.max(a.hypot(*b)));
                    let mut trial = with_discovered(from.campaign, point, &effect)?;
                    let start: Vec<f64> = point.iter().copied().chain([*a, *b]).collect();
                    for (p, v) in trial.free.iter_mut().zip(&start) {
                        p.nominal = v.clamp(p.min, p.max);
                    }
                    let c = calibrate(&local_refit(&trial), evaluator, &Silent)?;
                    let best = c.best_run();
                    Ok(Scanned {
                        joint: joint.clone(),
                        multiple: *k,
                        share: *share,
                        objective: best.objective,
                        held_out_objective: held_out(from, &[&effect], &best.point, evaluator)?,
                        point: best.point.clone(),
                    })
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    })
}

/// Scan for a harmonic torque on each of `joints`.
pub fn scan<E: Evaluator>(
    from: &ScanStart,
    joints: &[String],
    evaluator: &E,
) -> Result<HarmonicScan> {
    let tried: Vec<(String, usize)> = joints
        .iter()
        .flat_map(|j| MULTIPLES.map(move |k| (j.clone(), k)))
        .collect();
    let (linear, objective_before) = linear(from, &tried, evaluator)?;
    let before = held_out(from, &[], from.point, evaluator)?;
    let scanned = refitted(from, &linear, evaluator)?;
    // As many parameters each: the likelihood alone ranks them (the information criterion's
    // penalty is the same), the held-out window guards against a harmonic that only fits.
    let best = scanned
        .iter()
        .min_by(|a, b| {
            a.objective
                .total_cmp(&b.objective)
                .then_with(|| a.held_out_objective.total_cmp(&b.held_out_objective))
        })
        .cloned();
    let proposal = best
        .as_ref()
        .filter(|b| b.held_out_objective < before && b.objective < objective_before)
        .map(|b| {
            let n = from.point.len();
            let (a, c) = (b.point[n], b.point[n + 1]);
            effect_of(&b.joint, b.multiple, a, c, a.hypot(c))
        });
    Ok(HarmonicScan {
        objective: objective_before,
        held_out_objective: before,
        scanned,
        best,
        proposal,
        withheld: None,
    })
}

/// The held-out objective of `from`'s campaign with `effects` added, at `point`.
fn held_out<E: Evaluator>(
    from: &ScanStart,
    effects: &[&DiscoveredEffect],
    point: &[f64],
    evaluator: &E,
) -> Result<f64> {
    let mut campaign = from.holdout.clone();
    for effect in effects {
        campaign = with_discovered(&campaign, &point[..campaign.free.len()], effect)?;
    }
    let objective = Objective::new(&campaign, from.measurement)?;
    let answer = evaluator.evaluate(&objective, &[point.to_vec()])?;
    Ok(answer.first().map_or(f64::INFINITY, |e| e.objective))
}
