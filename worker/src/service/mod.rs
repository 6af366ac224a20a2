//! The worker's gRPC server: the `calib.v1.Simulator` service over the hosted models, with
//! the standard health and reflection services.
//!
//! Simulations run on a bounded pool of blocking threads ([`pool`]), so the async runtime
//! keeps answering health checks and refusals while every core simulates. Requests are
//! checked completely on arrival ([`request`]); measurements are cached by content hash
//! ([`cache`]). A worker given a coordinator's address registers with it and renews the
//! registration as a heartbeat ([`registration`]).

pub mod cache;
pub mod error;
pub mod fmu_cache;
pub mod pool;
pub mod registration;
pub mod request;
pub mod simulator;

pub use error::Error;
pub use pool::PoolLoad;

use calib_proto::v1::simulator_server::SimulatorServer;
use calib_security::{ClientSecurity, ServerSecurity};
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;
use tokio::net::TcpListener;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;
use tonic::transport::server::TcpIncoming;

pub use calib_model::limits;

/// The services a worker answers, as reflection lists them.
pub const SERVED: &[&str] = &[
    "calib.v1.Simulator",
    "grpc.health.v1.Health",
    "grpc.reflection.v1.ServerReflection",
    "grpc.reflection.v1alpha.ServerReflection",
];

/// How long a server stopped by a signal lets requests in flight finish.
const SHUTDOWN_GRACE: std::time::Duration = std::time::Duration::from_secs(10);

/// How a worker runs.
#[derive(Debug, Clone)]
pub struct WorkerConfig {
    pub listen: SocketAddr,
    /// Simulations at once.
    pub slots: usize,
    /// Simulations that may wait for a slot; beyond, requests get `RESOURCE_EXHAUSTED`.
    pub queue_bound: usize,
    /// Bound of the measurement cache [bytes].
    pub cache_bytes: usize,
    /// Coordinator to register with (its Registry service), e.g. `http://coordinator:50050`.
    pub register: Option<String>,
    /// URL the coordinator should dial back; default: derived from the bound address.
    pub advertise: Option<String>,
    /// TLS and the token this worker requires.
    pub security: ServerSecurity,
    /// The CA this worker trusts and the token it presents when registering.
    pub register_security: ClientSecurity,
    /// Accept FMUs (their native code runs in child processes): the folder of the FMU
    /// cache and its bound [bytes]. `None`: FMUs are refused with `PERMISSION_DENIED`.
    pub fmu_cache: Option<(PathBuf, u64)>,
}

impl WorkerConfig {
    /// A worker on `listen` with one slot per core and the default bounds.
    pub fn new(listen: SocketAddr) -> Self {
        let slots = std::thread::available_parallelism().map_or(1, |n| n.get());
        Self {
            listen,
            slots,
            queue_bound: 64 * slots,
            cache_bytes: 256 << 20,
            register: None,
            advertise: None,
            security: ServerSecurity::default(),
            register_security: ClientSecurity::default(),
            fmu_cache: None,
        }
    }
}

/// A worker serving in this process.
pub struct RunningWorker {
    address: SocketAddr,
    service: Arc<simulator::SimulatorService>,
    shutdown: Option<oneshot::Sender<()>>,
    server: JoinHandle<Result<(), tonic::transport::Error>>,
    registration: Option<JoinHandle<()>>,
}

impl RunningWorker {
    /// The address the server is bound to (the real port when asked for port 0).
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Load and counters of the simulation pool (simulations completed included).
    pub fn load(&self) -> PoolLoad {
        self.service.load()
    }

    /// Serve until the server fails.
    pub async fn wait(mut self) -> Result<(), tonic::transport::Error> {
        (&mut self.server)
            .await
            .unwrap_or_else(|e| panic!("worker server task failed: {e}"))
    }

    /// Serve until the server fails, or until `stop` completes (a termination signal):
    /// then drain (stop registering, accept no new requests, finish those in flight) and
    /// say so on standard error, with what was held and what was done.
    pub async fn serve_until(
        mut self,
        stop: impl std::future::Future<Output = ()>,
    ) -> Result<(), tonic::transport::Error> {
        tokio::select! {
            outcome = &mut self.server => {
                outcome.unwrap_or_else(|e| panic!("worker server task failed: {e}"))
            }
            () = stop => {
                let service = self.service.clone();
                let held = service.load();
                eprintln!(
                    "calib worker: draining: registration stopped, no new requests; \
                     finishing {} simulations running and {} queued",
                    held.running, held.queued
                );
                // Requests in flight get a few seconds; a stream that would outlive them
                // (a client following a campaign) is cut, and reconnects elsewhere.
                let drained = tokio::time::timeout(SHUTDOWN_GRACE, self.shutdown())
                    .await
                    .is_ok();
                let done = service.load();
                if drained {
                    eprintln!(
                        "calib worker: drained: {} simulations completed since start",
                        done.completed
                    );
                } else {
                    eprintln!(
                        "calib worker: drain cut after {} s with {} simulations running: \
                         {} completed since start",
                        SHUTDOWN_GRACE.as_secs(),
                        done.running,
                        done.completed
                    );
                }
                Ok(())
            }
        }
    }

