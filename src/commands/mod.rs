//! One module per subcommand: parse nothing, call the library, print.

pub mod bench;
pub mod bench_cluster;
pub mod bench_diagnose;
pub mod bench_store;
pub mod calibrate;
pub mod coordinator;
pub mod diagnose;
pub mod models;
pub mod simulate;
pub mod store;
pub mod worker;

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

impl From<calib_coordinator::Error> for Failure {
    fn from(e: calib_coordinator::Error) -> Self {
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

/// Where evaluations run, for the commands that dispatch them.
#[derive(clap::Args, Debug, Clone)]
pub struct WorkersArgs {
    /// Workers to spread evaluations over, comma separated: http://HOST:PORT (one worker)
    /// or dns:///NAME:PORT (every address NAME resolves to, re-resolved periodically).
    #[arg(long, value_name = "LIST")]
    pub workers: Option<String>,
    /// Deadline of one request to a worker [s].
    #[arg(long, default_value_t = 120.0, value_name = "SECONDS")]
    pub deadline: f64,
    /// How long to wait for a worker to be up before evaluations fail [s].
    #[arg(long, default_value_t = 300.0, value_name = "SECONDS")]
    pub wait_for_workers: f64,
}

impl WorkersArgs {
    /// Connect to the workers of `list` and wait for one to be up (`--wait-for-workers`).
    pub fn connect(
        &self,
        list: &str,
    ) -> Result<calib_coordinator::dispatch::RemoteWorkers, Failure> {
        use calib_coordinator::dispatch::{self, DispatchConfig, RemoteWorkers};
        let addresses =
            dispatch::parse_list(list).map_err(|e| Failure::input(format!("--workers {e}")))?;
        let config = self.apply(DispatchConfig::new(addresses));
        let wait = config.wait_for_workers;
        let workers = RemoteWorkers::connect(config)?;
        if !workers.wait_until_up(1, wait) {
            let states: Vec<String> = workers
                .pool()
                .workers()
                .iter()
                .map(|w| format!("{} ({:?})", w.url, w.health))
                .collect();
            return Err(Failure::internal(format!(
                "no worker up after {:.0} s: {}",
                wait.as_secs_f64(),
                states.join(", ")
            )));
        }
        Ok(workers)
    }

    pub fn apply(
        &self,
        mut config: calib_coordinator::dispatch::DispatchConfig,
    ) -> calib_coordinator::dispatch::DispatchConfig {
        use std::time::Duration;
        config.deadline = Duration::from_secs_f64(self.deadline.max(0.001));
        config.wait_for_workers = Duration::from_secs_f64(self.wait_for_workers.max(0.0));
        config
    }
}
