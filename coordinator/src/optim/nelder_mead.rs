//! Nelder–Mead on the unit box, with argmin's solver.
//!
//! J. A. Nelder, R. Mead, "A simplex method for function minimization", The Computer
//! Journal 7 (1965) 308–313. argmin's implementation evaluates the simplex one vertex at a
//! time; the initial simplex is therefore evaluated here first, as one parallel batch, so
//! that argmin's own evaluations of it are answered from the evaluation cache.

use super::problem::RunProblem;
use super::space::initial_steps;
use argmin::core::Error;
use argmin::solver::neldermead::NelderMead;

/// Convergence: standard deviation of the (scaled) costs over the simplex.
pub const SD_TOLERANCE: f64 = 1e-12;

/// The initial simplex around `start`: one vertex per axis, that coordinate moved by
/// its [`initial_steps`] (towards the inside of the box when at the upper bound).
pub fn initial_simplex(start: &[f64]) -> Vec<Vec<f64>> {
    let mut vertices = vec![start.to_vec()];
    for (i, step) in initial_steps(start).into_iter().enumerate() {
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

/// A Nelder–Mead solver starting from `start`, its simplex already evaluated in one batch.
pub fn solver(problem: &RunProblem, start: &[f64]) -> Result<NelderMead<Vec<f64>, f64>, Error> {
    let vertices = initial_simplex(start);
    problem.prefetch(&vertices)?;
    NelderMead::new(vertices).with_sd_tolerance(SD_TOLERANCE)
}
