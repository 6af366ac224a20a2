//! A coordinator in the test's own process: on the store (`db`) and API files (`api`) of a
//! folder, dispatching to given workers, on a runtime of its own; shut down when dropped.

use calib_proto::v1::calibration_client::CalibrationClient;
use calib_service::server::{serve_coordinator, CoordinatorConfig, RunningCoordinator};
use std::path::Path;
use tonic::transport::Channel;

pub struct Coordinator {
    pub runtime: tokio::runtime::Runtime,
    pub server: Option<RunningCoordinator>,
}

impl Coordinator {
    pub fn start(dir: &Path, workers: &[String]) -> Self {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let mut config = CoordinatorConfig::new(
            "127.0.0.1:0".parse().unwrap(),
            calib_sandbox::cluster::dispatch_config(workers),
        );
        config.store = Some(dir.join("db"));
        config.api = Some(dir.join("api"));
        let server = runtime.block_on(async {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            serve_coordinator(listener, config).unwrap()
        });
        Self {
            runtime,
            server: Some(server),
        }
    }

    pub fn url(&self) -> String {
        format!("http://{}", self.server.as_ref().unwrap().address())
    }

    pub fn client(&self) -> CalibrationClient<Channel> {
        let url = self.url();
        self.runtime
            .block_on(async { CalibrationClient::connect(url).await })
            .unwrap()
    }
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        if let Some(server) = self.server.take() {
            self.runtime.block_on(server.shutdown());
        }
    }
}
