//! The `calib.v1.Calibration` gRPC service: campaigns for clients in any language. A thin
//! layer: messages are checked and converted here, the work is [`crate::hosting`]'.
//!
//! One concern a module: `service` answers each RPC; `uploads` receives and finds the
//! uploaded datasets and FMUs; `submit` turns a campaign message into the campaign file
//! started; `validation` and `problem` find and word what is wrong with a campaign
//! message; `messages` and `follow` turn the domain's snapshots into the messages and
//! streams answered; `refusals` words the domain's errors for a client.

pub mod defined_effects;
pub mod discovery;
mod follow;
mod messages;
mod problem;
mod refusals;
pub mod result;
mod service;
pub mod spec;
mod submit;
mod uploads;
mod validation;

use crate::hosting::Campaigns;
use calib_engine::error::Error;
use std::sync::Arc;
use tonic::Status;

pub use calib_engine::limits::{MAX_CHUNK_BYTES, MAX_PAGE, MAX_SENSITIVITY_SAMPLES};
pub use problem::Problem;

pub struct CalibrationApi {
    campaigns: Arc<Campaigns>,
}

impl CalibrationApi {
    pub fn new(campaigns: Arc<Campaigns>) -> Self {
        Self { campaigns }
    }

    /// [`blocking`], its refusals worded for a client: no path of this server in them.
    pub(super) async fn blocking<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> Result<T, Error> + Send + 'static,
    ) -> Result<T, Status> {
        blocking(work)
            .await
            .map_err(|s| Status::new(s.code(), self.campaigns.public(s.message())))
    }
}

/// Run blocking domain work off the async runtime.
async fn blocking<T: Send + 'static>(
    work: impl FnOnce() -> Result<T, Error> + Send + 'static,
) -> Result<T, Status> {
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| Status::internal(format!("task failed: {e}")))?
        .map_err(refusals::status)
}
