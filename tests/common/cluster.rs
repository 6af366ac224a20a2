//! An in-process cluster: workers serving on `127.0.0.1` port-0 listeners, each on a tokio
//! runtime of its own so that `kill` can stop one abruptly (its connections drop at once,
//! as when a process dies), and a coordinator-side pool dispatching to them.

use calib_coordinator::dispatch::{DispatchConfig, RemoteWorkers, WorkerAddress};
use calib_worker::service::{serve_worker, RunningWorker, WorkerConfig};
use std::time::Duration;

/// One worker of a [`TestCluster`].
pub struct TestWorker {
    worker: RunningWorker,
    runtime: Option<tokio::runtime::Runtime>,
}

impl TestWorker {
    /// A worker with `slots` simulation slots and the given queue bound.
    pub fn start(slots: usize, queue_bound: usize) -> Self {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .expect("worker runtime");
        let worker = runtime.block_on(async {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
                .await
                .expect("bind 127.0.0.1:0");
            let mut config = WorkerConfig::new(listener.local_addr().unwrap());
            config.slots = slots;
            config.queue_bound = queue_bound;
            serve_worker(listener, config).expect("serve worker")
        });
        Self {
            worker,
            runtime: Some(runtime),
        }
    }

    pub fn url(&self) -> String {
        format!("http://{}", self.worker.address())
    }

    pub fn address(&self) -> std::net::SocketAddr {
        self.worker.address()
    }

    /// Simulations this worker has completed.
    pub fn simulations(&self) -> u64 {
        self.worker.load().completed
    }

    /// True when no simulation runs or waits (those of a client that went away included).
    pub fn is_idle(&self) -> bool {
        let load = self.worker.load();
        load.running == 0 && load.queued == 0
    }

    /// Stop the worker abruptly: its runtime goes, and with it every connection.
    pub fn kill(&mut self) {
        if let Some(runtime) = self.runtime.take() {
            runtime.shutdown_background();
        }
    }

    pub fn is_alive(&self) -> bool {
        self.runtime.is_some()
    }
}

impl Drop for TestWorker {
    fn drop(&mut self) {
        self.kill();
    }
}

pub struct TestCluster {
    pub workers: Vec<TestWorker>,
}

impl TestCluster {
    /// `count` workers of `slots` slots each.
    pub fn start(count: usize, slots: usize) -> Self {
        Self {
            workers: (0..count).map(|_| TestWorker::start(slots, 64)).collect(),
        }
    }

    /// `--workers` for the `calib` binary: every worker of the cluster.
    pub fn workers_arg(&self) -> String {
        let urls: Vec<String> = self.workers.iter().map(|w| w.url()).collect();
        urls.join(",")
    }

    /// Simulations completed by all workers together.
    pub fn simulations(&self) -> u64 {
        self.workers.iter().map(|w| w.simulations()).sum()
    }

    /// Wait until every worker is idle, and return the simulations they completed.
    pub fn settled_simulations(&self) -> u64 {
        // Idle at two polls in a row with the same count: a simulation that just left its
        // slot is counted.
        let mut last = None;
        super::await_condition(
            "the workers to finish what they were given",
            Duration::from_secs(60),
            || {
                let now = self.simulations();
                let settled = self.workers.iter().all(|w| w.is_idle()) && last == Some(now);
                last = Some(now);
                settled
            },
        );
        self.simulations()
    }

    /// Dispatch settings for tests: every worker of the cluster, quick probes.
    pub fn dispatch_config(&self) -> DispatchConfig {
        let mut config = DispatchConfig::new(
            self.workers
                .iter()
                .map(|w| WorkerAddress::Url(w.url()))
                .collect(),
        );
        config.probe_interval = Duration::from_millis(100);
        config.probe_timeout = Duration::from_secs(2);
        config.deadline = Duration::from_secs(60);
        config.wait_for_workers = Duration::from_secs(30);
        config
    }

    /// A coordinator-side pool over every worker, returned once all are up.
    pub fn connect(&self) -> RemoteWorkers {
        let remote = RemoteWorkers::connect(self.dispatch_config()).expect("connect");
        assert!(
            remote.wait_until_up(self.workers.len(), Duration::from_secs(10)),
            "workers did not come up: {:?}",
            remote.pool().workers()
        );
        remote
    }
}
