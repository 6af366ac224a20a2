//! The dispatcher of [`super::StoredEvaluator`]: every decision about points, on one thread
//! (see the [evaluator's module](super::evaluator) for what it does and why).

use super::evaluator::{Ask, Counts, Group, Message, Reply, Round, Shared, Write, ROUNDS};
use super::{EvaluationKey, Store, StoreError};
use crate::evaluator::{Evaluator, Fault};
use crate::objective::{Evaluation, Objective};
use std::any::Any;
use std::collections::HashMap;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, Sender, SyncSender};
use std::sync::Arc;

/// A point a drained batch of asks looks up: who asks for it (ask, position), its objective
/// and the point.
type Looked = (Vec<(u64, usize)>, Arc<Objective>, Vec<f64>);

/// A point being simulated: the round it went in, who waits for it (ask, position), the
/// first being the ask that sent it, and the counts of the evaluator that sent it (its
/// simulation is counted there, whichever campaigns it answers).
struct Flight {
    objective: Arc<Objective>,
    point: Vec<f64>,
    waiters: Vec<(u64, usize)>,
    counts: Arc<Counts>,
    /// The round it went in, once sent.
    round: Option<u64>,
    /// Its answer, once arrived and until written.
    answer: Option<Evaluation>,
}

/// An ask not yet answered.
struct Pending {
    answers: Vec<Option<Evaluation>>,
    missing: usize,
    /// Of its points, those it sent and were simulated: the rest were hits.
    simulated: u64,
    /// The counts of the evaluator that asked.
    counts: Arc<Counts>,
    reply: SyncSender<Reply>,
}

/// A round under way: its points by group, and whether it holds a place while written.
struct Travelling {
    keys: Vec<Vec<EvaluationKey>>,
    holds_place: bool,
}

/// The dispatcher's state: everything about points lives here, on one thread.
pub(super) struct Dispatcher<'d, E: ?Sized> {
    inner: &'d E,
    store: &'d dyn Store,
    shared: &'d Shared,
    rounds: Sender<Round>,
    writes: Sender<Write>,
    pending: HashMap<u64, Pending>,
    in_flight: HashMap<EvaluationKey, Flight>,
    /// Keys to send in the next round, in order of asking.
    queue: Vec<EvaluationKey>,
    travelling: HashMap<u64, Travelling>,
    /// Rounds travelling, and arrived ones that keep their place until written.
    places: usize,
    /// Asks whose points are all answered, to reply to.
    done: Vec<u64>,
    next_ask: u64,
    next_round: u64,
    closing: bool,
}

impl<'d, E: Evaluator + ?Sized> Dispatcher<'d, E> {
    pub(super) fn new(
        inner: &'d E,
        store: &'d dyn Store,
        shared: &'d Shared,
        rounds: Sender<Round>,
        writes: Sender<Write>,
    ) -> Self {
        Self {
            inner,
            store,
            shared,
            rounds,
            writes,
            pending: HashMap::new(),
            in_flight: HashMap::new(),
            queue: Vec::new(),
            travelling: HashMap::new(),
            places: 0,
            done: Vec::new(),
            next_ask: 0,
            next_round: 0,
            closing: false,
        }
    }

    /// Serve until the handle is gone and nothing is under way: every message waiting is
    /// taken before a round sets out, so that asks arriving together go together.
    pub(super) fn run(mut self, messages: Receiver<Message>) {
        while !(self.closing && self.travelling.is_empty()) {
            let Ok(first) = messages.recv() else { return };
            let mut asks = Vec::new();
            for message in std::iter::once(first).chain(messages.try_iter()) {
                match message {
                    Message::Ask(ask) => asks.push(ask),
                    Message::Arrived { round, groups } => self.arrived(round, groups),
                    Message::Panicked { round, payload } => self.panicked(round, payload),
                    Message::Written { round, error } => self.written(round, error),
                    Message::Close => self.closing = true,
                }
            }
            if !asks.is_empty() {
                self.take_asks(asks);
            }
            self.send_round();
        }
    }

