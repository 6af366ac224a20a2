//! Derivative-free optimisers for calibration, written as argmin [`Solver`]s.
//!
//! All solvers search the unit box `[0, 1]^n`: the caller maps every physical
//! parameter from its bounds onto `[0, 1]` before optimising and back afterwards.
//! The solvers never ask the problem to evaluate a point outside the box.
//! Independent evaluations are requested in batches through
//! [`Problem::bulk_cost`], so a problem that overrides
//! [`CostFunction::bulk_cost`] can evaluate them in parallel.
//!
//! * [`Powell`]: Powell's conjugate-direction method, a local method for smooth
//!   objectives ([`powell`]).
//! * [`DifferentialEvolution`]: differential evolution after Storn and Price
//!   (rand/1/bin or best/1/bin), a global population-based method
//!   ([`differential_evolution`]).
//!
//! [`Solver`]: argmin::core::Solver
//! [`Problem::bulk_cost`]: argmin::core::Problem::bulk_cost
//! [`CostFunction::bulk_cost`]: argmin::core::CostFunction::bulk_cost

pub mod differential_evolution;
pub mod powell;

pub use differential_evolution::{DifferentialEvolution, Strategy};
pub use powell::Powell;
