//! calib's coordinator: campaigns, their objective, the optimisers that search it, the
//! evaluators that run it (in this process or on remote workers), the reports that show
//! the result, the coordinator's gRPC server and the web app.

pub mod api;
pub mod calibration;
pub mod campaign;
pub mod campaigns;
pub mod coalesce;
pub mod diagnosis;
pub mod dispatch;
pub mod error;
pub mod evaluator;
pub mod evidence;
pub mod limits;
pub mod measurement;
pub mod objective;
pub mod optim;
pub mod outcome;
pub mod profile;
pub mod report;
pub mod residuals;
pub mod sensitivity;
pub mod server;
pub mod store;
pub mod web;

pub use error::{Error, Result};
