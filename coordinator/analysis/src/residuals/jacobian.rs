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
    let probe = Probe {
        simulator,
        objective,
        candidates,
        n,
        at_base,
        y0,
    };
    let mut steps: Vec<f64> = initial_steps
        .iter()
        .enumerate()
        .map(|(j, s)| probe.clamp(j, *s))
        .collect();
    let mut columns = probe.columns(&steps)?;
    // Rescale the steps whose effect was far from the residual's size, once.
    let (rescaled, again) = probe.rescaled(&columns, &steps, residual_rms);
    if !again.is_empty() {
        let second = probe.columns(&rescaled)?;
        for j in again {
            if second[j].is_some() {
                columns[j] = second[j].clone();
                steps[j] = rescaled[j];
            }
        }
    }
    let len = probe.y0.len();
    Ok(Sensitivities {
        columns: columns
            .into_iter()
            .map(|c| c.unwrap_or_else(|| vec![0.0; len]))
            .collect(),
        steps,
    })
}

/// What probing the candidates needs: the point with every candidate off (`at_base`, the
/// `n` base entries then one 0 per candidate) and the stacked outputs there (`y0`).
struct Probe<'a> {
    simulator: &'a dyn Simulator,
    objective: &'a Objective,
    candidates: &'a [FreeParameter],
    n: usize,
    at_base: Vec<f64>,
    y0: Column,
}

impl Probe<'_> {
    /// The secant columns for switching each candidate `j` on to `steps[j]` alone, one batch;
    /// `None` where that simulation failed.
    fn columns(&self, steps: &[f64]) -> Result<Vec<Option<Column>>> {
        let points: Vec<Vec<f64>> = steps
            .iter()
            .enumerate()
            .map(|(j, &s)| {
                let mut p = self.at_base.clone();
                p[self.n + j] = s;
                p
            })
            .collect();
        Ok(self
            .simulator
            .simulate(self.objective, &points)?
            .into_iter()
            .zip(steps)
            .map(|(r, s)| {
                r.ok().map(|series| {
                    stack(&series, &self.objective.weights)
                        .iter()
                        .zip(&self.y0)
                        .map(|(a, b)| (a - b) / s)
                        .collect()
                })
            })
            .collect())
    }

    /// Step `s` of candidate `j` held below its upper bound and, for an effect that may be
    /// negative, above its lower bound (an effect that cannot be negative is probed with the
    /// step's magnitude).
    fn clamp(&self, j: usize, s: f64) -> f64 {
        let c = &self.candidates[j];
        if c.min >= 0.0 {
            s.abs().min(c.max)
        } else {
            s.clamp(c.min, c.max)
        }
    }

    /// The steps rescaled so that each candidate's change is about the residual's size, and
    /// the candidates whose change was far from it (outside 0.3–3 times), to probe again.
    fn rescaled(
        &self,
        columns: &[Option<Column>],
        steps: &[f64],
        residual_rms: f64,
    ) -> (Vec<f64>, Vec<usize>) {
        let mut rescaled = steps.to_vec();
        let mut again = Vec::new();
        for j in 0..self.candidates.len() {
            let change = columns[j]
                .as_ref()
                .map(|c| rms(c) * steps[j].abs())
                .unwrap_or(0.0);
            if residual_rms > 0.0 && change > 0.0 {
                let ratio = change / residual_rms;
                if !(0.3..=3.0).contains(&ratio) {
                    rescaled[j] = self.clamp(j, steps[j] / ratio);
                    again.push(j);
                }
            }
        }
        (rescaled, again)
    }
}
