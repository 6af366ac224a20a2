//! [`GrpcEvaluator`]: evaluations spread over the pool's workers.
//!
//! A batch is cut into chunks of at most one point per slot of a worker, up to two chunks
//! per worker at once (one running, one waiting in the worker's queue, so that no slot idles
//! while an answer travels back); more points than that wait for the first chunk to return. A chunk whose worker fails
//! (unreachable, crashed, timed out, busy) goes back into the batch to be retried on another
//! worker, and the worker is probed back in later; a chunk the worker rejects as invalid is
//! never retried: its points fail with the worker's reason.
//!
//! [`Evaluator::evaluate`] is synchronous and called from many run threads at once; each
//! call drives its batch on the pool's tokio runtime with [`Handle::block_on`].

use super::client::WireObjective;
use super::error::WorkerError;
use super::pool::{Lease, WorkerPool};
use crate::evaluator::Evaluator;
use crate::objective::{Evaluation, Objective};
use std::collections::{HashMap, VecDeque};
use std::sync::{Arc, Mutex};
use std::time::Instant;
use tokio::runtime::Handle;
use tokio::task::JoinSet;

pub struct GrpcEvaluator {
    pool: Arc<WorkerPool>,
    runtime: Handle,
    /// Objectives already put in wire form, by fingerprint.
    wire: Mutex<HashMap<[u8; 32], Arc<WireObjective>>>,
}

impl GrpcEvaluator {
    /// Evaluate on `pool`, whose tasks run on `runtime`.
    pub fn new(pool: Arc<WorkerPool>, runtime: Handle) -> Self {
        Self {
            pool,
            runtime,
            wire: Mutex::new(HashMap::new()),
        }
    }

    pub fn pool(&self) -> &Arc<WorkerPool> {
        &self.pool
    }

    fn wire(&self, objective: &Objective) -> Arc<WireObjective> {
        let mut wire = self.wire.lock().expect("wire lock");
        wire.entry(objective.fingerprint())
            .or_insert_with(|| Arc::new(WireObjective::new(objective)))
            .clone()
    }
}

impl Evaluator for GrpcEvaluator {
    fn evaluate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Evaluation> {
        if points.is_empty() {
            return Vec::new();
        }
        let wire = self.wire(objective);
        self.runtime
            .block_on(dispatch(self.pool.clone(), wire, points.to_vec()))
    }
}

/// What one chunk came back with.
struct ChunkOutcome {
    lease: Lease,
    indices: Vec<usize>,
    result: Result<Vec<Evaluation>, WorkerError>,
}

/// Evaluate `points` on the pool's workers, retrying what failed elsewhere.
pub async fn dispatch(
    pool: Arc<WorkerPool>,
    objective: Arc<WireObjective>,
    points: Vec<Vec<f64>>,
) -> Vec<Evaluation> {
    let config = pool.config().clone();
    let mut answers: Vec<Option<Evaluation>> = vec![None; points.len()];
    let mut attempts = vec![0u32; points.len()];
    let mut last_error: Vec<Option<String>> = vec![None; points.len()];
    let mut pending: VecDeque<usize> = (0..points.len()).collect();
    let mut in_flight: JoinSet<ChunkOutcome> = JoinSet::new();
    let mut idle_since: Option<Instant> = None;
    let points = Arc::new(points);

    while !pending.is_empty() || !in_flight.is_empty() {
        // Listen for pool changes before leasing, so that none is missed in between.
        let changed = pool.notified();
        tokio::pin!(changed);
        changed.as_mut().enable();
        for lease in pool.acquire(pending.len()) {
            let indices: Vec<usize> = pending.drain(..lease.points).collect();
            let chunk: Vec<Vec<f64>> = indices.iter().map(|&i| points[i].clone()).collect();
            let objective = objective.clone();
            let deadline = config.deadline;
            in_flight.spawn(async move {
                let result = lease.client.evaluate(&objective, chunk, deadline).await;
                ChunkOutcome {
                    lease,
                    indices,
                    result,
                }
            });
        }
        if in_flight.is_empty() {
            // Points wait and no worker has a free slot: wait for one to come up.
            let since = *idle_since.get_or_insert_with(Instant::now);
            if since.elapsed() > config.wait_for_workers || !pool.has_prospects() {
                let why = format!(
                    "no worker available for {:.0} s",
                    since.elapsed().as_secs_f64()
                );
                tracing::error!(points = pending.len(), "{why}");
                for i in pending.drain(..) {
                    let reason = last_error[i].clone().unwrap_or_else(|| why.clone());
                    answers[i] = Some(Evaluation::failed(objective.outputs, reason));
                }
                break;
            }
            let _ = tokio::time::timeout(config.probe_interval, changed).await;
            continue;
        }
        idle_since = None;
        let outcome = tokio::select! {
            done = in_flight.join_next() => done,
            // Slots freed elsewhere or a worker came up: lease more while chunks run.
            _ = &mut changed, if !pending.is_empty() => None,
        };
        let Some(joined) = outcome else { continue };
        let ChunkOutcome {
            lease,
            indices,
            result,
        } = match joined {
            Ok(outcome) => outcome,
            Err(e) => panic!("dispatch task failed: {e}"),
        };
        match result {
            Ok(evaluations) => {
                pool.release(&lease, indices.len());
                for (i, e) in indices.into_iter().zip(evaluations) {
                    answers[i] = Some(e);
                }
            }
            Err(WorkerError::Rejected(reason)) => {
                pool.release(&lease, 0);
                tracing::warn!(worker = %lease.client.url(), %reason, "worker rejected a request");
                for i in indices {
                    answers[i] = Some(Evaluation::failed(
                        objective.outputs,
                        format!("rejected by worker {}: {reason}", lease.client.url()),
                    ));
                }
            }
            Err(error) => {
                pool.release(&lease, 0);
                match &error {
                    WorkerError::Incompatible(reason) => {
                        pool.mark_incompatible(lease.worker, reason.clone())
                    }
                    _ => pool.mark_down(lease.worker, error.to_string()),
                }
                tracing::debug!(worker = %lease.client.url(), %error, points = indices.len(), "chunk failed, retrying elsewhere");
                for i in indices.into_iter().rev() {
                    attempts[i] += 1;
                    last_error[i] = Some(format!("{}: {error}", lease.client.url()));
                    if attempts[i] >= config.max_attempts {
                        answers[i] = Some(Evaluation::failed(
                            objective.outputs,
                            format!(
                                "gave up after {} attempts, last: {}",
                                attempts[i],
                                last_error[i].as_deref().unwrap_or_default()
                            ),
                        ));
                    } else {
                        pending.push_front(i);
                    }
                }
            }
        }
    }
    answers
        .into_iter()
        .map(|a| a.expect("every point answered"))
        .collect()
}
