//! What can go wrong when asking a worker.

/// A worker's answer other than results, classified for the dispatcher.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WorkerError {
    /// The worker judged the request invalid (`INVALID_ARGUMENT`): asking again, here or
    /// elsewhere, gives the same answer, so it is never retried.
    #[error("request rejected: {0}")]
    Rejected(String),
    /// The worker does not hold the measurement: send it along.
    #[error("measurement not cached on the worker")]
    MeasurementMissing,
    /// The worker's queue is full (`RESOURCE_EXHAUSTED`).
    #[error("worker busy: {0}")]
    Busy(String),
    /// The worker speaks another protocol version (`FAILED_PRECONDITION`).
    #[error("incompatible worker: {0}")]
    Incompatible(String),
    /// Unreachable, timed out, crashed or shutting down: the request may succeed elsewhere.
    #[error("worker unavailable: {0}")]
    Unavailable(String),
    /// The answer does not fit the request (wrong number of results).
    #[error("malformed answer: {0}")]
    Malformed(String),
}

impl WorkerError {
    /// True when the same request may succeed on another worker or later.
    pub fn is_retryable(&self) -> bool {
        !matches!(self, WorkerError::Rejected(_))
    }
}

impl From<tonic::Status> for WorkerError {
    fn from(status: tonic::Status) -> Self {
        use tonic::Code;
        let message = status.message().to_string();
        match status.code() {
            Code::InvalidArgument => WorkerError::Rejected(message),
            Code::NotFound => WorkerError::MeasurementMissing,
            Code::ResourceExhausted => WorkerError::Busy(message),
            Code::FailedPrecondition | Code::Unimplemented => WorkerError::Incompatible(message),
            code => WorkerError::Unavailable(format!("{code:?}: {message}")),
        }
    }
}
