//! Scoring a simulation against measured data: the one place where the calibration
//! objective is computed, so that a point scored in the coordinator's process and a point
//! scored by a remote worker give the same bits.
//!
//! `f(p) = Σ_i k_i Σ_t (y_i(p, t) − w_i(t))²`, outputs read at the measurement times. A
//! simulation that fails (diverged, step limit) or yields a non-finite value scores
//! [`FAILURE_PENALTY`]: finite, so optimisers that compare or average costs keep working.
//!
//! A point may also be asked for its weighted residuals `r = sqrt(k_i) (y_i(p, t) − w_i(t))`
//! (per output, then per sample: `f = Σ r²` up to rounding), which least-squares methods
//! read; they are computed only when asked for ([`Target::residuals`]).

use crate::content_hash::ContentHasher;
use crate::inputs::{Inputs, NamedSignal};
use crate::Run;
use crate::{Model, SimulationError, SolverOptions};

/// Objective value given to parameter sets whose simulation failed: far above any real fit.
pub const FAILURE_PENALTY: f64 = 1e30;

/// One point's outcome.
#[derive(Debug, Clone, PartialEq)]
pub struct Evaluation {
    pub objective: f64,
    /// Unweighted sum of squared errors per output, in campaign order.
    pub sse: Vec<f64>,
    /// Why the simulation failed, when it did (then `objective` is the penalty).
    pub failure: Option<String>,
    /// The weighted residuals `sqrt(k_i) (y_i − w_i)`, output after output, when they were
    /// asked for and the simulation succeeded; empty otherwise.
    pub residuals: Vec<f64>,
}

impl Evaluation {
    pub fn failed(outputs: usize, why: String) -> Self {
        Self {
            objective: FAILURE_PENALTY,
            sse: vec![f64::NAN; outputs],
            failure: Some(why),
            residuals: Vec::new(),
        }
    }
}

/// Why a simulated output scored nothing although the solver finished.
pub const NON_FINITE_OUTPUT: &str = "simulated output is not finite";

/// Score simulated series against measured ones (one per output, on the same grid).
pub fn score(simulated: &[Vec<f64>], measured: &[Vec<f64>], weights: &[f64]) -> Evaluation {
    let sse: Vec<f64> = simulated
        .iter()
        .zip(measured)
        .map(|(y, w)| y.iter().zip(w).map(|(a, b)| (a - b) * (a - b)).sum())
        .collect();
    let objective: f64 = sse.iter().zip(weights).map(|(s, k)| s * k).sum();
    if objective.is_finite() {
        Evaluation {
            objective,
            sse,
            failure: None,
            residuals: Vec::new(),
        }
    } else {
        Evaluation::failed(measured.len(), NON_FINITE_OUTPUT.into())
    }
}

/// The weighted residuals `sqrt(k_i) (y_i − w_i)` of simulated series against measured
/// ones, output after output.
pub fn residuals(simulated: &[Vec<f64>], measured: &[Vec<f64>], weights: &[f64]) -> Vec<f64> {
    simulated
        .iter()
        .zip(measured)
        .zip(weights)
        .flat_map(|((y, w), k)| {
            let root = k.sqrt();
            y.iter().zip(w).map(move |(a, b)| root * (a - b))
        })
        .collect()
}

/// [`score`], with the weighted [`residuals`] when `with_residuals` (and the score is not a
/// failure). The objective is the same bits either way.
pub fn score_with(
    simulated: &[Vec<f64>],
    measured: &[Vec<f64>],
    weights: &[f64],
    with_residuals: bool,
) -> Evaluation {
    let mut e = score(simulated, measured, weights);
    if with_residuals && e.failure.is_none() {
        e.residuals = residuals(simulated, measured, weights);
    }
    e
}

/// What a point is scored against: the measured series on their grid, and the weights.
#[derive(Debug, Clone, Copy)]
pub struct Target<'a> {
    pub grid: &'a [f64],
    /// Model output indices, one per measured series.
    pub outputs: &'a [usize],
    pub measured: &'a [Vec<f64>],
    pub weights: &'a [f64],
    pub solver: &'a SolverOptions,
    /// The signals driving the model (none for a free response).
    pub inputs: &'a Inputs,
    /// Whether the weighted residuals are returned beside the objective.
    pub residuals: bool,
}

/// Simulate `model` with the full parameter vector `params` and score it. A failed
/// simulation is returned as the error so that callers can report its kind; see
/// [`evaluate`] for the penalised form.
pub fn simulate_and_score(
    model: &dyn Model,
    params: &[f64],
    target: &Target,
) -> Result<Evaluation, SimulationError> {
    let trajectory = model.simulate(
        &Run::new(params, target.grid, target.outputs, target.solver).driven(target.inputs),
    )?;
    Ok(score_with(
        &trajectory.values,
        target.measured,
        target.weights,
        target.residuals,
    ))
}

