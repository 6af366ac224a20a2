//! [`GrpcEvaluator`]: evaluations and simulations spread over the pool's workers.
//!
//! A batch is cut into chunks sized by what is pending ([`WorkerPool::acquire`]): up to
//! about 50 ms of work per slot of a worker while much is left (as its answers have taken;
//! eight points before the first), one point per slot at the tail; idle
//! slots are filled first, then up to two chunks per worker at once (one running, one
//! waiting in the worker's queue, so that no slot idles while an answer travels back); more
//! points than that wait for a chunk to return. A chunk whose worker fails
//! (unreachable, crashed, timed out, busy) goes back into the batch to be retried on another
//! worker, and the worker is probed back in later; a chunk the worker rejects as invalid is
//! never retried: its points fail with the worker's reason.
//!
//! Evaluations go as one `Evaluate` request per chunk ([`WireObjective`]); simulations,
//! whose outputs the diagnosis needs, as one `Simulate` request per point of the chunk, all
//! at once ([`WireSimulation`]). Both take the same path through the pool.
//!
//! [`Evaluator::evaluate`] and [`Simulator::simulate`] are synchronous: the evaluation
//! store's dispatcher calls them from its round threads (plain threads, outside the
//! runtime), and each call drives its batch on the pool's tokio runtime with
//! [`Handle::block_on`]. Gathering the points of many runs into rounds is the dispatcher's
//! work ([`calib_engine::store::StoredEvaluator`]), not this evaluator's.

use super::client::{WireObjective, WireSimulation, WorkerClient};
use super::error::WorkerError;
use super::pool::{Lease, WorkerPool};
use calib_engine::evaluator::{Evaluator, Fault, Outputs, Simulator};
use calib_engine::objective::{Evaluation, Objective};
use std::collections::{HashMap, VecDeque};
use std::future::Future;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use tokio::runtime::Handle;
use tokio::task::JoinSet;

pub struct GrpcEvaluator {
    pool: Arc<WorkerPool>,
    runtime: Handle,
    /// Objectives already put in wire form, by fingerprint.
    wire: Mutex<WireCache>,
    /// The experiments of objectives of several, each as an objective of its own, by the
    /// whole objective's fingerprint (split once, not per batch).
    parts: Mutex<HashMap<[u8; 32], Arc<Vec<Objective>>>>,
}

impl GrpcEvaluator {
    /// Evaluate on `pool`, whose tasks run on `runtime`.
    pub fn new(pool: Arc<WorkerPool>, runtime: Handle) -> Self {
        Self {
            pool,
            runtime,
            wire: Mutex::new(WireCache::default()),
            parts: Mutex::new(HashMap::new()),
        }
    }

    pub fn pool(&self) -> &Arc<WorkerPool> {
        &self.pool
    }

    fn wire(&self, objective: &Objective) -> Arc<WireObjective> {
        self.wire.lock().expect("wire lock").get(objective)
    }
}

/// Objectives in wire form, most recently used kept: at most [`WIRE_CACHE_VALUES`] numbers
/// of records and [`WIRE_CACHE_ENTRIES`] objectives, and an objective's entries dropped when
/// its work ends ([`Evaluator::release`]).
#[derive(Default)]
struct WireCache {
    entries: HashMap<[u8; 32], (Arc<WireObjective>, u64)>,
    /// Numbers of the records held.
    values: usize,
    /// Uses so far: the last use of each entry orders them.
    tick: u64,
}

/// Most numbers of records the wire cache holds (two of the largest records a campaign may
/// have, about 100 MB).
pub const WIRE_CACHE_VALUES: usize = 2 * calib_model::limits::MAX_RECORD_VALUES;

/// Most objectives the wire cache holds.
pub const WIRE_CACHE_ENTRIES: usize = 64;

impl WireCache {
    fn get(&mut self, objective: &Objective) -> Arc<WireObjective> {
        self.tick += 1;
        let key = objective.fingerprint();
        if let Some((wire, used)) = self.entries.get_mut(&key) {
            *used = self.tick;
            return wire.clone();
        }
        let wire = Arc::new(WireObjective::new(objective));
        self.values += wire.record_values();
        self.entries.insert(key, (wire.clone(), self.tick));
        while self.entries.len() > 1
            && (self.values > WIRE_CACHE_VALUES || self.entries.len() > WIRE_CACHE_ENTRIES)
        {
            let oldest = self
                .entries
                .iter()
                .min_by_key(|(_, (_, used))| *used)
                .map(|(k, _)| *k)
                .expect("not empty");
            self.remove(&oldest);
        }
        wire
    }

