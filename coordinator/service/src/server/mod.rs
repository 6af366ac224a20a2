//! The coordinator's gRPC server: the Calibration API ([`crate::api`]), the worker
//! Registry, health and reflection, over a pool of workers kept alive for campaigns. Given
//! an evaluation store, it finishes the campaigns a previous coordinator left unfinished,
//! again whenever workers come back ([`resume`]).

use crate::api::CalibrationApi;
use crate::dispatch::registry::RegistryService;
use crate::dispatch::{self, DispatchConfig, GrpcEvaluator, WorkerPool};
use crate::hosting::datasets::Datasets;
use crate::hosting::fmus::Fmus;
use crate::hosting::resume;
use crate::hosting::{self, Campaigns};
use crate::web::door::DoorConfig;
use crate::web::local::{serve_app, RunningUi};
use crate::web::{self, WebApp};
use calib_engine::error::{Error, Result};
use calib_engine::store::{MemoryStore, SledStore, Store};
use calib_proto::v1::calibration_server::CalibrationServer;
use calib_proto::v1::registry_server::RegistryServer;
use calib_security::ServerSecurity;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use tokio::net::TcpListener;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;
use tonic::transport::server::TcpIncoming;

/// The services a coordinator answers, as reflection lists them.
pub const SERVED: &[&str] = &[
    "calib.v1.Calibration",
    "calib.v1.Registry",
    "grpc.health.v1.Health",
    "grpc.reflection.v1.ServerReflection",
    "grpc.reflection.v1alpha.ServerReflection",
];

/// How long a server stopped by a signal lets requests in flight finish.
const SHUTDOWN_GRACE: std::time::Duration = std::time::Duration::from_secs(10);

/// How a coordinator runs.
#[derive(Debug, Clone)]
pub struct CoordinatorConfig {
    pub listen: SocketAddr,
    pub dispatch: DispatchConfig,
    /// Evaluation store (a folder): the campaigns it holds unfinished are resumed on the
    /// workers once the server is up.
    pub store: Option<PathBuf>,
    /// Folder for the results of resumed campaigns, one `<name>/` each [default:
    /// `results/<name>/` beside each campaign file].
    pub results: Option<PathBuf>,
    /// Folder of the Calibration API: uploaded datasets in `datasets/`, results of submitted
    /// campaigns in `results/<id>/` [default: `calib-api/` beside the store].
    pub api: Option<PathBuf>,
    /// TLS and the token this coordinator's server requires.
    pub security: ServerSecurity,
    /// Serve the web app ([`crate::web`]) on this address too, over the same campaigns,
    /// behind a login when the server has a token.
    pub http: Option<SocketAddr>,
    /// Host names the web app also answers as (`--allow-host`).
    pub http_allow_hosts: Vec<String>,
}

impl CoordinatorConfig {
    /// Serve on `listen` over the workers of `dispatch`, without a store.
    pub fn new(listen: SocketAddr, dispatch: DispatchConfig) -> Self {
        Self {
            listen,
            dispatch,
            store: None,
            results: None,
            api: None,
            security: ServerSecurity::default(),
            http: None,
            http_allow_hosts: Vec::new(),
        }
    }
}

/// A coordinator serving in this process.
pub struct RunningCoordinator {
    address: SocketAddr,
    pool: Arc<WorkerPool>,
    shutdown: Option<oneshot::Sender<()>>,
    server: GrpcTask,
    resume: Option<JoinHandle<Result<usize>>>,
    control: Arc<resume::ResumeControl>,
    web: Option<RunningUi>,
}

impl RunningCoordinator {
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Where the web app is served (`--http`).
    pub fn http_address(&self) -> Option<SocketAddr> {
        self.web.as_ref().map(RunningUi::address)
    }

    /// The workers this coordinator dispatches to.
    pub fn pool(&self) -> &Arc<WorkerPool> {
        &self.pool
    }

    /// Passes made over the store's unfinished campaigns (each after the first waits for a
    /// worker to be up).
    pub fn resume_passes(&self) -> usize {
        self.control
            .passes
            .load(std::sync::atomic::Ordering::SeqCst)
    }

    /// Wait until the unfinished campaigns of the store are finished; how many there were
    /// (0 without a store, and on every call after the first).
    pub async fn resumed(&mut self) -> Result<usize> {
        match self.resume.take() {
            Some(task) => task
                .await
                .map_err(|e| Error::Dispatch(format!("resume task failed: {e}")))?,
            None => Ok(0),
        }
    }

