//! The optimisers and the multistart that drives them.
//!
//! Every solver searches the unit box (see [`space`]): each free parameter mapped from its
//! bounds to [0, 1]. Nelder–Mead is argmin's; Powell and differential evolution are argmin
//! `Solver`s of ours, so one executor and one termination story serve all three.

pub mod budget;
pub mod differential_evolution;
pub mod multistart;
pub mod nelder_mead;
pub mod powell;
pub mod problem;
pub mod space;
