//! The streams of the watching RPCs: every state of a live campaign, diagnosis or analysis
//! as a message, to its end.

use super::messages::analysis_state;
use crate::hosting::analyses::AnalysisSnapshot;
use calib_proto::v1 as pb;
use std::pin::Pin;
use tokio_stream::wrappers::ReceiverStream;
use tonic::Status;

pub(super) type StateStream =
    Pin<Box<dyn tokio_stream::Stream<Item = Result<pb::CampaignState, Status>> + Send>>;

pub(super) type DiagnosisStream =
    Pin<Box<dyn tokio_stream::Stream<Item = Result<pb::DiagnosisState, Status>> + Send>>;

pub(super) type AnalysisStream =
    Pin<Box<dyn tokio_stream::Stream<Item = Result<pb::AnalysisState, Status>> + Send>>;

/// Every state of `receiver` as a message, from the current one to the one that `ended`.
pub(super) fn follow<S, M>(
    mut receiver: tokio::sync::watch::Receiver<S>,
    message: fn(&S) -> M,
    ended: fn(&S) -> bool,
) -> Pin<Box<dyn tokio_stream::Stream<Item = Result<M, Status>> + Send>>
where
    S: Clone + Send + Sync + 'static,
    M: Send + 'static,
{
    let (tx, rx) = tokio::sync::mpsc::channel(16);
    tokio::spawn(async move {
        loop {
            let snapshot = receiver.borrow_and_update().clone();
            if tx.send(Ok(message(&snapshot))).await.is_err() || ended(&snapshot) {
                break;
            }
            if receiver.changed().await.is_err() {
                break;
            }
        }
    });
    Box::pin(ReceiverStream::new(rx))
}

/// Every state of an analysis, to its end.
pub(super) fn follow_analysis(
    receiver: tokio::sync::watch::Receiver<AnalysisSnapshot>,
) -> AnalysisStream {
    follow(receiver, analysis_state, |s| s.phase.ended())
}
