//! calib's models: the hosted models, the ODE solvers they run on, their effects and inputs,
//! user-defined effects, FMUs, and the scoring of a simulation against measured data.
//!
//! No network and no async runtime: the engine and the analyses run these models in
//! process, and `calib-worker` serves them over gRPC.

pub mod command;
pub mod content_hash;
pub mod effects;
pub mod fmu;
pub mod inputs;
pub mod limits;
pub mod model;
pub mod models;
pub mod ode;
pub mod scoring;
pub mod testing;
pub mod user_effects;
pub mod validate;

pub use model::{
    EffectSpec, InputSpec, Model, ModelInfo, OutputSpec, ParameterSpec, PlaceKind, PlaceSpec, Run,
    SimulationError, SolverOptions, SolverStats, Trajectory,
};
