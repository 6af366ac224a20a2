//! The coordinator's gRPC server: health, reflection and the worker Registry, over a pool
//! of workers kept alive for campaigns.

use crate::dispatch::registry::RegistryService;
use crate::dispatch::{self, DispatchConfig, WorkerPool};
use crate::error::{Error, Result};
use calib_proto::v1::registry_server::RegistryServer;
use std::net::SocketAddr;
use std::sync::Arc;
use tokio::net::TcpListener;
use tokio::sync::oneshot;
use tokio::task::JoinHandle;
use tonic::transport::server::TcpIncoming;

/// How a coordinator runs.
#[derive(Debug, Clone)]
pub struct CoordinatorConfig {
    pub listen: SocketAddr,
    pub dispatch: DispatchConfig,
}

/// A coordinator serving in this process.
pub struct RunningCoordinator {
    address: SocketAddr,
    pool: Arc<WorkerPool>,
    shutdown: Option<oneshot::Sender<()>>,
    server: JoinHandle<std::result::Result<(), tonic::transport::Error>>,
}

impl RunningCoordinator {
    pub fn address(&self) -> SocketAddr {
        self.address
    }

    /// The workers this coordinator dispatches to.
    pub fn pool(&self) -> &Arc<WorkerPool> {
        &self.pool
    }

    /// Serve until the server fails.
    pub async fn wait(mut self) -> Result<()> {
        (&mut self.server)
            .await
            .map_err(|e| Error::Dispatch(format!("coordinator server task failed: {e}")))?
            .map_err(|e| Error::Dispatch(format!("coordinator server failed: {e}")))
    }

    pub async fn shutdown(mut self) {
        if let Some(tx) = self.shutdown.take() {
            let _ = tx.send(());
        }
        let _ = (&mut self.server).await;
    }
}

/// Bind `config.listen` and serve.
pub async fn start_coordinator(config: CoordinatorConfig) -> Result<RunningCoordinator> {
    let listener = TcpListener::bind(config.listen)
        .await
        .map_err(|e| Error::InvalidRequest(format!("cannot listen on {}: {e}", config.listen)))?;
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
    let pool = dispatch::start_pool(config.dispatch.clone())?;
    let registry = RegistryServer::new(RegistryService::new(
        pool.clone(),
        config.dispatch.heartbeat,
    ));
    let (health_reporter, health) = tonic_health::server::health_reporter();
    let reflection = tonic_reflection::server::Builder::configure()
        .register_encoded_file_descriptor_set(calib_proto::FILE_DESCRIPTOR_SET)
        .register_encoded_file_descriptor_set(tonic_health::pb::FILE_DESCRIPTOR_SET)
        .build_v1()
        .map_err(|e| Error::Dispatch(e.to_string()))?;
    let (shutdown_tx, shutdown_rx) = oneshot::channel::<()>();
    let incoming = TcpIncoming::from(listener).with_nodelay(Some(true));
    let server = tokio::spawn(async move {
        health_reporter
            .set_serving::<RegistryServer<RegistryService>>()
            .await;
        tonic::transport::Server::builder()
            .add_service(health)
            .add_service(reflection)
            .add_service(registry)
            .serve_with_incoming_shutdown(incoming, async {
                let _ = shutdown_rx.await;
            })
            .await
    });
    tracing::info!(%address, "coordinator serving");
    Ok(RunningCoordinator {
        address,
        pool,
        shutdown: Some(shutdown_tx),
        server,
    })
}