    fn remove(&mut self, key: &[u8; 32]) {
        if let Some((wire, _)) = self.entries.remove(key) {
            self.values -= wire.record_values();
        }
    }
}

impl GrpcEvaluator {
    /// Evaluate an objective of several experiments: each experiment's batch sent as its
    /// own (side by side), the answers combined point by point.
    fn evaluate_experiments(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        let parts = self
            .parts
            .lock()
            .expect("parts lock")
            .entry(objective.fingerprint())
            .or_insert_with(|| Arc::new(objective.parts()))
            .clone();
        let answers: Vec<Result<Vec<Evaluation>, Fault>> = std::thread::scope(|scope| {
            let running: Vec<_> = parts
                .iter()
                .map(|part| scope.spawn(move || self.evaluate(part, points)))
                .collect();
            running
                .into_iter()
                .map(|r| r.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
                .collect()
        });
        let mut answers = answers.into_iter().collect::<Result<Vec<_>, Fault>>()?;
        Ok((0..points.len())
            .map(|i| {
                let each = answers
                    .iter_mut()
                    .map(|a| std::mem::replace(&mut a[i], Evaluation::failed(0, String::new())))
                    .collect();
                objective.combine(each)
            })
            .collect())
    }
}

impl Evaluator for GrpcEvaluator {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        if points.is_empty() {
            return Ok(Vec::new());
        }
        if !objective.more.is_empty() {
            return self.evaluate_experiments(objective, points);
        }
        let wire = self.wire(objective);
        self.runtime
            .block_on(dispatch(self.pool.clone(), wire, points.to_vec()))
    }

    fn has_room(&self) -> bool {
        self.pool.has_room()
    }

    /// Drop the wire forms of `objective`, with residuals and without, and of its parts.
    fn release(&self, objective: &Objective) {
        let parts = self
            .parts
            .lock()
            .expect("parts lock")
            .remove(&objective.fingerprint());
        let mut wire = self.wire.lock().expect("wire lock");
        let mut forget = |o: &Objective| {
            wire.remove(&o.fingerprint());
            wire.remove(&o.with_residuals().fingerprint());
        };
        forget(objective);
        for part in parts.iter().flat_map(|p| p.iter()) {
            forget(part);
        }
    }
}

impl Simulator for GrpcEvaluator {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Result<Vec<Outputs>, Fault> {
        if points.is_empty() {
            return Ok(Vec::new());
        }
        // One experiment after another; a point's outputs are those of each in turn.
        let mut outputs: Vec<Outputs> = vec![Ok(Vec::new()); points.len()];
        for part in objective.parts() {
            let wire = Arc::new(WireSimulation::new(&part));
            let answers =
                self.runtime
                    .block_on(dispatch(self.pool.clone(), wire, points.to_vec()))?;
            for (all, answer) in outputs.iter_mut().zip(answers) {
                match (all.as_mut(), answer) {
                    (Ok(series), Ok(more)) => series.extend(more),
                    (Ok(_), Err(why)) => *all = Err(why),
                    (Err(_), _) => {}
                }
            }
        }
        Ok(outputs)
    }
}

/// A kind of work a batch is made of: how one worker is asked for a chunk of points, and
/// what a point answers when it cannot be done.
pub trait Work: Send + Sync + 'static {
    type Answer: Send + 'static;

    /// Most points per slot of a worker in one chunk (see [`WorkerPool::acquire`]).
    const MOST_PER_SLOT: usize;

    /// Ask `client` for `points`: one answer each, in order.
    fn ask(
        self: Arc<Self>,
        client: WorkerClient,
        points: Vec<Vec<f64>>,
        deadline: Duration,
    ) -> impl Future<Output = Result<Vec<Self::Answer>, WorkerError>> + Send;
}

impl Work for WireObjective {
    type Answer = Evaluation;
    /// An answer is a few numbers per point: as large as the worker's speed allows.
    const MOST_PER_SLOT: usize = super::pool::MAX_POINTS_PER_SLOT_FAST;

    async fn ask(
        self: Arc<Self>,
        client: WorkerClient,
        points: Vec<Vec<f64>>,
        deadline: Duration,
    ) -> Result<Vec<Evaluation>, WorkerError> {
        let most = self.points_per_request();
        if points.len() <= most {
            return client.evaluate(&self, points, deadline).await;
        }
        // Answers that would not fit one message (residuals of a long record) come in
        // several, one after another.
        let mut answers = Vec::with_capacity(points.len());
        for part in points.chunks(most) {
            answers.extend(client.evaluate(&self, part.to_vec(), deadline).await?);
        }
        Ok(answers)
    }
}

