//! The evaluator the optimisers talk to: the store first, the simulator for the misses, all
//! through one dispatcher.
//!
//! A dispatcher is one thread that owns every decision about points. [`StoredEvaluator::with`]
//! runs one for the time of its closure (a command's campaign or analysis);
//! [`SharedDispatcher`] runs one for as long as it is kept (a coordinator's), and hands an
//! evaluator to each campaign and analysis: a point one of them has in flight is simulated
//! once for all, and one writer makes every answer durable. The callers (the runs of the
//! campaigns, each asking for a point or two at a time) send it `(objective, points, reply)`
//! and wait for their reply; it looks up what a drained batch of asks needs in one store
//! lookup, keeps the points being simulated in one in-flight map (point → who waits for it)
//! so that a point is simulated once however many runs ask, sends what is missing in rounds
//! to the inner evaluator, has each round's answers written durably, and only then answers.
//!
//! **Rounds.** A round is everything queued when it sets out, one batch per objective, sent
//! side by side by a runner thread ([`ROUNDS`] runners: a second round fills idle workers
//! while the first's answers travel back, and only when the inner evaluator has room for it,
//! [`Evaluator::has_room`]). A round's answers go to the writer thread, which makes them
//! durable with one write while the next round is already under way. A round that arrives
//! with nothing queued keeps its place until its answers are written, so that the callers it
//! answers, asking again one by one, gather into the next round instead of each setting out
//! alone. No timer: a lone caller's points set out at once.
//!
//! **Troubles.** A [`Fault`] of the inner evaluator (no worker, a refused request) answers
//! every ask waiting on the faulted batch's points and stores nothing. A batch answered short
//! is such a fault. A simulation that panics ends the asks that sent its points (the panic
//! resumes in their callers); asks that joined them later send the points again. A store
//! failure does not stop the optimisers (their answers are still right), but the first one is
//! kept and reported by [`StoredEvaluator::error`] of each evaluator whose points it touched.
//!
//! **Counts.** Each evaluator counts its own points ([`StoredEvaluator::stats`]): asked for,
//! and simulated for it. A point two evaluators ask for at once is simulated once and counted
//! by the one that sent it; the other counts it answered without a simulation, as a hit.
//!
//! Each point's answer is the answer for that point alone, so how points are grouped into
//! rounds changes no number.

use super::dispatcher::Dispatcher;
use super::{evaluation_key, EvaluationKey, Store, StoreError};
use crate::evaluator::{CacheStats, Evaluator, Fault};
use crate::objective::{Evaluation, Objective};
use std::any::Any;
use std::collections::HashMap;
use std::panic::AssertUnwindSafe;
use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, Sender, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Rounds under way at once at most: a second fills idle workers while the first's answers
/// travel back.
pub const ROUNDS: usize = 2;

/// A handle on the dispatcher, for the optimisers: [`Evaluator::evaluate`] sends an ask and
/// waits for its reply.
pub struct StoredEvaluator<'d, E: ?Sized> {
    inner: &'d E,
    shared: &'d Shared,
    counts: Arc<Counts>,
    /// The objectives of its asks so far, by fingerprint: an ask carries its objective
    /// without copying it (an objective holds its record). They go with the evaluator, not
    /// with a dispatcher that outlives it.
    objectives: Mutex<HashMap<[u8; 32], Arc<Objective>>>,
    asks: Sender<Message>,
}

/// An evaluator that answers from a store: what it was asked and simulated, and the first
/// store failure met on its points. [`StoredEvaluator`] is one; a wrapper that refuses
/// asks (a cancelled campaign's) passes both on.
pub trait Stored: Evaluator {
    fn stats(&self) -> CacheStats;
    /// The first store failure met, if any (taken).
    fn error(&self) -> Option<StoreError>;
}

impl<E: Evaluator + ?Sized> Stored for StoredEvaluator<'_, E> {
    fn stats(&self) -> CacheStats {
        StoredEvaluator::stats(self)
    }

    fn error(&self) -> Option<StoreError> {
        StoredEvaluator::error(self)
    }
}

impl<S: Stored + ?Sized> Stored for &S {
    fn stats(&self) -> CacheStats {
        (**self).stats()
    }

