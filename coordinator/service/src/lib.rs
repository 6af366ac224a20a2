//! calib's coordinator as a service, over the engine and the analyses: dispatch of points to
//! remote workers, the campaigns a coordinator hosts (their data, FMUs and resume), the
//! Calibration gRPC API, the web app, and the server that serves them together.

pub mod api;
pub mod dispatch;
pub mod hosting;
pub mod memory;
pub mod server;
pub mod web;