    /// Stop accepting requests and finish those in flight.
    pub async fn shutdown(mut self) {
        if let Some(task) = self.registration.take() {
            task.abort();
        }
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        let _ = (&mut self.server).await;
    }
}

/// Bind `config.listen` and serve.
pub async fn start_worker(config: WorkerConfig) -> std::io::Result<RunningWorker> {
    let listener = TcpListener::bind(config.listen).await?;
    serve_worker(listener, config)
}

/// Serve on an already bound listener (tests bind `127.0.0.1:0` first).
pub fn serve_worker(listener: TcpListener, config: WorkerConfig) -> std::io::Result<RunningWorker> {
    let address = listener.local_addr()?;
    let service = simulator_service(&config)?;
    let (health_reporter, health) = tonic_health::server::health_reporter();
    let reflection_v1 = reflection(SERVED)
        .build_v1()
        .map_err(std::io::Error::other)?;
    let reflection_v1alpha = reflection(SERVED)
        .build_v1alpha()
        .map_err(std::io::Error::other)?;
    let simulator = SimulatorServer::from_arc(service.clone())
        .max_decoding_message_size(limits::MAX_MESSAGE_BYTES)
        .max_encoding_message_size(limits::MAX_MESSAGE_BYTES);
    let builder = config
        .security
        .apply(tonic::transport::Server::builder())
        .map_err(std::io::Error::other)?;
    let (shutdown_tx, shutdown_rx) = oneshot::channel::<()>();
    let incoming = TcpIncoming::from(listener)
        .with_nodelay(Some(true))
        .with_keepalive(Some(Duration::from_secs(30)));
    let server = tokio::spawn(async move {
        health_reporter
            .set_serving::<SimulatorServer<simulator::SimulatorService>>()
            .await;
        builder
            .http2_keepalive_interval(Some(Duration::from_secs(10)))
            .http2_keepalive_timeout(Some(Duration::from_secs(20)))
            .add_service(health)
            .add_service(reflection_v1)
            .add_service(reflection_v1alpha)
            .add_service(simulator)
            .serve_with_incoming_shutdown(incoming, async {
                let _ = shutdown_rx.await;
            })
            .await
    });
    let registration = spawn_registration(&config, address);
    tracing::info!(
        %address,
        slots = config.slots,
        queue_bound = config.queue_bound,
        tls = config.security.tls.is_some(),
        token = config.security.token.is_some(),
        "worker serving"
    );
    Ok(RunningWorker {
        address,
        service,
        shutdown: Some(shutdown_tx),
        server,
        registration,
    })
}

/// The Simulator service of `config`: its pool, its measurement cache and, when FMUs are
/// accepted, its FMU cache (opened now, so a bad folder fails the start).
fn simulator_service(config: &WorkerConfig) -> std::io::Result<Arc<simulator::SimulatorService>> {
    let fmus = match &config.fmu_cache {
        Some((dir, bound)) => Some(fmu_cache::FmuCache::new(dir.clone(), *bound)?),
        None => None,
    };
    Ok(Arc::new(
        simulator::SimulatorService::new(
            pool::SimulationPool::new(config.slots, config.queue_bound),
            cache::MeasurementCache::new(config.cache_bytes),
        )
        .with_fmus(fmus),
    ))
}

/// The reflection service's builder for a server answering the services `served`, built once
/// per protocol version: reflection lists exactly what that server answers (the worker's and
/// the coordinator's services share one file set of descriptors), over both versions of the
/// protocol.
pub fn reflection(served: &[&str]) -> tonic_reflection::server::Builder<'static> {
    let mut builder = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(calib_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        // Both versions of the reflection protocol describe both reflection services
        // (each build adds only its own file): a client of either version can look up
        // every service it is listed.
        .register_encoded_file_descriptor_set(tonic_reflection::pb::v1::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_reflection::pb::v1alpha::FILE_DESCRIPTOR_SET);
    for name in served {
        builder = builder.with_service_name(*name);
    }
    builder
}

/// With a coordinator to register with: the heartbeat task that registers this worker (at
/// its advertised URL, by default derived from the bound `address`) and renews it.
fn spawn_registration(config: &WorkerConfig, address: SocketAddr) -> Option<JoinHandle<()>> {
    config.register.clone().map(|coordinator| {
        let advertised = config
            .advertise
            .clone()
            .unwrap_or_else(|| registration::advertised_url(address, config.security.scheme()));
        tokio::spawn(registration::heartbeat(
            coordinator,
            advertised,
            config.register_security.clone(),
        ))
    })
}
