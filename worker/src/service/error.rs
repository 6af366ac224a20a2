//! The worker service's error type and its gRPC status.

/// Why a request to the worker was not answered. Its gRPC status code is all a client sees;
/// whether a request is worth retrying elsewhere is decided on the coordinator's side
/// (`calib_service::dispatch::WorkerError::is_retryable`).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum Error {
    /// The request is malformed; `field` names the offending field of the request.
    #[error("{field}: {message}")]
    InvalidArgument { field: String, message: String },
    /// The client speaks another version of the protocol.
    #[error("protocol_version: the client speaks version {client}, this worker speaks {worker}")]
    ProtocolMismatch { client: u32, worker: u32 },
    /// The worker does not hold the measurement the request names.
    #[error("measurement_hash: measurement {hash} is not cached here; repeat the request with `measurement` set")]
    MeasurementMissing { hash: String },
    /// The worker does not hold the FMU the request names.
    #[error(
        "fmu_hash: FMU {hash} is not cached here; upload it with UploadFmu and repeat the request"
    )]
    FmuMissing { hash: String },
    /// The worker was not started with `--allow-fmu`.
    #[error("{field}: this worker runs no FMUs (they run native code); start it with --allow-fmu")]
    FmuRefused { field: String },
    /// Too many simulations are waiting already.
    #[error("the worker's queue is full ({queued} simulations wait, bound {bound}); retry later or elsewhere")]
    QueueFull { queued: usize, bound: usize },
    /// The worker is shutting down or lost the simulation.
    #[error("internal: {0}")]
    Internal(String),
}

impl Error {
    /// An invalid value in `field`.
    pub fn invalid(field: impl Into<String>, message: impl Into<String>) -> Self {
        Error::InvalidArgument {
            field: field.into(),
            message: message.into(),
        }
    }
}

impl From<Error> for tonic::Status {
    fn from(e: Error) -> Self {
        let message = e.to_string();
        match e {
            Error::InvalidArgument { .. } => tonic::Status::invalid_argument(message),
            Error::ProtocolMismatch { .. } => tonic::Status::failed_precondition(message),
            Error::MeasurementMissing { .. } | Error::FmuMissing { .. } => {
                tonic::Status::not_found(message)
            }
            Error::FmuRefused { .. } => tonic::Status::permission_denied(message),
            Error::QueueFull { .. } => tonic::Status::resource_exhausted(message),
            Error::Internal(_) => tonic::Status::internal(message),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
