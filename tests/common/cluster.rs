//! The in-process cluster of the `calib-sandbox` crate, under the names the tests use.

#![allow(unused_imports)] // each test binary uses its own part

pub use calib_sandbox::{SandboxCluster as TestCluster, SandboxWorker as TestWorker};
