//! Derivative-free optimisers for calibration, and the multistart that drives them.
//!
//! All solvers search the unit box `[0, 1]^n` ([`space`]): every physical parameter is
//! mapped from its bounds onto `[0, 1]` before optimising and back afterwards, so one step
//! size and one tolerance fit parameters of any scale, and bounds always hold.
//! Independent evaluations are requested in batches through [`Problem::bulk_cost`], which
//! [`problem::RunProblem`] overrides to evaluate them in parallel.
//!
//! * [`nelder_mead`]: the Nelder–Mead simplex; its initial simplex and its shrinks are batches.
//! * [`Powell`]: Powell's conjugate-direction method, a local method for smooth
//!   objectives ([`powell`]).
//! * [`DifferentialEvolution`]: differential evolution after Storn and Price
//!   (rand/1/bin or best/1/bin), a global population-based method
//!   ([`differential_evolution`]).
//! * [`levenberg_marquardt`]: Levenberg–Marquardt on the weighted residuals, bounded to the
//!   box, for the least-squares objective; its Jacobian and trial steps are one batch per
//!   iteration.
//! * [`cma_es`]: CMA-ES (Hansen's (μ/μ_w, λ)-CMA-ES with IPOP restarts), a
//!   population-based method whose generation is one batch.
//! * [`multistart`]: every method from every start point, concurrently; minima clustered.
//!
//! [`Problem::bulk_cost`]: argmin::core::Problem::bulk_cost

pub mod budget;
pub mod cma_es;
pub mod differential_evolution;
pub mod levenberg_marquardt;
pub mod multistart;
pub mod nelder_mead;
pub mod powell;
pub mod problem;
pub mod screening;
pub mod space;
#[cfg(test)]
mod test_problems;

pub use differential_evolution::{DifferentialEvolution, Strategy};

/// An invalid setting or start of a solver, as argmin reports it.
pub(crate) fn invalid(text: &str) -> argmin::core::Error {
    argmin::core::ArgminError::InvalidParameter { text: text.into() }.into()
}

/// The start point of `solver` must be non-empty and lie in the unit box.
pub(crate) fn check_start(solver: &str, start: &[f64]) -> Result<(), argmin::core::Error> {
    if start.is_empty() {
        return Err(invalid(&format!("`{solver}`: the start point is empty.")));
    }
    if !start.iter().all(|v| (0.0..=1.0).contains(v)) {
        return Err(invalid(&format!(
            "`{solver}`: the start point must lie in [0, 1]^n."
        )));
    }
    Ok(())
}

/// A cost the solvers can order: NaN and +∞ become the largest finite value, so a failed
/// evaluation ranks last without poisoning comparisons or averages.
pub(crate) fn sanitize(cost: f64) -> f64 {
    if cost.is_nan() || cost == f64::INFINITY {
        f64::MAX
    } else {
        cost
    }
}
pub use powell::Powell;
