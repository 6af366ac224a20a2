//! calib's worker side: the hosted models, the ODE solver they run on, the scoring of a
//! simulation against measured data, and the gRPC Simulator service that serves them.
//!
//! The worker is stateless: it simulates a model for a parameter vector and returns
//! trajectories, or objective values against a measurement it caches by content hash.

pub mod content_hash;
pub mod effects;
pub mod fmu;
pub mod inputs;
pub mod limits;
pub mod model;
pub mod models;
pub mod ode;
pub mod scoring;
pub mod service;
pub mod testing;
pub mod user_effects;
pub mod validate;

pub use model::{
    EffectSpec, InputSpec, Model, ModelInfo, OutputSpec, ParameterSpec, PlaceKind, PlaceSpec,
    SimulationError, SolverOptions, SolverStats, Trajectory,
};
