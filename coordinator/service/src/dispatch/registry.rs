//! The coordinator's `calib.v1.Registry` service: workers announce themselves and renew
//! the announcement as a heartbeat; three missed heartbeats and they are dropped.

use super::discovery::WorkerAddress;
use super::pool::{Origin, WorkerPool};
use calib_proto::v1 as proto;
use std::sync::Arc;
use std::time::{Duration, Instant};
use tonic::{Request, Response, Status};

pub struct RegistryService {
    pool: Arc<WorkerPool>,
    heartbeat: Duration,
}

impl RegistryService {
    pub fn new(pool: Arc<WorkerPool>, heartbeat: Duration) -> Self {
        Self { pool, heartbeat }
    }
}

/// A registration, checked.
struct Registration {
    url: String,
}

impl TryFrom<proto::RegisterRequest> for Registration {
    type Error = Status;

    fn try_from(r: proto::RegisterRequest) -> Result<Self, Status> {
        if r.protocol_version != calib_proto::PROTOCOL_VERSION {
            return Err(Status::failed_precondition(format!(
                "protocol_version: the worker speaks version {}, this coordinator {}",
                r.protocol_version,
                calib_proto::PROTOCOL_VERSION
            )));
        }
        match r.address.parse::<WorkerAddress>() {
            Ok(WorkerAddress::Url(url)) => Ok(Self { url }),
            Ok(WorkerAddress::Dns { .. }) => Err(Status::invalid_argument(
                "address: a worker registers one URL, not a DNS name",
            )),
            Err(e) => Err(Status::invalid_argument(format!("address: {e}"))),
        }
    }
}

#[tonic::async_trait]
impl proto::registry_server::Registry for RegistryService {
    async fn register(
        &self,
        request: Request<proto::RegisterRequest>,
    ) -> Result<Response<proto::RegisterResponse>, Status> {
        let registration = Registration::try_from(request.into_inner())?;
        let expires = Instant::now() + 3 * self.heartbeat;
        self.pool
            .add(&registration.url, Origin::Registered { expires })
            .map_err(|e| Status::invalid_argument(format!("address: {e}")))?;
        Ok(Response::new(proto::RegisterResponse {
            heartbeat_seconds: self.heartbeat.as_secs().max(1) as u32,
        }))
    }
}