    /// Serve until the server fails.
    pub async fn wait(mut self) -> Result<()> {
        (&mut self.server)
            .await
            .map_err(|e| Error::Dispatch(format!("coordinator server task failed: {e}")))?
            .map_err(|e| Error::Dispatch(format!("coordinator server failed: {e}")))
    }

    /// Serve until the server fails, or until `stop` completes (a termination signal): then
    /// stop resuming campaigns and serving, and let requests in flight finish.
    pub async fn serve_until(mut self, stop: impl std::future::Future<Output = ()>) -> Result<()> {
        tokio::select! {
            outcome = &mut self.server => outcome
                .map_err(|e| Error::Dispatch(format!("coordinator server task failed: {e}")))?
                .map_err(|e| Error::Dispatch(format!("coordinator server failed: {e}"))),
            () = stop => {
                // Requests in flight get a few seconds; a stream that would outlive them
                // (a client following a campaign) is cut, and reconnects elsewhere.
                let _ = tokio::time::timeout(SHUTDOWN_GRACE, self.shutdown()).await;
                Ok(())
            }
        }
    }

    pub async fn shutdown(mut self) {
        self.control
            .stop
            .store(true, std::sync::atomic::Ordering::SeqCst);
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        if let Some(web) = self.web.take() {
            web.shutdown().await;
        }
        let _ = (&mut self.server).await;
    }
}

/// Bind `config.listen` and serve.
pub async fn start_coordinator(config: CoordinatorConfig) -> Result<RunningCoordinator> {
    let listener = TcpListener::bind(config.listen)
        .await
        .map_err(|source| Error::Listen {
            option: "--listen",
            address: config.listen,
            source,
        })?;
    serve_coordinator(listener, config)
}

/// Serve on an already bound listener (tests bind `127.0.0.1:0` first).
pub fn serve_coordinator(
    listener: TcpListener,
    config: CoordinatorConfig,
) -> Result<RunningCoordinator> {
    let address = listener
        .local_addr()
        .map_err(|e| Error::Dispatch(e.to_string()))?;
    crate::memory::map_large_blocks();
    let web_listener = match config.http {
        Some(http) => Some(bind_http(http)?),
        None => None,
    };
    // Open the store first: one held by another process stops the coordinator at once.
    let store = match &config.store {
        Some(path) => Some(Arc::new(SledStore::open(path)?)),
        None => None,
    };
    let pool = dispatch::start_pool(config.dispatch.clone())?;
    let campaigns = open_campaigns(&config, store.as_ref(), &pool)?;
    let web = match web_listener {
        Some(listener) => Some(start_web(listener, &config, &campaigns)?),
        None => None,
    };
    let (shutdown, server) = spawn_grpc(listener, &config, &campaigns, &pool)?;
    tracing::info!(
        %address,
        tls = config.security.tls.is_some(),
        token = config.security.token.is_some(),
        "coordinator serving"
    );
    // Campaigns submitted to the API and left running go on as live campaigns, so their
    // clients follow them; the store's resume below skips them.
    if store.is_some() {
        match campaigns.resume_submitted() {
            Ok(0) => {}
            Ok(count) => tracing::info!(campaigns = count, "submitted campaigns resumed"),
            Err(e) => tracing::error!(error = %e, "cannot resume submitted campaigns"),
        }
    }
    let control = Arc::new(resume::ResumeControl::default());
    let resume = store.map(|_| spawn_resume(&config, &pool, &control, &campaigns));
    Ok(RunningCoordinator {
        address,
        pool,
        shutdown: Some(shutdown),
        server,
        resume,
        control,
        web,
    })
}

/// The web app's listener on `http` (`--http`).
fn bind_http(http: SocketAddr) -> Result<TcpListener> {
    std::net::TcpListener::bind(http)
        .and_then(|l| l.set_nonblocking(true).map(|_| l))
        .and_then(TcpListener::from_std)
        .map_err(|source| Error::Listen {
            option: "--http",
            address: http,
            source,
        })
}

/// The API's campaigns: on the coordinator's store (in memory without one), evaluated on
/// the pool's workers, their datasets, results and FMUs in the API folder.
fn open_campaigns(
    config: &CoordinatorConfig,
    store: Option<&Arc<SledStore>>,
    pool: &Arc<WorkerPool>,
) -> Result<Arc<Campaigns>> {
    let api_folder = config
        .api
        .clone()
        .unwrap_or_else(|| hosting::default_folder(config.store.as_deref()));
    let api_store: Arc<dyn Store> = match store {
        Some(s) => s.clone(),
        None => Arc::new(MemoryStore::new()),
    };
    Ok(Arc::new(
        Campaigns::new(
            api_store,
            Arc::new(GrpcEvaluator::new(
                pool.clone(),
                tokio::runtime::Handle::current(),
            )),
            Datasets::open(&api_folder.join("datasets"))?,
            api_folder.join("results"),
        )
        .with_fmus(Fmus::open(&api_folder.join("fmus"))?),
    ))
}

