//! Output sensitivities by finite differences, evaluated as one batch through the
//! [`Simulator`] (so they run wherever evaluations run).
//!
//! Free parameters get central differences with a step relative to their value. Candidate
//! effects are switched on from 0 (one-sided where the effect cannot be negative) with a
//! step chosen so that the change it makes is about the size of the residual: the secant at
//! the scale that matters, which for effects that act non-smoothly (friction that makes a
//! joint stick) describes far better than the tangent what freeing the effect could do.

use calib_engine::campaign::FreeParameter;
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::Simulator;
use calib_engine::objective::Objective;

/// A simulation the sensitivities need failed (a fault of the evaluator passes through).
fn failed(reason: &str) -> Error {
    Error::Optimiser(format!("sensitivities failed: {reason}"))
}

/// A weighted, stacked column: every sample of every output, output `i` scaled by `√k_i`.
pub type Column = Vec<f64>;

/// Stack series (one per output) into one weighted column.
pub fn stack(series: &[Vec<f64>], weights: &[f64]) -> Column {
    series
        .iter()
        .zip(weights)
        .flat_map(|(s, k)| {
            let w = k.sqrt();
            s.iter().map(move |v| w * v)
        })
        .collect()
}

/// The weights of every series an objective compares, experiment after experiment: those
/// [`Objective::simulate`] returns and [`stack`] scales.
pub fn series_weights(objective: &Objective) -> Vec<f64> {
    objective
        .experiments()
        .flat_map(|e| e.weights.iter().copied())
        .collect()
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// Sensitivity of the stacked outputs to each free entry of `objective`, at `point`.
pub struct Sensitivities {
    /// d(outputs)/d(entry), per unit of the entry, weighted and stacked.
    pub columns: Vec<Column>,
    /// The finite-difference step used for each entry.
    pub steps: Vec<f64>,
}

/// Central differences of the outputs (of every experiment) with respect to each free
/// parameter.
pub fn parameter_jacobian(
    simulator: &dyn Simulator,
    objective: &Objective,
    free: &[FreeParameter],
    point: &[f64],
) -> Result<Sensitivities> {
    let mut points = Vec::new();
    let mut steps = Vec::new();
    for (i, p) in free.iter().enumerate() {
        let h = (1e-3 * point[i].abs()).max(1e-6 * (p.max - p.min));
        let up = (point[i] + h).min(p.max);
        let down = (point[i] - h).max(p.min);
        let mut a = point.to_vec();
        a[i] = up;
        let mut b = point.to_vec();
        b[i] = down;
        points.push(a);
        points.push(b);
        steps.push(up - down);
    }
    let results = simulator.simulate(objective, &points)?;
    // Every experiment's series, not the first one's alone.
    let weights = series_weights(objective);
    let mut columns = Vec::new();
    for (i, pair) in results.chunks(2).enumerate() {
        let up = stack(pair[0].as_ref().map_err(|e| failed(e))?, &weights);
        let down = stack(pair[1].as_ref().map_err(|e| failed(e))?, &weights);
        columns.push(
            up.iter()
                .zip(&down)
                .map(|(a, b)| (a - b) / steps[i])
                .collect(),
        );
    }
    Ok(Sensitivities { columns, steps })
}

/// Sensitivities of the outputs to switching each candidate on from 0, by a step about the
/// size that would explain a residual of RMS `residual_rms`, starting from `initial_steps`.
/// `base` is the point without candidates; candidates are the free entries after it.
pub fn candidate_sensitivities(
    simulator: &dyn Simulator,
    objective: &Objective,
    candidates: &[FreeParameter],
    base: &[f64],
    initial_steps: &[f64],
    residual_rms: f64,
) -> Result<Sensitivities> {
    let n = base.len();
    let mut at_base = base.to_vec();
    at_base.extend(std::iter::repeat_n(0.0, candidates.len()));
    let reference = simulator.simulate(objective, std::slice::from_ref(&at_base))?;
    let y0 = stack(
        reference[0].as_ref().map_err(|e| failed(e))?,
        &objective.weights,
    );
    let probe = |steps: &[f64]| -> Result<Vec<Option<Column>>> {
        let points: Vec<Vec<f64>> = steps
            .iter()
            .enumerate()
            .map(|(j, &s)| {
                let mut p = at_base.clone();
                p[n + j] = s;
                p
            })
            .collect();
        Ok(simulator
            .simulate(objective, &points)?
            .into_iter()
            .zip(steps)
            .map(|(r, s)| {
                r.ok().map(|series| {
                    stack(&series, &objective.weights)
                        .iter()
                        .zip(&y0)
                        .map(|(a, b)| (a - b) / s)
                        .collect()
                })
            })
            .collect())
    };
    let clamp = |j: usize, s: f64| {
        let c = &candidates[j];
        if c.min >= 0.0 {
            s.abs().min(c.max)
        } else {
            s.clamp(c.min, c.max)
        }
    };
    let mut steps: Vec<f64> = initial_steps
        .iter()
        .enumerate()
        .map(|(j, s)| clamp(j, *s))
        .collect();
    let mut columns = probe(&steps)?;
    // Rescale the steps whose effect was far from the residual's size, once.
    let mut rescaled = steps.clone();
    let mut again = Vec::new();
    for j in 0..candidates.len() {
        let change = columns[j]
            .as_ref()
            .map(|c| rms(c) * steps[j].abs())
            .unwrap_or(0.0);
        if residual_rms > 0.0 && change > 0.0 {
            let ratio = change / residual_rms;
            if !(0.3..=3.0).contains(&ratio) {
                rescaled[j] = clamp(j, steps[j] / ratio);
                again.push(j);
            }
        }
    }
    if !again.is_empty() {
        let second = probe(&rescaled)?;
        for j in again {
            if second[j].is_some() {
                columns[j] = second[j].clone();
                steps[j] = rescaled[j];
            }
        }
    }
    let len = y0.len();
    Ok(Sensitivities {
        columns: columns
            .into_iter()
            .map(|c| c.unwrap_or_else(|| vec![0.0; len]))
            .collect(),
        steps,
    })
}
