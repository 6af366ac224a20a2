//! The in-process cluster of the `calib-sandbox` crate, under the names the tests use.

pub use calib_sandbox::{SandboxCluster as TestCluster, SandboxWorker as TestWorker};
