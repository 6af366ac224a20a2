//! Evaluations on remote workers: the pool of workers ([`pool`]), how they are found
//! ([`discovery`], [`registry`]), one worker's client ([`client`]) and the [`Evaluator`]
//! that spreads batches over them ([`grpc`]).
//!
//! [`Evaluator`]: calib_engine::evaluator::Evaluator

pub mod client;
pub mod discovery;
pub mod error;
pub mod grpc;
pub mod pool;
pub mod registry;

pub use discovery::{parse_list, Resolve, Resolver, WorkerAddress};
pub use error::WorkerError;
pub use grpc::{GrpcEvaluator, Work};
pub use pool::{Health, WorkerPool, WorkerView};

use calib_engine::error::{Error, Result};
use calib_security::ClientSecurity;
use std::sync::Arc;
use std::time::{Duration, Instant};

/// How the coordinator finds and uses workers.
#[derive(Debug, Clone)]
pub struct DispatchConfig {
    pub workers: Vec<WorkerAddress>,
    /// Deadline of one request to a worker (one chunk of a batch).
    pub deadline: Duration,
    /// Chunks in flight per worker (the second queued behind the first): 2 keeps a worker
    /// busy while an answer travels back.
    pub depth: usize,
    /// How often workers that are down or joining are probed.
    pub probe_interval: Duration,
    /// Deadline of one probe.
    pub probe_timeout: Duration,
    /// How often DNS names are resolved again.
    pub resolve_interval: Duration,
    /// What resolves DNS names (the system's resolver unless a test brings its own).
    pub resolver: Resolver,
    /// Attempts at one point (on different workers, as they fail) before it is given up.
    pub max_attempts: u32,
    /// How long a batch waits for any worker to be up before its points fail.
    pub wait_for_workers: Duration,
    /// Heartbeat interval asked of registering workers.
    pub heartbeat: Duration,
    /// The CA trusted for `https://` workers and the token presented to every worker.
    pub security: ClientSecurity,
}

impl DispatchConfig {
    pub fn new(workers: Vec<WorkerAddress>) -> Self {
        Self {
            workers,
            deadline: Duration::from_secs(120),
            depth: 2,
            probe_interval: Duration::from_secs(1),
            probe_timeout: Duration::from_secs(3),
            resolve_interval: Duration::from_secs(10),
            resolver: Resolver::default(),
            max_attempts: 5,
            wait_for_workers: Duration::from_secs(300),
            heartbeat: Duration::from_secs(5),
            security: ClientSecurity::default(),
        }
    }
}

/// Start a pool on the current runtime and put the configured workers in it.
pub fn start_pool(config: DispatchConfig) -> Result<Arc<WorkerPool>> {
    let addresses = config.workers.clone();
    let pool = WorkerPool::start(config);
    discovery::discover(&pool, &addresses).map_err(Error::InvalidRequest)?;
    Ok(pool)
}

/// Remote workers for synchronous callers (`calib calibrate --workers`): a pool on a
/// runtime of its own.
pub struct RemoteWorkers {
    runtime: tokio::runtime::Runtime,
    pool: Arc<WorkerPool>,
    /// Every worker is a fixed URL (no DNS name that may resolve to more later).
    fixed: bool,
}

impl RemoteWorkers {
    pub fn connect(config: DispatchConfig) -> Result<Self> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("calib-dispatch")
            .enable_all()
            .build()
            .map_err(|e| Error::Dispatch(format!("cannot start the dispatch runtime: {e}")))?;
        let fixed = config
            .workers
            .iter()
            .all(|w| matches!(w, WorkerAddress::Url(_)));
        let pool = runtime.block_on(async { start_pool(config) })?;
        Ok(Self {
            runtime,
            pool,
            fixed,
        })
    }

    pub fn pool(&self) -> &Arc<WorkerPool> {
        &self.pool
    }

    /// An evaluator over these workers.
    pub fn evaluator(&self) -> GrpcEvaluator {
        GrpcEvaluator::new(self.pool.clone(), self.runtime.handle().clone())
    }

    /// Wait until a worker is up, telling `changed` what is awaited whenever that changes.
    /// Fails at once when every worker is a fixed URL where nothing listens and none was ever
    /// up (workers not started, or a wrong port), when every worker is set aside (another
    /// protocol, a refused token or certificate), and once `timeout` has passed otherwise.
    pub fn wait_for_worker(
        &self,
        timeout: Duration,
        mut changed: impl FnMut(&str),
    ) -> std::result::Result<(), String> {
        let until = Instant::now() + timeout;
        let mut last = String::new();
        loop {
            let workers = self.pool.workers();
            if workers.iter().any(|w| w.health == Health::Up) {
                return Ok(());
            }
            let state = describe(&workers);
            if state != last {
                changed(&format!(
                    "waiting up to {:.0} s for a worker: {state}",
                    timeout.as_secs_f64()
                ));
                last = state.clone();
            }
            if self.fixed && !workers.is_empty() && workers.iter().all(|w| w.refused && !w.ever_up)
            {
                return Err(format!("no worker is listening: {state}"));
            }
            if !self.pool.has_prospects() {
                return Err(format!("no worker can be used: {state}"));
            }
            if Instant::now() > until {
                return Err(format!(
                    "no worker up after {:.0} s: {state}",
                    timeout.as_secs_f64()
                ));
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Wait until at least `count` workers are up; false when `timeout` passes first.
    pub fn wait_until_up(&self, count: usize, timeout: Duration) -> bool {
        let until = Instant::now() + timeout;
        loop {
            let up = self
                .pool
                .workers()
                .iter()
                .filter(|w| w.health == Health::Up)
                .count();
            if up >= count {
                return true;
            }
            if Instant::now() > until {
                return false;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// The workers of a pool in a few words: how many are up, and each that is not.
pub fn describe(workers: &[WorkerView]) -> String {
    if workers.is_empty() {
        return "none known yet".into();
    }
    let up = workers.iter().filter(|w| w.health == Health::Up).count();
    let mut text = format!("{up} of {} up", workers.len());
    for w in workers.iter().filter(|w| w.health != Health::Up) {
        text.push_str(&format!("; {} {}", w.url, w.health));
    }
    text
}