    /// Register asks: points already in flight join their flight; the others are looked up
    /// in the store with one lookup, and what it lacks is queued.
    fn take_asks(&mut self, asks: Vec<Ask>) {
        let mut lookup: Vec<EvaluationKey> = Vec::new();
        // Per key looked up: the asks' positions, the objective and the point.
        let mut looked: HashMap<EvaluationKey, Looked> = HashMap::new();
        let mut askers: Vec<Arc<Counts>> = Vec::new();
        for ask in asks {
            let id = self.next_ask;
            self.next_ask += 1;
            let Ask {
                objective,
                keys,
                points,
                counts,
                reply,
            } = ask;
            askers.push(counts.clone());
            self.pending.insert(
                id,
                Pending {
                    answers: vec![None; keys.len()],
                    missing: keys.len(),
                    simulated: 0,
                    counts,
                    reply,
                },
            );
            for (position, (key, point)) in keys.into_iter().zip(points).enumerate() {
                if let Some(flight) = self.in_flight.get_mut(&key) {
                    flight.waiters.push((id, position));
                    self.shared.joined.fetch_add(1, Ordering::SeqCst);
                    continue;
                }
                looked
                    .entry(key)
                    .or_insert_with(|| {
                        lookup.push(key);
                        (Vec::new(), objective.clone(), point)
                    })
                    .0
                    .push((id, position));
            }
        }
        let found = self.store.get_evaluations(&lookup).unwrap_or_else(|e| {
            tracing::error!(error = %e, "evaluation store failed");
            for counts in &askers {
                counts.note(e.clone());
            }
            vec![None; lookup.len()]
        });
        for (key, found) in lookup.into_iter().zip(found) {
            let (waiters, objective, point) = looked.remove(&key).expect("each key looked up");
            match found {
                Some(evaluation) => {
                    for (id, position) in waiters {
                        self.answer(id, position, &evaluation);
                    }
                }
                None => {
                    let counts = self.pending[&waiters[0].0].counts.clone();
                    self.queue_flight(key, objective, point, waiters, counts);
                }
            }
        }
        self.finish_answered();
    }

    /// Queue `point` for the next round, `waiters` (at least one) waiting on it, the first
    /// the ask that sends it (whose evaluator's `counts` count its simulation).
    fn queue_flight(
        &mut self,
        key: EvaluationKey,
        objective: Arc<Objective>,
        point: Vec<f64>,
        waiters: Vec<(u64, usize)>,
        counts: Arc<Counts>,
    ) {
        self.shared
            .joined
            .fetch_add(waiters.len() - 1, Ordering::SeqCst);
        self.in_flight.insert(
            key,
            Flight {
                objective,
                point,
                waiters,
                counts,
                round: None,
                answer: None,
            },
        );
        self.queue.push(key);
        self.shared.queued.fetch_add(1, Ordering::SeqCst);
    }

    /// Send everything queued as one round, when a place is free: at once when nothing
    /// travels, a second round only when the inner evaluator has room for it.
    fn send_round(&mut self) {
        if self.queue.is_empty()
            || !(self.places == 0 || (self.places < ROUNDS && self.inner.has_room()))
        {
            return;
        }
        let queue = std::mem::take(&mut self.queue);
        self.shared.queued.fetch_sub(queue.len(), Ordering::SeqCst);
        // One group per objective, in order of first appearance.
        let mut groups: Vec<Group> = Vec::new();
        let mut keys: Vec<Vec<EvaluationKey>> = Vec::new();
        let id = self.next_round;
        self.next_round += 1;
        for key in queue {
            let Some(flight) = self.in_flight.get_mut(&key) else {
                continue;
            };
            flight.round = Some(id);
            let fingerprint = flight.objective.fingerprint();
            let g = match groups
                .iter()
                .position(|g| g.objective.fingerprint() == fingerprint)
            {
                Some(g) => g,
                None => {
                    groups.push(Group {
                        objective: flight.objective.clone(),
                        points: Vec::new(),
                    });
                    keys.push(Vec::new());
                    groups.len() - 1
                }
            };
            keys[g].push(key);
            groups[g].points.push(flight.point.clone());
        }
        tracing::trace!(
            round = id,
            points = groups.iter().map(|g| g.points.len()).sum::<usize>(),
            "round"
        );
        self.travelling.insert(
            id,
            Travelling {
                keys,
                holds_place: true,
            },
        );
        self.places += 1;
        if self.rounds.send(Round { id, groups }).is_err() {
            // The runners are gone (the scope is ending): nothing will answer.
            let keys = self.travelling.remove(&id).expect("just inserted").keys;
            self.places -= 1;
            let fault = Fault::unavailable("the evaluation dispatcher stopped");
            for key in keys.into_iter().flatten() {
                self.fail_flight(&key, id, &fault);
            }
        }
    }

    /// A round's answers: faulted groups answer their asks with the fault; the others go to
    /// the writer, and are answered once written. The round's place goes to the next round
    /// when points wait, else it is kept until the write is done.
    fn arrived(&mut self, round: u64, results: Vec<Result<Vec<Evaluation>, Fault>>) {
        let keys = self.travelling[&round].keys.clone();
        let mut entries = Vec::new();
        for (keys, result) in keys.iter().zip(results) {
            let result = result.and_then(|evaluations| {
                if evaluations.len() == keys.len() {
                    Ok(evaluations)
                } else {
                    Err(Fault::unavailable(format!(
                        "{} answers for {} points",
                        evaluations.len(),
                        keys.len()
                    )))
                }
            });
            match result {
                Ok(evaluations) => {
                    let failed = evaluations.iter().filter(|e| e.failure.is_some()).count();
                    if failed > 0 {
                        let first = evaluations.iter().find_map(|e| e.failure.as_ref());
                        tracing::info!(failed, first = ?first, "simulations failed");
                    }
                    for (key, evaluation) in keys.iter().zip(evaluations) {
                        if let Some(flight) = self.in_flight.get_mut(key) {
                            if flight.round == Some(round) {
                                flight.counts.simulated(evaluation.failure.is_some());
                                flight.answer = Some(evaluation.clone());
                            }
                        }
                        entries.push((*key, evaluation));
                    }
                }
                Err(fault) => {
                    for key in keys {
                        self.fail_flight(key, round, &fault);
                    }
                }
            }
        }
        self.finish_answered();
        let travelling = self.travelling.get_mut(&round).expect("a round under way");
        if !self.queue.is_empty() {
            travelling.holds_place = false;
            self.places -= 1;
        }
        // Nothing to write (or no writer left): published at once.
        if entries.is_empty() || self.writes.send(Write { round, entries }).is_err() {
            self.written(round, None);
        }
    }

