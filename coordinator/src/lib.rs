//! calib's coordinator: campaigns, their objective, the optimisers that search it, the
//! evaluators that run it, and the reports that show the result.

pub mod calibration;
pub mod campaign;
pub mod diagnosis;
pub mod error;
pub mod evaluator;
pub mod measurement;
pub mod objective;
pub mod optim;
pub mod report;
pub mod store;

pub use error::{Error, Result};