impl Work for WireSimulation {
    type Answer = Outputs;
    /// An answer is a whole trajectory per point, all requested at once.
    const MOST_PER_SLOT: usize = super::pool::MAX_POINTS_PER_SLOT;

    /// Every point of the chunk at once, one request each: the chunk holds at most as many
    /// points as the worker has slots (twice, with the chunk queued behind it).
    async fn ask(
        self: Arc<Self>,
        client: WorkerClient,
        points: Vec<Vec<f64>>,
        deadline: Duration,
    ) -> Result<Vec<Outputs>, WorkerError> {
        let count = points.len();
        let mut requests = JoinSet::new();
        for (i, point) in points.into_iter().enumerate() {
            let (wire, client) = (self.clone(), client.clone());
            requests.spawn(async move { (i, client.simulate(&wire, &point, deadline).await) });
        }
        let mut answers: Vec<Option<Outputs>> = (0..count).map(|_| None).collect();
        while let Some(joined) = requests.join_next().await {
            let (i, answer) = joined.map_err(|e| WorkerError::Unavailable(e.to_string()))?;
            // The first failure fails the chunk; dropping the set cancels the others.
            answers[i] = Some(answer?);
        }
        Ok(answers
            .into_iter()
            .map(|a| a.expect("every point answered"))
            .collect())
    }
}

/// What one chunk came back with.
struct ChunkOutcome<A> {
    lease: Lease,
    indices: Vec<usize>,
    result: Result<Vec<A>, WorkerError>,
    /// From request to answer.
    took: Duration,
}

/// Do `work` at `points` on the pool's workers, retrying what failed elsewhere. A batch
/// that cannot be done (no worker for `wait_for_workers`, a point that failed on
/// `max_attempts` workers, a request refused as invalid) ends in a [`Fault`]: no answer is
/// made up for its points.
pub async fn dispatch<W: Work>(
    pool: Arc<WorkerPool>,
    work: Arc<W>,
    points: Vec<Vec<f64>>,
) -> Result<Vec<W::Answer>, Fault> {
    let mut batch = Batch::new(pool.clone(), points.len());
    let mut in_flight: JoinSet<ChunkOutcome<W::Answer>> = JoinSet::new();
    let mut idle_since: Option<Instant> = None;
    let points = Arc::new(points);
    while !batch.pending.is_empty() || !in_flight.is_empty() {
        // Listen for pool changes before leasing, so that none is missed in between.
        let changed = pool.notified();
        tokio::pin!(changed);
        changed.as_mut().enable();
        batch.lease(&work, &points, &mut in_flight);
        if in_flight.is_empty() {
            // Points wait and no worker has a free slot: wait for one to come up.
            let since = *idle_since.get_or_insert_with(Instant::now);
            batch.give_up_without_workers(since)?;
            let _ = tokio::time::timeout(batch.config.probe_interval, changed).await;
            continue;
        }
        idle_since = None;
        let outcome = tokio::select! {
            done = in_flight.join_next() => done,
            // Slots freed elsewhere or a worker came up: lease more while chunks run.
            _ = &mut changed, if !batch.pending.is_empty() => None,
        };
        let Some(joined) = outcome else { continue };
        match joined {
            Ok(outcome) => batch.take(outcome),
            // The runtime is shutting down (the coordinator stops): no answer will come.
            Err(e) if e.is_cancelled() => {
                return Err(Fault::unavailable(
                    "dispatch stopped: the coordinator is shutting down",
                ))
            }
            Err(e) => std::panic::resume_unwind(e.into_panic()),
        }
    }
    batch.answers()
}

/// One batch's state while its chunks travel: the answers so far, the points still to
/// lease, the attempts of each and the fault that ended the batch, if one did.
struct Batch<A> {
    pool: Arc<WorkerPool>,
    config: super::DispatchConfig,
    answers: Vec<Option<A>>,
    attempts: Vec<u32>,
    last_error: Vec<Option<String>>,
    pending: VecDeque<usize>,
    /// Once set, nothing more is leased; the chunks in flight are waited for (to give their
    /// slots back) and their answers dropped.
    fault: Option<Fault>,
}

