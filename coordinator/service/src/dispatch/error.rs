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
    /// The worker does not hold the FMU the request names: upload it.
    #[error("FMU not cached on the worker")]
    FmuMissing,
    /// The worker's queue is full (`RESOURCE_EXHAUSTED`).
    #[error("worker busy: {0}")]
    Busy(String),
    /// The worker speaks another protocol version (`FAILED_PRECONDITION`).
    #[error("incompatible worker: {0}")]
    Incompatible(String),
    /// Nothing listens at the worker's address: the connection was refused.
    #[error("connection refused: {0}")]
    Refused(String),
    /// Unreachable, timed out, crashed or shutting down: the request may succeed elsewhere.
    #[error("worker unavailable: {0}")]
    Unavailable(String),
    /// The worker refused this client's token, or this client does not trust the worker's
    /// certificate: a matter of configuration, which asking again does not change.
    #[error("{0}")]
    Untrusted(String),
    /// The answer does not fit the request (wrong number of results).
    #[error("malformed answer: {0}")]
    Malformed(String),
}

impl WorkerError {
    /// True when the same request may succeed on another worker or later (not when invalid,
    /// nor when the token or the certificate was refused): the dispatcher
    /// retries the chunk elsewhere (and takes the worker out) or stops the batch with a
    /// [`Fault`](calib_engine::evaluator::Fault) of kind `Rejected`. The one place that decides.
    pub fn is_retryable(&self) -> bool {
        !matches!(self, WorkerError::Rejected(_) | WorkerError::Untrusted(_))
    }
}

impl From<tonic::Status> for WorkerError {
    fn from(status: tonic::Status) -> Self {
        use tonic::Code;
        if let Some(reason) = calib_security::failure::refusal(&status) {
            return WorkerError::Untrusted(reason);
        }
        let message = status.message().to_string();
        if refused(&status) {
            return WorkerError::Refused(message);
        }
        match status.code() {
            // A worker that runs no FMUs (`PERMISSION_DENIED`) refuses them every time.
            Code::InvalidArgument | Code::PermissionDenied => WorkerError::Rejected(message),
            Code::NotFound if message.starts_with("fmu_hash") => WorkerError::FmuMissing,
            Code::NotFound => WorkerError::MeasurementMissing,
            Code::ResourceExhausted => WorkerError::Busy(message),
            Code::FailedPrecondition | Code::Unimplemented => WorkerError::Incompatible(message),
            code => match calib_security::failure::plain_to_tls_hint(&status) {
                Some(hint) => WorkerError::Unavailable(format!("{code:?}: {message}; {hint}")),
                None => WorkerError::Unavailable(format!("{code:?}: {message}")),
            },
        }
    }
}

/// True when the call failed because nothing listens at the address.
fn refused(status: &tonic::Status) -> bool {
    let mut source: Option<&(dyn std::error::Error + 'static)> = std::error::Error::source(status);
    while let Some(error) = source {
        if let Some(io) = error.downcast_ref::<std::io::Error>() {
            if io.kind() == std::io::ErrorKind::ConnectionRefused {
                return true;
            }
        }
        source = error.source();
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use tonic::Status;

    #[test]
    fn only_an_invalid_request_is_not_worth_retrying() {
        let cases = [
            (Status::invalid_argument("points[0]: NaN"), false),
            (Status::resource_exhausted("queue full"), true),
            (Status::unavailable("shutting down"), true),
            (Status::internal("lost"), true),
            (Status::deadline_exceeded("late"), true),
            (Status::failed_precondition("protocol_version"), true),
            (Status::not_found("measurement_hash"), true),
            (
                Status::unauthenticated("the bearer token is not valid"),
                false,
            ),
        ];
        for (status, retryable) in cases {
            let error = WorkerError::from(status.clone());
            assert_eq!(error.is_retryable(), retryable, "{status:?} -> {error:?}");
        }
        assert_eq!(
            WorkerError::from(Status::invalid_argument("points[0]: NaN")),
            WorkerError::Rejected("points[0]: NaN".into())
        );
    }
}
