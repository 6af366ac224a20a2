//! calib's worker: the gRPC Simulator service that serves calib-model's hosted models and
//! FMUs.
//!
//! The worker is stateless: it simulates a model for a parameter vector and returns
//! trajectories, or objective values against a measurement it caches by content hash.

pub mod service;
pub mod wire;
