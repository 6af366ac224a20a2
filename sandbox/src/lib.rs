//! Workers serving in this process on `127.0.0.1` port-0 listeners, for the integration
//! tests and `calib bench --cluster`: real workers that can be killed abruptly and brought
//! back at their address ([`worker`]), workers that only nap ([`napping`]), and clusters of
//! either with a coordinator-side pool over them ([`cluster`]).
//!
//! A crate of its own so that the production crates carry no test double, while the tests
//! and the bench share one sandbox instead of building two.

pub mod cluster;
pub mod napping;
pub mod worker;

pub use cluster::{connect, NappingCluster, SandboxCluster};
pub use napping::{serve_napping, NappingSimulator};
pub use worker::{hold_port, SandboxWorker};
