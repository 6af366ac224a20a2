//! `calib ui`: the web app in local single-node mode. Campaigns run in this process on all
//! cores ([`LocalEvaluator`], as `calib calibrate` runs them) and keep their evaluations in
//! a store on disk (as `calib calibrate --db`), which finishes the campaigns it holds
//! unfinished as a coordinator does; simulations of the Model tab run on a Simulator
//! service of this process.

use super::WebApp;
use crate::hosting::datasets::Datasets;
use crate::hosting::fmus::Fmus;
use crate::hosting::resume;
use crate::hosting::{self, Campaigns};
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::store::SledStore;
use calib_worker::service::cache::MeasurementCache;
use calib_worker::service::fmu_cache::FmuCache;
use calib_worker::service::pool::SimulationPool;
use calib_worker::service::simulator::SimulatorService;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use tokio::net::TcpListener;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

/// How `calib ui` runs.
#[derive(Debug, Clone)]
pub struct UiConfig {
    pub listen: SocketAddr,
    /// Evaluation store (a folder, created when absent).
    pub store: PathBuf,
    /// Uploaded datasets in `datasets/`, results in `results/<id>/` [default: `calib-api/`
    /// beside the store].
    pub api: Option<PathBuf>,
    /// Host names the app also answers as (`--allow-host`), besides its address and
    /// localhost.
    pub allow_hosts: Vec<String>,
}

/// A Simulator service of this process, one slot per core: the Model tab's simulations.
pub fn simulator() -> Arc<SimulatorService> {
    Arc::new(simulator_service())
}

fn simulator_service() -> SimulatorService {
    let slots = std::thread::available_parallelism().map_or(1, |n| n.get());
    SimulatorService::new(
        SimulationPool::new(slots, 64 * slots),
        MeasurementCache::new(16 << 20),
    )
}

/// [`simulator`], which also simulates the FMUs uploaded to `fmus` (named by their hash,
/// as a worker's are; their code runs in the host processes of this binary).
pub fn simulator_with_fmus(fmus: &Fmus) -> Result<Arc<SimulatorService>> {
    let cache =
        FmuCache::new(fmus.folder().to_path_buf(), u64::MAX).map_err(|source| Error::Write {
            path: fmus.folder().to_path_buf(),
            source,
        })?;
    Ok(Arc::new(simulator_service().with_fmus(Some(cache))))
}

/// The web app serving in this process.
pub struct RunningUi {
    address: SocketAddr,
    shutdown: Option<oneshot::Sender<()>>,
    server: JoinHandle<std::io::Result<()>>,
}

impl RunningUi {
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// Serve until the server fails.
    pub async fn wait(mut self) -> Result<()> {
        (&mut self.server)
            .await
            .map_err(|e| Error::Dispatch(format!("web server task failed: {e}")))?
            .map_err(|e| Error::Dispatch(format!("web server failed: {e}")))
    }

    pub async fn shutdown(mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        let _ = (&mut self.server).await;
    }
}

/// Open the store, bind `config.listen` and serve the app.
pub async fn start_ui(config: UiConfig) -> Result<RunningUi> {
    crate::memory::map_large_blocks();
    let store = Arc::new(SledStore::open(&config.store)?);
    let folder = config
        .api
        .clone()
        .unwrap_or_else(|| hosting::default_folder(Some(&config.store)));
    let campaigns = Arc::new(
        Campaigns::new(
            store.clone(),
            Arc::new(LocalEvaluator),
            Datasets::open(&folder.join("datasets"))?,
            folder.join("results"),
        )
        .with_fmus(Fmus::open(&folder.join("fmus"))?),
    );
    let simulator = simulator_with_fmus(campaigns.fmus()?)?;
    let listener = TcpListener::bind(config.listen)
        .await
        .map_err(|source| Error::Listen {
            option: "--listen",
            address: config.listen,
            source,
        })?;
    // Campaigns a killed `calib ui` or `calib calibrate` left running on this store finish
    // here, replayed from the store, their results where `calib calibrate` puts them.
    let live = campaigns.clone();
    tokio::task::spawn_blocking(move || {
        let skip = |id: &_| live.is_live(id);
        match resume::resume_campaigns_except(&live, None, &skip) {
            Ok(0) => {}
            Ok(count) => tracing::info!(campaigns = count, "unfinished campaigns resumed"),
            Err(e) => tracing::error!(error = %e, "cannot resume unfinished campaigns"),
        }
    });
    let door = super::door::DoorConfig {
        allow_hosts: config.allow_hosts,
        token: None,
    };
    serve_app(
        listener,
        WebApp::new(campaigns, simulator)
            .with_door(door)
            .with_fmu_simulation(true),
    )
}

/// Serve `app` on an already bound listener.
pub fn serve_app(listener: TcpListener, app: WebApp) -> Result<RunningUi> {
    let address = listener
        .local_addr()
        .map_err(|e| Error::Dispatch(e.to_string()))?;
    let (tx, rx) = oneshot::channel::<()>();
    let server = tokio::spawn(super::serve(listener, app.router(address), async {
        let _ = rx.await;
    }));
    tracing::info!(%address, "web app serving");
    Ok(RunningUi {
        address,
        shutdown: Some(tx),
        server,
    })
}
