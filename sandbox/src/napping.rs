//! A Simulator that simulates nothing: it answers every Evaluate after a nap per point and
//! slot, its slots shared by the requests it serves at once (a request queued behind
//! another waits for its slots, as on a worker).
//!
//! For measuring the coordinator's dispatch without the cost of simulations, and for fault
//! tests (a nap of `Duration::MAX` is a worker that hangs). It serves the health service
//! and `Status` like a real worker, asks for a measurement it has not seen as a worker
//! does, and refuses everything else as unimplemented.

use calib_proto::v1 as proto;
use calib_proto::v1::simulator_server::{Simulator, SimulatorServer};
use std::collections::HashSet;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;
use tokio::net::TcpListener;
use tonic::{Request, Response, Status};

pub struct NappingSimulator {
    nap: Duration,
    slots: u32,
    /// The slots not napping.
    free: tokio::sync::Semaphore,
    requests: AtomicU64,
    in_flight: AtomicU64,
    most_in_flight: AtomicU64,
    most_points: AtomicU64,
    /// Hashes of the measurements received, as a worker caches them.
    measurements: Mutex<HashSet<Vec<u8>>>,
    uploads: AtomicU64,
}

impl NappingSimulator {
    /// Requests to Evaluate received so far.
    pub fn requests(&self) -> u64 {
        self.requests.load(Ordering::Relaxed)
    }

    /// Most Evaluate requests that were being answered at once.
    pub fn most_in_flight(&self) -> u64 {
        self.most_in_flight.load(Ordering::SeqCst)
    }

    /// Evaluate requests that carried their measurement.
    pub fn uploads(&self) -> u64 {
        self.uploads.load(Ordering::SeqCst)
    }

    /// Most points one Evaluate request carried.
    pub fn most_points(&self) -> u64 {
        self.most_points.load(Ordering::SeqCst)
    }
}

/// Serve a napping worker on `listener` (on the current runtime).
pub async fn serve_napping(
    listener: TcpListener,
    nap: Duration,
    slots: u32,
) -> Arc<NappingSimulator> {
    let simulator = Arc::new(NappingSimulator {
        nap,
        slots,
        free: tokio::sync::Semaphore::new(slots.max(1) as usize),
        requests: AtomicU64::new(0),
        in_flight: AtomicU64::new(0),
        most_in_flight: AtomicU64::new(0),
        most_points: AtomicU64::new(0),
        measurements: Mutex::new(HashSet::new()),
        uploads: AtomicU64::new(0),
    });
    let (reporter, health) = tonic_health::server::health_reporter();
    reporter
        .set_serving::<SimulatorServer<NappingSimulator>>()
        .await;
    let incoming = tonic::transport::server::TcpIncoming::from(listener).with_nodelay(Some(true));
    tokio::spawn(
        tonic::transport::Server::builder()
            .add_service(health)
            .add_service(SimulatorServer::from_arc(simulator.clone()))
            .serve_with_incoming(incoming),
    );
    simulator
}

fn unimplemented<T>() -> Result<Response<T>, Status> {
    Err(Status::unimplemented("a napping worker only evaluates"))
}

#[tonic::async_trait]
impl Simulator for NappingSimulator {
    async fn list_models(
        &self,
        _: Request<proto::ListModelsRequest>,
    ) -> Result<Response<proto::ListModelsResponse>, Status> {
        unimplemented()
    }

    async fn describe(
        &self,
        _: Request<proto::DescribeRequest>,
    ) -> Result<Response<proto::DescribeResponse>, Status> {
        unimplemented()
    }

    async fn simulate(
        &self,
        _: Request<proto::SimulateRequest>,
    ) -> Result<Response<proto::SimulateResponse>, Status> {
        unimplemented()
    }

    async fn evaluate(
        &self,
        request: Request<proto::EvaluateRequest>,
    ) -> Result<Response<proto::EvaluateResponse>, Status> {
        self.requests.fetch_add(1, Ordering::Relaxed);
        {
            // Like a worker: a measurement is sent once, then named by its hash.
            let request = request.get_ref();
            let mut known = self.measurements.lock().expect("measurements lock");
            if request.measurement.is_some() {
                self.uploads.fetch_add(1, Ordering::SeqCst);
                known.insert(request.measurement_hash.clone());
            } else if !known.contains(&request.measurement_hash) {
                return Err(Status::not_found("measurement_hash: not cached here"));
            }
        }
        let now = self.in_flight.fetch_add(1, Ordering::SeqCst) + 1;
        self.most_in_flight.fetch_max(now, Ordering::SeqCst);
        let request = request.into_inner();
        self.most_points
            .fetch_max(request.points.len() as u64, Ordering::SeqCst);
        let rounds = (request.points.len() as u32).div_ceil(self.slots.max(1));
        {
            let slots = (request.points.len() as u32).clamp(1, self.slots.max(1));
            let _napping = self.free.acquire_many(slots).await;
            tokio::time::sleep(self.nap.saturating_mul(rounds)).await;
        }
        self.in_flight.fetch_sub(1, Ordering::SeqCst);
        let outputs = request.outputs.len();
        Ok(Response::new(proto::EvaluateResponse {
            results: request
                .points
                .iter()
                .map(|_| proto::PointResult {
                    objective: 1.0,
                    sse: vec![1.0; outputs],
                    failure: None,
                    residuals: Vec::new(),
                })
                .collect(),
            measurement_hash: request.measurement_hash.clone(),
        }))
    }

    async fn upload_fmu(
        &self,
        _: Request<proto::UploadFmuRequest>,
    ) -> Result<Response<proto::UploadFmuResponse>, Status> {
        unimplemented()
    }

    async fn status(
        &self,
        _: Request<proto::StatusRequest>,
    ) -> Result<Response<proto::StatusResponse>, Status> {
        Ok(Response::new(proto::StatusResponse {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            release: env!("CARGO_PKG_VERSION").into(),
            slots: self.slots,
            // Requests wait for slots without bound; this is what the dispatcher is told.
            queue_bound: 64 * self.slots,
            ..Default::default()
        }))
    }
}
