//! The coordinator's error type.

use crate::campaign::CampaignError;
use crate::evaluator::Fault;
use crate::measurement::MeasurementError;
use crate::store::StoreError;
use std::path::PathBuf;

#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The campaign file is wrong: the user must fix it.
    #[error(transparent)]
    Campaign(#[from] CampaignError),
    /// The measurement is missing or malformed: the user must fix it.
    #[error(transparent)]
    Measurement(#[from] MeasurementError),
    /// A request names something that does not exist or a value out of range.
    #[error("{0}")]
    InvalidRequest(String),
    /// An address to serve on cannot be bound (in use, not this machine's, not permitted):
    /// the machine's state, not the request, is at fault.
    #[error("{option} {address}: cannot listen: {source}")]
    Listen {
        /// The command-line option that named the address.
        option: &'static str,
        address: std::net::SocketAddr,
        source: std::io::Error,
    },
    #[error("cannot write {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("optimiser failed: {0}")]
    Optimiser(String),
    /// No point of the search could be simulated: the model, an effect's formula or the
    /// solver options fail everywhere the search looked. `why` is the best point's failure.
    #[error("every simulation of the search failed; at the start point: {why}")]
    EverySimulationFailed { why: String },
    /// The evaluation store failed (disk, corruption, in use by another process).
    #[error(transparent)]
    Store(#[from] StoreError),
    /// The cluster machinery (runtime, server, workers) failed.
    #[error("dispatch: {0}")]
    Dispatch(String),
    /// Evaluations could not run (no worker, a refused request, a cancellation): the
    /// campaign stopped without a result; its store resumes it.
    #[error("evaluations stopped: {0}")]
    Fault(#[from] Fault),
}

impl Error {
    /// True when the error comes from what the user gave us (campaign, data, request), as
    /// opposed to a failure of the machine or of calib itself.
    pub fn is_bad_input(&self) -> bool {
        matches!(
            self,
            Error::Campaign(_)
                | Error::Measurement(_)
                | Error::InvalidRequest(_)
                | Error::EverySimulationFailed { .. }
        )
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
