//! Clusters of sandbox workers and a coordinator-side pool over them.

use crate::napping::{serve_napping, NappingSimulator};
use crate::worker::SandboxWorker;
use calib_service::dispatch::{DispatchConfig, RemoteWorkers, WorkerAddress};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// Dispatch settings for a sandbox: every worker of `urls`, quick probes.
pub fn dispatch_config(urls: &[String]) -> DispatchConfig {
    let mut config = DispatchConfig::new(urls.iter().cloned().map(WorkerAddress::Url).collect());
    config.probe_interval = Duration::from_millis(50);
    config.probe_timeout = Duration::from_secs(2);
    config.deadline = Duration::from_secs(60);
    config.wait_for_workers = Duration::from_secs(30);
    config
}

/// A pool over `urls` ([`dispatch_config`]), returned once every worker is up.
pub fn connect(urls: &[String]) -> Result<RemoteWorkers, String> {
    let remote = RemoteWorkers::connect(dispatch_config(urls)).map_err(|e| e.to_string())?;
    if !remote.wait_until_up(urls.len(), Duration::from_secs(30)) {
        return Err(format!(
            "the sandbox's workers did not come up within 30 s: {:?}",
            remote.pool().workers()
        ));
    }
    Ok(remote)
}

/// Real workers, each on a runtime of its own.
pub struct SandboxCluster {
    pub workers: Vec<SandboxWorker>,
}

impl SandboxCluster {
    /// `count` workers of `slots` slots each.
    pub fn start(count: usize, slots: usize) -> Self {
        Self {
            workers: (0..count)
                .map(|_| SandboxWorker::start(slots, 64))
                .collect(),
        }
    }

    pub fn urls(&self) -> Vec<String> {
        self.workers.iter().map(|w| w.url()).collect()
    }

    /// `--workers` for the `calib` binary: every worker of the cluster.
    pub fn workers_arg(&self) -> String {
        self.urls().join(",")
    }

    /// Simulations completed by all workers together.
    pub fn simulations(&self) -> u64 {
        self.workers.iter().map(|w| w.simulations()).sum()
    }

    /// Wait until every worker is idle, and return the simulations they completed.
    pub fn settled_simulations(&self) -> u64 {
        // Idle at two polls in a row with the same count: a simulation that just left its
        // slot is counted.
        let until = Instant::now() + Duration::from_secs(60);
        let mut last = None;
        loop {
            let now = self.simulations();
            if self.workers.iter().all(|w| w.is_idle()) && last == Some(now) {
                return now;
            }
            assert!(
                Instant::now() < until,
                "the workers did not finish what they were given within 60 s"
            );
            last = Some(now);
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Dispatch settings over every worker of the cluster, quick probes.
    pub fn dispatch_config(&self) -> DispatchConfig {
        dispatch_config(&self.urls())
    }

    /// A coordinator-side pool over every worker, returned once all are up.
    pub fn try_connect(&self) -> Result<RemoteWorkers, String> {
        connect(&self.urls())
    }

    /// [`Self::try_connect`], for tests.
    pub fn connect(&self) -> RemoteWorkers {
        self.try_connect().expect("connect to the sandbox")
    }
}

/// Workers that answer every evaluation after a nap, simulating nothing, all on one runtime.
pub struct NappingCluster {
    _runtime: tokio::runtime::Runtime,
    pub simulators: Vec<Arc<NappingSimulator>>,
    urls: Vec<String>,
}

impl NappingCluster {
    /// `count` workers of `slots` slots napping `nap` per point and slot.
    pub fn start(count: usize, nap: Duration, slots: u32) -> std::io::Result<Self> {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .enable_all()
            .build()?;
        let (urls, simulators) = runtime.block_on(async {
            let mut urls = Vec::new();
            let mut simulators = Vec::new();
            for _ in 0..count {
                let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await?;
                urls.push(format!("http://{}", listener.local_addr()?));
                simulators.push(serve_napping(listener, nap, slots).await);
            }
            Ok::<_, std::io::Error>((urls, simulators))
        })?;
        Ok(Self {
            _runtime: runtime,
            simulators,
            urls,
        })
    }

    pub fn urls(&self) -> &[String] {
        &self.urls
    }

    /// A coordinator-side pool over every worker, returned once all are up.
    pub fn try_connect(&self) -> Result<RemoteWorkers, String> {
        connect(&self.urls)
    }
}