    fn error(&self) -> Option<StoreError> {
        (**self).error()
    }
}

/// One evaluator's counts, kept by its calls and by the dispatcher, and the first store
/// failure met on its points.
#[derive(Default)]
pub(super) struct Counts {
    requested: AtomicU64,
    simulated: AtomicU64,
    failed: AtomicU64,
    error: Mutex<Option<StoreError>>,
}

impl Counts {
    /// One of its points was simulated (and `failed`, when the simulation failed).
    pub(super) fn simulated(&self, failed: bool) {
        self.simulated.fetch_add(1, Ordering::Relaxed);
        if failed {
            self.failed.fetch_add(1, Ordering::Relaxed);
        }
    }

    pub(super) fn note(&self, error: StoreError) {
        self.error.lock().expect("error lock").get_or_insert(error);
    }
}

/// What the callers and the dispatcher share.
#[derive(Default)]
pub(super) struct Shared {
    /// Points queued for the next round (for tests that wait for a caller to queue).
    pub(super) queued: AtomicUsize,
    /// Asked points waiting on a point another ask sent (for tests).
    pub(super) joined: AtomicUsize,
    /// Asks handed to the dispatcher (for tests that wait for callers to have asked).
    pub(super) sent: AtomicUsize,
}

/// Closes its dispatcher when dropped (also when the closure of
/// [`StoredEvaluator::with`] panics): it ends once nothing is under way.
struct Closer(Sender<Message>);

impl Drop for Closer {
    fn drop(&mut self) {
        let _ = self.0.send(Message::Close);
    }
}

/// The channels between the callers, the dispatcher, its runners and its writer.
struct Channels {
    asks: Sender<Message>,
    messages: Receiver<Message>,
    rounds: Sender<Round>,
    to_run: Mutex<Receiver<Round>>,
    writes: Sender<Write>,
    to_write: Receiver<Write>,
}

impl Channels {
    fn new() -> Self {
        let (asks, messages) = mpsc::channel();
        let (rounds, to_run) = mpsc::channel::<Round>();
        let (writes, to_write) = mpsc::channel::<Write>();
        Channels {
            asks,
            messages,
            rounds,
            to_run: Mutex::new(to_run),
            writes,
            to_write,
        }
    }
}

impl<'d, E: Evaluator> StoredEvaluator<'d, E> {
    /// Run `f` with an evaluator that answers from `store` and simulates the misses with
    /// `inner`: the dispatcher, its runners and its writer live until `f` returns.
    pub fn with<R>(inner: E, store: &dyn Store, f: impl FnOnce(&StoredEvaluator<'_, E>) -> R) -> R {
        let shared = Shared::default();
        let Channels {
            asks,
            messages,
            rounds,
            to_run,
            writes,
            to_write,
        } = Channels::new();
        std::thread::scope(|scope| {
            let (inner, shared, to_run) = (&inner, &shared, &to_run);
            for _ in 0..ROUNDS {
                let back = asks.clone();
                std::thread::Builder::new()
                    .name("calib-round".into())
                    .spawn_scoped(scope, move || run_rounds(inner, to_run, back))
                    .expect("a thread for rounds");
            }
            let back = asks.clone();
            std::thread::Builder::new()
                .name("calib-store-write".into())
                .spawn_scoped(scope, move || write_rounds(store, to_write, back))
                .expect("a thread for store writes");
            std::thread::Builder::new()
                .name("calib-dispatch".into())
                .spawn_scoped(scope, move || {
                    Dispatcher::new(inner, store, shared, rounds, writes).run(messages)
                })
                .expect("a thread for the dispatcher");
            let _closer = Closer(asks.clone());
            f(&StoredEvaluator::new(inner, shared, asks))
        })
    }
}

impl<'d, E: Evaluator + ?Sized> StoredEvaluator<'d, E> {
    fn new(inner: &'d E, shared: &'d Shared, asks: Sender<Message>) -> Self {
        StoredEvaluator {
            inner,
            shared,
            counts: Arc::default(),
            objectives: Mutex::default(),
            asks,
        }
    }
}

impl<E: ?Sized> StoredEvaluator<'_, E> {
    /// `simulated`: points this evaluator had simulated; `cached`: the others.
    pub fn stats(&self) -> CacheStats {
        let requested = self.counts.requested.load(Ordering::Relaxed);
        let simulated = self.counts.simulated.load(Ordering::Relaxed);
        CacheStats {
            requested,
            simulated,
            cached: requested - simulated,
            failed: self.counts.failed.load(Ordering::Relaxed),
        }
    }

