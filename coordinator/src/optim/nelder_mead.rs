//! Nelder–Mead on the unit box, with argmin's solver.
//!
//! J. A. Nelder, R. Mead, "A simplex method for function minimization", The Computer
//! Journal 7 (1965) 308–313. argmin's implementation evaluates the simplex one vertex at a
//! time; the initial simplex is therefore evaluated here first, as one parallel batch, so
//! that argmin's own evaluations of it are answered from the evaluation cache.

use super::problem::RunProblem;
use argmin::core::Error;
use argmin::solver::neldermead::NelderMead;

/// Relative size of the initial simplex: each vertex moves one coordinate by this fraction
/// of its distance from the lower bound (the convention of `scipy.optimize.minimize`, which
/// the seed used, measured in the unit box).
pub const RELATIVE_STEP: f64 = 0.05;

/// Step of a coordinate that sits on its lower bound.
pub const STEP_AT_BOUND: f64 = 0.00025;

/// Convergence: standard deviation of the (scaled) costs over the simplex.
pub const SD_TOLERANCE: f64 = 1e-12;

/// The initial simplex around `start`: one vertex per axis, that coordinate moved by
/// [`RELATIVE_STEP`] of itself (towards the inside of the box when at the upper bound).
pub fn initial_simplex(start: &[f64]) -> Vec<Vec<f64>> {
    let mut vertices = vec![start.to_vec()];
    for i in 0..start.len() {
        let mut v = start.to_vec();
        let step = if start[i] > 0.0 {
            RELATIVE_STEP * start[i]
        } else {
            STEP_AT_BOUND
        };
        v[i] = if start[i] + step <= 1.0 {
            start[i] + step
        } else {
            start[i] - step
        };
        vertices.push(v);
    }
    vertices
}

/// A Nelder–Mead solver starting from `start`, its simplex already evaluated in one batch.
pub fn solver(problem: &RunProblem, start: &[f64]) -> Result<NelderMead<Vec<f64>, f64>, Error> {
    let vertices = initial_simplex(start);
    problem.prefetch(&vertices);
    NelderMead::new(vertices).with_sd_tolerance(SD_TOLERANCE)
}
