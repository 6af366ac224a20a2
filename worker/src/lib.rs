//! calib's worker side: the hosted models and the ODE solver they run on.
//!
//! The worker is stateless: it simulates a model for a parameter vector and returns
//! trajectories (or, later, objective values against a cached measurement).

pub mod model;
pub mod models;
pub mod ode;

pub use model::{
    EffectSpec, Model, ModelInfo, OutputSpec, ParameterSpec, SimulationError, SolverOptions,
    SolverStats, Trajectory,
};