/// Simulate and score, a failed simulation scoring [`FAILURE_PENALTY`].
pub fn evaluate(model: &dyn Model, params: &[f64], target: &Target) -> Evaluation {
    simulate_and_score(model, params, target)
        .unwrap_or_else(|e| Evaluation::failed(target.measured.len(), e.to_string()))
}

/// Content hash of a measurement on its grid, as the Simulator protocol defines it: BLAKE3
/// over "calib-measurement-v1", the count and bits of the times, then the count of columns
/// and each column's length and bits, integers as little-endian `u64`. When inputs drive
/// the model, they follow: the text "inputs" (its length, then its bytes), their count, and
/// for each, in the order given, its input's name (length, bytes), its interpolation
/// (0 linear, 1 hold), then its times and its values, each after its count. A measurement
/// without inputs hashes as it always did.
pub fn measurement_hash(times: &[f64], columns: &[Vec<f64>], inputs: &[NamedSignal]) -> [u8; 32] {
    let mut h = ContentHasher::new(b"calib-measurement-v1");
    h.series(times).count(columns.len());
    for column in columns {
        h.series(column);
    }
    crate::inputs::hash_into(&mut h, inputs);
    h.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn score_weights_each_output() {
        let e = score(
            &[vec![1.0, 2.0], vec![0.0, 0.0]],
            &[vec![0.0, 0.0], vec![1.0, 1.0]],
            &[2.0, 0.5],
        );
        assert_eq!(e.sse, vec![5.0, 2.0]);
        assert_eq!(e.objective, 11.0);
        assert!(e.failure.is_none());
    }

    #[test]
    fn residuals_are_weighted_and_square_to_the_objective() {
        let simulated = [vec![1.0, 2.0], vec![0.0, 0.0]];
        let measured = [vec![0.0, 0.0], vec![1.0, 1.0]];
        let plain = score(&simulated, &measured, &[4.0, 0.25]);
        let with = score_with(&simulated, &measured, &[4.0, 0.25], true);
        assert!(plain.residuals.is_empty());
        assert_eq!(with.objective.to_bits(), plain.objective.to_bits());
        assert_eq!(with.residuals, vec![2.0, 4.0, -0.5, -0.5]);
        let squares: f64 = with.residuals.iter().map(|r| r * r).sum();
        assert_eq!(squares, with.objective);
        let failed = score_with(&[vec![f64::NAN]], &[vec![0.0]], &[1.0], true);
        assert!(failed.residuals.is_empty());
    }

    #[test]
    fn non_finite_output_scores_the_penalty() {
        let e = score(&[vec![f64::NAN]], &[vec![0.0]], &[1.0]);
        assert_eq!(e.objective, FAILURE_PENALTY);
        assert_eq!(e.failure.as_deref(), Some(NON_FINITE_OUTPUT));
    }

    #[test]
    fn measurement_hash_sees_every_bit_and_the_layout() {
        let hash = |t: &[f64], c: &[Vec<f64>]| measurement_hash(t, c, &[]);
        let a = hash(&[0.0, 1.0], &[vec![1.0, 2.0]]);
        assert_eq!(a, hash(&[0.0, 1.0], &[vec![1.0, 2.0]]));
        assert_ne!(a, hash(&[0.0, 1.0], &[vec![1.0, 2.0 + 1e-15]]));
        assert_ne!(a, hash(&[0.0, 1.0], &[vec![1.0], vec![2.0]]));
        assert_ne!(a, hash(&[0.0, -0.0], &[vec![1.0, 2.0]]));
    }

    #[test]
    fn measurement_hash_sees_the_inputs_and_how_they_are_read() {
        use crate::inputs::Interpolation;
        let driven = |name: &str, values: Vec<f64>, interpolation| {
            vec![NamedSignal {
                name: name.into(),
                times: vec![0.0, 1.0].into(),
                values: values.into(),
                interpolation,
            }]
        };
        let (t, c) = ([0.0, 1.0], [vec![1.0, 2.0]]);
        let linear = Interpolation::Linear;
        let free = measurement_hash(&t, &c, &[]);
        let a = measurement_hash(&t, &c, &driven("u", vec![0.0, 1.0], linear));
        assert_ne!(free, a);
        for other in [
            driven("u", vec![0.0, 1.5], linear),
            driven("v", vec![0.0, 1.0], linear),
            driven("u", vec![0.0, 1.0], Interpolation::Hold),
        ] {
            assert_ne!(a, measurement_hash(&t, &c, &other));
        }
    }
}