/// Serve the web app on `listener` over the API's campaigns.
fn start_web(
    listener: TcpListener,
    config: &CoordinatorConfig,
    campaigns: &Arc<Campaigns>,
) -> Result<RunningUi> {
    // The Model tab runs an uploaded FMU's code on this machine only behind the token:
    // without one, anyone reaching the port could. Campaigns on FMUs run on the workers.
    let web_fmus = config.security.token.is_some();
    let simulator = if web_fmus {
        web::local::simulator_with_fmus(campaigns.fmus()?)?
    } else {
        web::local::simulator()
    };
    serve_app(
        listener,
        WebApp::new(campaigns.clone(), simulator)
            .with_door(DoorConfig {
                allow_hosts: config.http_allow_hosts.clone(),
                token: config.security.token.clone(),
            })
            .with_fmu_simulation(web_fmus),
    )
}

/// The gRPC server's task: it ends when the server stops.
type GrpcTask = JoinHandle<std::result::Result<(), tonic::transport::Error>>;

/// Serve health, reflection, the worker registry and the Calibration API on `listener`;
/// the sender stops the server.
fn spawn_grpc(
    listener: TcpListener,
    config: &CoordinatorConfig,
    campaigns: &Arc<Campaigns>,
    pool: &Arc<WorkerPool>,
) -> Result<(oneshot::Sender<()>, GrpcTask)> {
    let calibration = CalibrationServer::new(CalibrationApi::new(campaigns.clone()))
        .max_decoding_message_size(64 << 20)
        .max_encoding_message_size(64 << 20);
    let registry = RegistryServer::new(RegistryService::new(
        pool.clone(),
        config.dispatch.heartbeat,
    ));
    let (health_reporter, health) = tonic_health::server::health_reporter();
    let reflection_v1 = calib_worker::service::reflection(SERVED)
        .build_v1()
        .map_err(|e| Error::Dispatch(e.to_string()))?;
    let reflection_v1alpha = calib_worker::service::reflection(SERVED)
        .build_v1alpha()
        .map_err(|e| Error::Dispatch(e.to_string()))?;
    let mut builder = config
        .security
        .apply(tonic::transport::Server::builder())
        .map_err(|e| Error::InvalidRequest(e.to_string()))?;
    let (shutdown_tx, shutdown_rx) = oneshot::channel::<()>();
    let incoming = TcpIncoming::from(listener).with_nodelay(Some(true));
    let server = tokio::spawn(async move {
        health_reporter
            .set_serving::<RegistryServer<RegistryService>>()
            .await;
        health_reporter
            .set_serving::<CalibrationServer<CalibrationApi>>()
            .await;
        builder
            .add_service(health)
            .add_service(reflection_v1)
            .add_service(reflection_v1alpha)
            .add_service(registry)
            .add_service(calibration)
            .serve_with_incoming_shutdown(incoming, async {
                let _ = shutdown_rx.await;
            })
            .await
    });
    Ok((shutdown_tx, server))
}

/// Finish, on a thread of their own, the campaigns a previous coordinator left running on
/// `store` (those the API follows live excepted).
fn spawn_resume(
    config: &CoordinatorConfig,
    pool: &Arc<WorkerPool>,
    control: &Arc<resume::ResumeControl>,
    campaigns: &Arc<Campaigns>,
) -> JoinHandle<Result<usize>> {
    let results = config.results.clone();
    let (pool, control) = (pool.clone(), control.clone());
    let live = campaigns.clone();
    // Campaigns block for as long as they run: on a thread of their own, through the
    // coordinator's one dispatcher.
    tokio::task::spawn_blocking(move || {
        let resumed =
            resume::resume_until_finished(&live, results.as_deref(), &pool, &control, &|id| {
                live.is_live(id)
            });
        match &resumed {
            Ok(count) => tracing::info!(campaigns = count, "unfinished campaigns resumed"),
            Err(e) => tracing::error!(error = %e, "cannot resume unfinished campaigns"),
        }
        resumed
    })
}
