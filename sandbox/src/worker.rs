//! One real worker on a tokio runtime of its own, so that [`SandboxWorker::kill`] stops it
//! abruptly: its runtime goes and every connection drops at once, as when a process dies.

use calib_worker::service::{serve_worker, RunningWorker, WorkerConfig};
use std::net::SocketAddr;

pub struct SandboxWorker {
    worker: RunningWorker,
    /// `http`, or `https` when serving TLS.
    scheme: &'static str,
    runtime: Option<tokio::runtime::Runtime>,
}

impl SandboxWorker {
    /// A worker with `slots` simulation slots and the given queue bound.
    pub fn start(slots: usize, queue_bound: usize) -> Self {
        Self::serve(loopback(), |config| {
            config.slots = slots;
            config.queue_bound = queue_bound;
        })
    }

    /// A worker of `slots` slots registering with the coordinator at `coordinator`.
    pub fn start_registered(slots: usize, coordinator: &str) -> Self {
        Self::serve(loopback(), |config| {
            config.slots = slots;
            config.register = Some(coordinator.to_string());
        })
    }

    /// A worker of `slots` slots on `address` (that of a worker killed before: it comes
    /// back where it was).
    pub fn start_at(address: SocketAddr, slots: usize) -> Self {
        Self::serve(address, |config| config.slots = slots)
    }

    /// A worker on a loopback port, configured by `configure` (slots, security, registration).
    pub fn start_with(configure: impl FnOnce(&mut WorkerConfig)) -> Self {
        Self::serve(loopback(), configure)
    }

    fn serve(address: SocketAddr, configure: impl FnOnce(&mut WorkerConfig)) -> Self {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .expect("worker runtime");
        let (worker, scheme) = runtime.block_on(async {
            let listener = bind_shared(address).unwrap_or_else(|e| panic!("bind {address}: {e}"));
            let mut config = WorkerConfig::new(listener.local_addr().expect("bound"));
            config.queue_bound = 64;
            configure(&mut config);
            let scheme = config.security.scheme();
            (
                serve_worker(listener, config).expect("serve worker"),
                scheme,
            )
        });
        Self {
            worker,
            scheme,
            runtime: Some(runtime),
        }
    }

    pub fn url(&self) -> String {
        format!("{}://{}", self.scheme, self.worker.address())
    }

    pub fn address(&self) -> SocketAddr {
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

/// A socket bound to `address` with `SO_REUSEPORT` (and `SO_REUSEADDR` when it is to
/// listen), as every sandbox worker binds.
fn shared_socket(address: SocketAddr, listening: bool) -> std::io::Result<tokio::net::TcpSocket> {
    let socket = if address.is_ipv4() {
        tokio::net::TcpSocket::new_v4()?
    } else {
        tokio::net::TcpSocket::new_v6()?
    };
    // A listener may take a port its predecessor's connections still linger on; a socket
    // that never listens must not, or any socket with SO_REUSEADDR could share its port.
    socket.set_reuseaddr(listening)?;
    #[cfg(unix)]
    socket.set_reuseport(true)?;
    socket.bind(address)?;
    Ok(socket)
}

/// Listen on `address` so that [`hold_port`] can share the port.
fn bind_shared(address: SocketAddr) -> std::io::Result<tokio::net::TcpListener> {
    shared_socket(address, true)?.listen(1024)
}

/// Hold a sandbox worker's port: a socket bound there that never listens. While it lives,
/// and the worker is killed, connections to the port are refused and only a socket that shares
/// it on purpose (as sandbox workers do) can bind it: [`SandboxWorker::start_at`] finds it
/// free when the worker comes back, whatever else runs on the machine.
pub fn hold_port(address: SocketAddr) -> std::io::Result<tokio::net::TcpSocket> {
    shared_socket(address, false)
}

impl Drop for SandboxWorker {
    fn drop(&mut self) {
        self.kill();
    }
}

fn loopback() -> SocketAddr {
    SocketAddr::from(([127, 0, 0, 1], 0))
}
