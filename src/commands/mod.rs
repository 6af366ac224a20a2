//! One module per subcommand: parse nothing, call the library, print.

pub mod bench;
pub mod bench_cluster;
pub mod bench_command;
pub mod bench_diagnose;
pub mod bench_fmu;
pub mod bench_matrix;
pub mod bench_random;
pub mod bench_search;
pub mod bench_store;
pub mod calibrate;
pub mod coordinator;
pub mod cpu;
pub mod diagnose;
pub mod fmu;
pub mod health;
pub mod models;
pub mod profile;
pub mod security;
pub mod sensitivity;
pub mod simulate;
pub mod store;
pub mod submit;
pub mod ui;
pub mod worker;
pub mod workers;

pub use workers::WorkersArgs;

/// A command's failure: the message for the user and the process exit code.
#[derive(Debug)]
pub struct Failure {
    pub message: String,
    pub code: u8,
}

impl Failure {
    /// Bad input: a campaign, data file or argument the user must fix (exit code 2).
    pub fn input(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
            code: 2,
        }
    }

    /// Anything else (exit code 1).
    pub fn internal(message: impl Into<String>) -> Self {
        Self {
            message: message.into(),
            code: 1,
        }
    }
}

impl From<calib_engine::Error> for Failure {
    fn from(e: calib_engine::Error) -> Self {
        if e.is_bad_input() {
            Failure::input(e.to_string())
        } else {
            Failure::internal(e.to_string())
        }
    }
}

pub type Outcome = Result<(), Failure>;

/// A multi-threaded tokio runtime for the serving commands.
pub fn runtime() -> Result<tokio::runtime::Runtime, Failure> {
    tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| Failure::internal(format!("cannot start the async runtime: {e}")))
}

/// Completes on SIGTERM (a container stopped, a pod evicted) or SIGINT (Ctrl-C), after
/// logging it. A server in a container runs as PID 1, which the kernel never terminates on
/// a signal it does not handle.
pub async fn terminated() {
    use tokio::signal::unix::{signal, SignalKind};
    let (Ok(mut term), Ok(mut int)) = (
        signal(SignalKind::terminate()),
        signal(SignalKind::interrupt()),
    ) else {
        return std::future::pending().await;
    };
    let name = tokio::select! {
        _ = term.recv() => "SIGTERM",
        _ = int.recv() => "SIGINT",
    };
    tracing::info!(signal = name, "shutting down");
    eprintln!("{name}: shutting down");
}