    /// The first store failure met on this evaluator's points, if any (taken).
    pub fn error(&self) -> Option<StoreError> {
        self.counts.error.lock().expect("error lock").take()
    }

    /// Points queued for a round not yet sent.
    #[cfg(test)]
    pub(crate) fn rounds_waiting(&self) -> usize {
        self.shared.queued.load(Ordering::SeqCst)
    }

    /// Asked points waiting on a point another ask sent.
    #[cfg(test)]
    pub(crate) fn waiting_on_others(&self) -> usize {
        self.shared.joined.load(Ordering::SeqCst)
    }

    /// Asks handed to the dispatcher so far.
    #[cfg(test)]
    pub(crate) fn asks_sent(&self) -> usize {
        self.shared.sent.load(Ordering::SeqCst)
    }

    fn objective(&self, objective: &Objective) -> Arc<Objective> {
        let mut objectives = self.objectives.lock().expect("objectives lock");
        objectives
            .entry(objective.fingerprint())
            .or_insert_with(|| Arc::new(objective.clone()))
            .clone()
    }
}

/// A dispatcher that lives as long as it is kept, with its runners and its writer: one per
/// coordinator, shared by every campaign and analysis it runs ([`Self::evaluator`]). Dropped,
/// it ends once nothing is under way.
pub struct SharedDispatcher<E: ?Sized> {
    inner: Arc<E>,
    shared: Arc<Shared>,
    asks: Sender<Message>,
    threads: Vec<JoinHandle<()>>,
}

impl<E: Evaluator + ?Sized + 'static> SharedDispatcher<E> {
    /// Start a dispatcher over `store` that simulates the misses with `inner`.
    pub fn start(inner: Arc<E>, store: Arc<dyn Store>) -> Self {
        let shared = Arc::new(Shared::default());
        let Channels {
            asks,
            messages,
            rounds,
            to_run,
            writes,
            to_write,
        } = Channels::new();
        let to_run = Arc::new(to_run);
        let spawn = |name: &str, run: Box<dyn FnOnce() + Send>| {
            std::thread::Builder::new()
                .name(name.into())
                .spawn(run)
                .expect("a thread of the dispatcher")
        };
        let mut threads = Vec::new();
        for _ in 0..ROUNDS {
            let (inner, to_run, back) = (inner.clone(), to_run.clone(), asks.clone());
            let run = move || run_rounds(&*inner, &to_run, back);
            threads.push(spawn("calib-round", Box::new(run)));
        }
        let (writer_store, back) = (store.clone(), asks.clone());
        let write = move || write_rounds(&*writer_store, to_write, back);
        threads.push(spawn("calib-store-write", Box::new(write)));
        let (dispatch_inner, dispatch_shared) = (inner.clone(), shared.clone());
        let dispatch = move || {
            Dispatcher::new(&*dispatch_inner, &*store, &dispatch_shared, rounds, writes)
                .run(messages)
        };
        threads.push(spawn("calib-dispatch", Box::new(dispatch)));
        SharedDispatcher {
            inner,
            shared,
            asks,
            threads,
        }
    }

    /// An evaluator for one campaign or analysis: its own counts, every point through this
    /// dispatcher.
    pub fn evaluator(&self) -> StoredEvaluator<'_, E> {
        StoredEvaluator::new(&self.inner, &self.shared, self.asks.clone())
    }
}

impl<E: ?Sized> Drop for SharedDispatcher<E> {
    fn drop(&mut self) {
        let _ = self.asks.send(Message::Close);
        for thread in self.threads.drain(..) {
            let _ = thread.join();
        }
    }
}

