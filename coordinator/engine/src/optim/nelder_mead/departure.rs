//! Where a Nelder–Mead run starts: an initial simplex with objective spread.
//!
//! **Plateaus.** A simplex whose vertices all score the same (a region where a stuck joint
//! makes the objective flat, or where every simulation fails) would satisfy the spread test
//! at once and report convergence after its first evaluations. Before the solver starts, the
//! initial simplex is therefore checked for spread: a flat one is grown [`GROWTH`]-fold, up to
//! [`GROWTHS`] times (to half the box); still flat, the run restarts from a fresh point drawn
//! by its own seed, up to [`RESTARTS`] times, and a run that never leaves the plateau ends
//! with the termination reason `plateau`, never `converged`.

use crate::evaluator::Fault;
use crate::optim::problem::RunProblem;
use crate::optim::screening;
use crate::optim::space::initial_steps;

/// A simplex is flat when its objectives differ by no more than this, relative to the
/// smallest (or when every vertex failed).
pub const FLAT_SPREAD: f64 = 1e-9;

/// Factor by which a flat initial simplex grows.
pub const GROWTH: f64 = 4.0;

/// Times a flat initial simplex grows before the run restarts elsewhere.
pub const GROWTHS: usize = 3;

/// Restarts of a run whose simplex stays flat before it ends as `plateau`.
pub const RESTARTS: usize = 6;

/// The initial simplex around `start`: one vertex per axis, that coordinate moved by
/// its [`initial_steps`] (towards the inside of the box when at the upper bound).
pub fn initial_simplex(start: &[f64]) -> Vec<Vec<f64>> {
    simplex_with_steps(start, &initial_steps(start))
}

fn simplex_with_steps(start: &[f64], steps: &[f64]) -> Vec<Vec<f64>> {
    let mut vertices = vec![start.to_vec()];
    for (i, &step) in steps.iter().enumerate() {
        let mut v = start.to_vec();
        v[i] = if start[i] + step <= 1.0 {
            start[i] + step
        } else {
            start[i] - step
        };
        vertices.push(v);
    }
    vertices
}

/// Whether scaled objectives show no spread: all failed, or all equal within [`FLAT_SPREAD`].
pub fn is_flat(costs: &[f64]) -> bool {
    let lo = costs.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = costs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    lo >= f64::MAX || hi - lo <= FLAT_SPREAD * lo.abs().max(f64::MIN_POSITIVE)
}

/// Where a run's simplex starts, once it has left any plateau.
pub struct Departure {
    pub simplex: Vec<Vec<f64>>,
    /// Restarts from fresh points (growths of the simplex not counted).
    pub restarts: usize,
    /// Whether the simplex is still flat (the run then ends at once as `plateau`).
    pub flat: bool,
}

/// An initial simplex with spread, found from `start` by growing the simplex and then by
/// restarting from fresh points (screening coordinates mapped by `scales`, drawn by `seed`).
/// Every simplex tried is one batch; those abandoned count as the run's evaluations.
pub fn depart(
    problem: &RunProblem,
    start: &[f64],
    scales: &[Option<f64>],
    seed: u64,
) -> Result<Departure, Fault> {
    let fresh = screening::screening_sample(start.len(), RESTARTS, seed);
    let origins =
        std::iter::once(start.to_vec()).chain(fresh.iter().map(|s| screening::to_unit(s, scales)));
    let mut last = Vec::new();
    for (restarts, origin) in origins.enumerate() {
        let mut steps = initial_steps(&origin);
        for _ in 0..=GROWTHS {
            let simplex = simplex_with_steps(&origin, &steps);
            let costs = problem.peek(&simplex)?;
            if !is_flat(&costs) {
                return Ok(Departure {
                    simplex,
                    restarts,
                    flat: false,
                });
            }
            let abandoned: Vec<&Vec<f64>> = simplex.iter().collect();
            problem.batch(&abandoned)?;
            last = simplex;
            for s in steps.iter_mut() {
                *s = (*s * GROWTH).min(0.5);
            }
        }
    }
    Ok(Departure {
        simplex: last,
        restarts: RESTARTS,
        flat: true,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_simplex_is_flat_when_its_costs_do_not_differ_or_all_failed() {
        assert!(is_flat(&[5288.05, 5288.05, 5288.05]));
        assert!(is_flat(&[f64::MAX, f64::MAX]));
        assert!(!is_flat(&[5288.05, 5288.05, 5288.0]));
        assert!(!is_flat(&[f64::MAX, 1.0]));
        assert!(is_flat(&[0.0, 0.0]));
        assert!(!is_flat(&[0.0, 1e-300]));
    }
}