    /// A round's answers are durable (or the store failed to keep them, `error`, which the
    /// evaluators that sent them are told): publish them, and free the round's place.
    fn written(&mut self, round: u64, error: Option<StoreError>) {
        let Some(travelling) = self.travelling.remove(&round) else {
            return;
        };
        if travelling.holds_place {
            self.places -= 1;
        }
        let mut simulated = 0;
        for key in travelling.keys.iter().flatten() {
            let Some(flight) = self.land(key, round) else {
                continue;
            };
            if let Some(e) = &error {
                flight.counts.note(e.clone());
            }
            let Some(answer) = flight.answer else {
                continue;
            };
            simulated += 1;
            if let Some(sender) = self.pending.get_mut(&flight.waiters[0].0) {
                sender.simulated += 1;
            }
            for (id, position) in flight.waiters {
                self.answer(id, position, &answer);
            }
        }
        self.store.count_lookups(0, simulated);
        self.finish_answered();
    }

    /// A round's simulation panicked: the asks that sent its points panic too; asks that
    /// joined them send them again.
    fn panicked(&mut self, round: u64, payload: Box<dyn Any + Send>) {
        let Some(travelling) = self.travelling.remove(&round) else {
            return;
        };
        if travelling.holds_place {
            self.places -= 1;
        }
        let mut payload = Some(payload);
        for key in travelling.keys.into_iter().flatten() {
            let Some(flight) = self.land(&key, round) else {
                continue;
            };
            let sender = flight.waiters[0].0;
            if let Some(pending) = self.pending.remove(&sender) {
                let payload = payload.take().unwrap_or_else(|| {
                    Box::new("the simulation of this batch panicked".to_string())
                });
                let _ = pending.reply.send(Reply::Panic(payload));
            }
            let others: Vec<(u64, usize)> = flight
                .waiters
                .into_iter()
                .filter(|(id, _)| self.pending.contains_key(id))
                .collect();
            if !others.is_empty() {
                let counts = self.pending[&others[0].0].counts.clone();
                self.queue_flight(key, flight.objective, flight.point, others, counts);
            }
        }
    }

    /// The flight of `key` sent in `round`, taken out of the in-flight map (none when the
    /// key's flight is of another round: this one's was failed and the key asked again).
    fn land(&mut self, key: &EvaluationKey, round: u64) -> Option<Flight> {
        if self.in_flight.get(key)?.round != Some(round) {
            return None;
        }
        let flight = self.in_flight.remove(key)?;
        self.shared
            .joined
            .fetch_sub(flight.waiters.len() - 1, Ordering::SeqCst);
        Some(flight)
    }

    /// A point of `round` that has no answer (its batch faulted): every ask waiting on it
    /// gets the fault.
    fn fail_flight(&mut self, key: &EvaluationKey, round: u64, fault: &Fault) {
        let Some(flight) = self.land(key, round) else {
            return;
        };
        for (id, _) in flight.waiters {
            if let Some(pending) = self.pending.remove(&id) {
                let _ = pending.reply.send(Reply::Answer(Err(fault.clone())));
            }
        }
    }

    fn answer(&mut self, id: u64, position: usize, evaluation: &Evaluation) {
        if let Some(pending) = self.pending.get_mut(&id) {
            if pending.answers[position].is_none() {
                pending.answers[position] = Some(evaluation.clone());
                pending.missing -= 1;
                if pending.missing == 0 {
                    self.done.push(id);
                }
            }
        }
    }

    /// Reply to every ask whose points are all answered.
    fn finish_answered(&mut self) {
        for id in std::mem::take(&mut self.done) {
            let Some(pending) = self.pending.remove(&id) else {
                continue;
            };
            let points = pending.answers.len() as u64;
            self.store.count_lookups(points - pending.simulated, 0);
            let answers = pending
                .answers
                .into_iter()
                .map(|a| a.expect("every point answered"))
                .collect();
            let _ = pending.reply.send(Reply::Answer(Ok(answers)));
        }
    }
}