impl<A: Send + 'static> Batch<A> {
    fn new(pool: Arc<WorkerPool>, points: usize) -> Self {
        Self {
            config: pool.config().clone(),
            pool,
            answers: (0..points).map(|_| None).collect(),
            attempts: vec![0; points],
            last_error: vec![None; points],
            pending: (0..points).collect(),
            fault: None,
        }
    }

    /// Lease what the pool's free slots take of the pending points, one chunk per lease.
    fn lease<W: Work<Answer = A>>(
        &mut self,
        work: &Arc<W>,
        points: &Arc<Vec<Vec<f64>>>,
        in_flight: &mut JoinSet<ChunkOutcome<A>>,
    ) {
        for lease in self.pool.acquire(self.pending.len(), W::MOST_PER_SLOT) {
            let indices: Vec<usize> = self.pending.drain(..lease.points).collect();
            let chunk: Vec<Vec<f64>> = indices.iter().map(|&i| points[i].clone()).collect();
            let work = work.clone();
            let deadline = self.config.deadline;
            in_flight.spawn(async move {
                let asked = Instant::now();
                let result = work.ask(lease.client.clone(), chunk, deadline).await;
                ChunkOutcome {
                    lease,
                    indices,
                    result,
                    took: asked.elapsed(),
                }
            });
        }
    }

    /// The fault of a batch that has waited `since` for a worker longer than it may (or
    /// that has no worker to wait for).
    fn give_up_without_workers(&self, since: Instant) -> Result<(), Fault> {
        if since.elapsed() <= self.config.wait_for_workers && self.pool.has_prospects() {
            return Ok(());
        }
        let why = format!(
            "no worker available for {:.0} s",
            since.elapsed().as_secs_f64()
        );
        tracing::error!(points = self.pending.len(), "{why}");
        let last = self
            .pending
            .iter()
            .find_map(|&i| self.last_error[i].clone());
        Err(Fault::unavailable(match last {
            Some(last) => format!("{why}; last failure: {last}"),
            None => why,
        }))
    }

    /// What a chunk came back with: its answers, or its points back in the batch (or the
    /// batch's fault).
    fn take(&mut self, outcome: ChunkOutcome<A>) {
        let ChunkOutcome {
            lease,
            indices,
            result,
            took,
        } = outcome;
        match result {
            Ok(done) => {
                self.pool.release(&lease, indices.len(), took);
                for (i, e) in indices.into_iter().zip(done) {
                    self.answers[i] = Some(e);
                }
            }
            // Asking again, here or elsewhere, gives the same answer: the batch stops.
            Err(error) if !error.is_retryable() => {
                self.pool.release(&lease, 0, took);
                self.refused(&lease, error);
            }
            Err(error) => {
                self.pool.release(&lease, 0, took);
                self.failed(&lease, indices, error);
            }
        }
    }

    /// A worker refused the chunk for good: the batch ends in that fault.
    fn refused(&mut self, lease: &Lease, error: WorkerError) {
        tracing::warn!(worker = %lease.client.url(), %error, "worker refused a request for good");
        let url = lease.client.url();
        self.fault.get_or_insert(Fault::rejected(match error {
            WorkerError::Rejected(reason) => {
                format!("worker {url} rejected the request: {reason}")
            }
            WorkerError::Untrusted(reason) => {
                self.pool.set_aside_untrusted(lease.worker, reason.clone());
                format!("worker {url}: {reason}")
            }
            other => format!("worker {url} rejected the request: {other}"),
        }));
        self.pending.clear();
    }

    /// A chunk's worker failed: it is marked down (or incompatible) and the chunk's points
    /// go back to the front of the batch, unless one has failed `max_attempts` times.
    fn failed(&mut self, lease: &Lease, indices: Vec<usize>, error: WorkerError) {
        match &error {
            WorkerError::Incompatible(reason) => {
                self.pool.mark_incompatible(lease.worker, reason.clone())
            }
            _ => self.pool.mark_down(lease.worker, error.to_string()),
        }
        tracing::debug!(worker = %lease.client.url(), %error, points = indices.len(), "chunk failed, retrying elsewhere");
        for i in indices.into_iter().rev() {
            self.attempts[i] += 1;
            self.last_error[i] = Some(format!("{}: {error}", lease.client.url()));
            if self.attempts[i] >= self.config.max_attempts {
                self.fault.get_or_insert(Fault::unavailable(format!(
                    "gave up after {} attempts, last: {}",
                    self.attempts[i],
                    self.last_error[i].as_deref().unwrap_or_default()
                )));
            } else if self.fault.is_none() {
                self.pending.push_front(i);
            }
        }
        if self.fault.is_some() {
            self.pending.clear();
        }
    }

    /// Every point's answer, or the fault that ended the batch.
    fn answers(self) -> Result<Vec<A>, Fault> {
        if let Some(fault) = self.fault {
            return Err(fault);
        }
        Ok(self
            .answers
            .into_iter()
            .map(|a| a.expect("every point answered"))
            .collect())
    }
}