impl<E: Evaluator + ?Sized> Evaluator for StoredEvaluator<'_, E> {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        self.counts
            .requested
            .fetch_add(points.len() as u64, Ordering::Relaxed);
        if points.is_empty() {
            return Ok(Vec::new());
        }
        let keys = points
            .iter()
            .map(|p| evaluation_key(objective, p))
            .collect();
        let (reply, answer) = mpsc::sync_channel(1);
        let ask = Ask {
            objective: self.objective(objective),
            keys,
            points: points.to_vec(),
            counts: self.counts.clone(),
            reply,
        };
        let stopped = || Fault::unavailable("the evaluation dispatcher stopped");
        self.asks.send(Message::Ask(ask)).map_err(|_| stopped())?;
        self.shared.sent.fetch_add(1, Ordering::SeqCst);
        match answer.recv().map_err(|_| stopped())? {
            Reply::Answer(answer) => answer,
            Reply::Panic(payload) => std::panic::resume_unwind(payload),
        }
    }

    fn has_room(&self) -> bool {
        self.inner.has_room()
    }

    fn release(&self, objective: &Objective) {
        self.inner.release(objective)
    }
}

/// One caller's points and where to answer.
pub(super) struct Ask {
    pub(super) objective: Arc<Objective>,
    pub(super) keys: Vec<EvaluationKey>,
    pub(super) points: Vec<Vec<f64>>,
    pub(super) counts: Arc<Counts>,
    pub(super) reply: SyncSender<Reply>,
}

pub(super) enum Reply {
    Answer(Result<Vec<Evaluation>, Fault>),
    /// The simulation of this ask's points panicked: the caller panics too.
    Panic(Box<dyn Any + Send>),
}

/// What the dispatcher hears: asks, and the news of its runners and its writer.
pub(super) enum Message {
    Ask(Ask),
    /// A round's answers, one result per group.
    Arrived {
        round: u64,
        groups: Vec<Result<Vec<Evaluation>, Fault>>,
    },
    Panicked {
        round: u64,
        payload: Box<dyn Any + Send>,
    },
    /// A round's answers are durable, or the store failed to keep them.
    Written {
        round: u64,
        error: Option<StoreError>,
    },
    /// The dispatcher's owner is gone: no more asks.
    Close,
}

/// Points of one objective in a round.
pub(super) struct Group {
    pub(super) objective: Arc<Objective>,
    pub(super) points: Vec<Vec<f64>>,
}

/// A round for a runner: every group sent side by side.
pub(super) struct Round {
    pub(super) id: u64,
    pub(super) groups: Vec<Group>,
}

/// A round's answers for the writer.
pub(super) struct Write {
    pub(super) round: u64,
    pub(super) entries: Vec<(EvaluationKey, Evaluation)>,
}

/// A runner: each round's groups sent side by side, the first on this thread, the others
/// on threads of their own; the answers (or the panic) back to the dispatcher.
fn run_rounds<E: Evaluator + ?Sized>(
    inner: &E,
    rounds: &Mutex<Receiver<Round>>,
    back: Sender<Message>,
) {
    loop {
        let round = match rounds.lock().expect("rounds lock").recv() {
            Ok(round) => round,
            Err(_) => return,
        };
        let id = round.id;
        let run = |g: &Group| inner.evaluate(&g.objective, &g.points);
        let ran = std::panic::catch_unwind(AssertUnwindSafe(|| match round.groups.as_slice() {
            [] => Vec::new(),
            [one] => vec![run(one)],
            [first, rest @ ..] => std::thread::scope(|scope| {
                let others: Vec<_> = rest.iter().map(|g| scope.spawn(move || run(g))).collect();
                let mut results = vec![run(first)];
                for other in others {
                    match other.join() {
                        Ok(result) => results.push(result),
                        Err(panic) => std::panic::resume_unwind(panic),
                    }
                }
                results
            }),
        }));
        let message = match ran {
            Ok(groups) => Message::Arrived { round: id, groups },
            Err(payload) => Message::Panicked { round: id, payload },
        };
        if back.send(message).is_err() {
            return;
        }
    }
}

/// The writer: each round's answers made durable with one write, then reported.
fn write_rounds(store: &dyn Store, writes: Receiver<Write>, back: Sender<Message>) {
    for write in writes {
        let error = store.put_evaluations(&write.entries).err();
        if let Some(e) = &error {
            tracing::error!(error = %e, "evaluation store failed");
        }
        let written = Message::Written {
            round: write.round,
            error,
        };
        if back.send(written).is_err() {
            return;
        }
    }
}
