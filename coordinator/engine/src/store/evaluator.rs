//! The evaluator the optimisers talk to: the store first, the simulator for the misses.

use super::{evaluation_key, EvaluationKey, Store, StoreError};
use crate::coalesce::{Answers, Arrival, Coalescer, Groups};
use crate::evaluator::{CacheStats, Evaluator, Fault};
use crate::objective::{Evaluation, Objective};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};

/// Answers each point from the store when it is there; simulates the others with the inner
/// evaluator, stores them durably, and only then answers. A point that another thread is
/// already simulating is waited for, not simulated again, so concurrent runs that ask for
/// the same point share one simulation. The missing points of concurrent callers go
/// together in rounds ([`crate::coalesce`]): one batch per objective to the inner evaluator,
/// one write and one flush to the store for all of them.
///
/// A store failure does not stop the optimisers (their answers are still right), but the
/// first one is kept and reported by [`StoredEvaluator::error`].
pub struct StoredEvaluator<'s, E> {
    inner: E,
    store: &'s dyn Store,
    in_flight: Mutex<HashMap<EvaluationKey, Arc<Slot>>>,
    /// Concurrent callers' missing points, resolved together: one claim, one lookup, one
    /// durable write per round.
    rounds: Coalescer<[u8; 32], Missing>,
    /// The objectives of the callers so far, by fingerprint (a round's leader simulates
    /// others' points with them).
    objectives: Mutex<HashMap<[u8; 32], Arc<Objective>>>,
    /// Releases of claimed keys with stored outcomes so far: a key claimed while this has
    /// not moved since its caller looked it up cannot have been stored by this evaluator
    /// meanwhile, so it is not looked up again.
    releases: AtomicU64,
    requested: AtomicU64,
    simulated: AtomicU64,
    failed: AtomicU64,
    error: Mutex<Option<StoreError>>,
}

/// What a claim of keys (by position) found.
struct Claim {
    /// Claimed: no one else simulates them until they are released.
    mine: Vec<usize>,
    /// Being simulated by another thread: their slots, to wait on.
    theirs: Vec<(usize, Arc<Slot>)>,
    /// [`StoredEvaluator::releases`] at the claim.
    releases: u64,
}

/// A point its caller found missing from the store, and [`StoredEvaluator::releases`] just
/// before that lookup.
struct Missing {
    key: EvaluationKey,
    point: Vec<f64>,
    looked: u64,
}

/// A point being simulated by some thread.
#[derive(Default)]
struct Slot {
    outcome: Mutex<SlotState>,
    ready: Condvar,
}

#[derive(Default)]
enum SlotState {
    #[default]
    Pending,
    Done(Evaluation),
    /// The simulating thread gave up (it panicked): whoever waits simulates it.
    Abandoned,
}

impl<'s, E: Evaluator> StoredEvaluator<'s, E> {
    pub fn new(inner: E, store: &'s dyn Store) -> Self {
        Self {
            inner,
            store,
            in_flight: Mutex::new(HashMap::new()),
            rounds: Coalescer::default(),
            objectives: Mutex::new(HashMap::new()),
            releases: AtomicU64::new(0),
            requested: AtomicU64::new(0),
            simulated: AtomicU64::new(0),
            failed: AtomicU64::new(0),
            error: Mutex::new(None),
        }
    }

    /// `simulated`: points this evaluator had simulated; `cached`: the others.
    pub fn stats(&self) -> CacheStats {
        let requested = self.requested.load(Ordering::Relaxed);
        let simulated = self.simulated.load(Ordering::Relaxed);
        CacheStats {
            requested,
            simulated,
            cached: requested - simulated,
            failed: self.failed.load(Ordering::Relaxed),
        }
    }

    /// The first store failure met, if any (taken).
    pub fn error(&self) -> Option<StoreError> {
        self.error.lock().expect("error lock").take()
    }

    /// Callers waiting for a round.
    #[cfg(test)]
    pub(crate) fn rounds_waiting(&self) -> usize {
        self.rounds.waiting()
    }

    /// Callers waiting on points another caller simulates.
    #[cfg(test)]
    pub(crate) fn waiting_on_others(&self) -> usize {
        let in_flight = self.in_flight.lock().expect("in-flight lock");
        // The map holds one reference to a slot; every waiter holds another.
        in_flight.values().map(|s| Arc::strong_count(s) - 1).sum()
    }

    fn note(&self, error: StoreError) {
        tracing::error!(error = %error, "evaluation store failed");
        self.error.lock().expect("error lock").get_or_insert(error);
    }

    fn lookup(&self, keys: &[EvaluationKey]) -> Vec<Option<Evaluation>> {
        self.store.get_evaluations(keys).unwrap_or_else(|e| {
            self.note(e);
            vec![None; keys.len()]
        })
    }

    /// Claim the keys nobody is simulating; the others' slots are returned to wait on.
    fn claim(&self, keys: &[EvaluationKey]) -> Claim {
        let mut in_flight = self.in_flight.lock().expect("in-flight lock");
        let releases = self.releases.load(Ordering::SeqCst);
        let mut mine = Vec::new();
        let mut theirs = Vec::new();
        for (i, key) in keys.iter().enumerate() {
            match in_flight.get(key) {
                Some(slot) => theirs.push((i, slot.clone())),
                None => {
                    in_flight.insert(*key, Arc::new(Slot::default()));
                    mine.push(i);
                }
            }
        }
        Claim {
            mine,
            theirs,
            releases,
        }
    }

    /// Publish the outcome of claimed keys (`None`: abandoned) and release them.
    fn release(&self, keys: &[EvaluationKey], outcomes: &[Option<Evaluation>]) {
        let mut in_flight = self.in_flight.lock().expect("in-flight lock");
        if outcomes.iter().any(Option::is_some) {
            self.releases.fetch_add(1, Ordering::SeqCst);
        }
        for (key, outcome) in keys.iter().zip(outcomes) {
            if let Some(slot) = in_flight.remove(key) {
                *slot.outcome.lock().expect("slot lock") = match outcome {
                    Some(e) => SlotState::Done(e.clone()),
                    None => SlotState::Abandoned,
                };
                slot.ready.notify_all();
            }
        }
    }

    /// The objective of a fingerprint met before (every caller remembers its own before it
    /// joins a round).
    fn objective_of(&self, fingerprint: &[u8; 32]) -> Arc<Objective> {
        self.objectives
            .lock()
            .expect("objectives lock")
            .get(fingerprint)
            .cloned()
            .expect("each caller remembers its objective before its round")
    }

    fn remember(&self, objective: &Objective) {
        self.objectives
            .lock()
            .expect("objectives lock")
            .entry(objective.fingerprint())
            .or_insert_with(|| Arc::new(objective.clone()));
    }

    /// One round of many callers' missing points (one group per objective): claimed
    /// together, looked up again, simulated group by group side by side, written together
    /// and made durable by one flush, then published. The round has arrived once its
    /// simulations are answered: a round waiting for it sets out while this one's write is
    /// made durable. Keys another thread is simulating are waited for; keys it abandons are
    /// tried again (then beside the rounds under way: only after a simulation panicked).
    fn resolve_round(&self, groups: Groups<[u8; 32], Missing>, arrival: &Arrival) -> Answers {
        let groups: Vec<RoundGroup> = groups
            .into_iter()
            .map(|(fingerprint, points)| RoundGroup::new(self.objective_of(&fingerprint), points))
            .collect();
        let mut answers: Vec<Vec<Option<Evaluation>>> =
            groups.iter().map(|g| vec![None; g.keys.len()]).collect();
        let mut faults: Vec<Option<Fault>> = vec![None; groups.len()];
        let mut simulated: Vec<u64> = vec![0; groups.len()];
        // Open (group, distinct key index) pairs.
        let mut open: Vec<(usize, usize)> = groups
            .iter()
            .enumerate()
            .flat_map(|(g, group)| (0..group.keys.len()).map(move |k| (g, k)))
            .collect();
        while !open.is_empty() {
            let open_keys: Vec<EvaluationKey> =
                open.iter().map(|&(g, k)| groups[g].keys[k]).collect();
            let Claim {
                mine,
                theirs,
                releases,
            } = self.claim(&open_keys);
            let mine: Vec<(usize, usize)> = mine.into_iter().map(|j| open[j]).collect();
            let mut retry = Vec::new();
            if !mine.is_empty() {
                let my_keys: Vec<EvaluationKey> =
                    mine.iter().map(|&(g, k)| groups[g].keys[k]).collect();
                let guard = ReleaseOnPanic {
                    evaluator: self,
                    keys: &my_keys,
                    armed: true,
                };
                // Another round may have stored some between their callers' lookups and
                // this claim: only then are they looked up again. (Writes of other
                // evaluators on the same store are not seen here; at worst such a point is
                // simulated again, with the same answer.)
                let stale: Vec<usize> = (0..mine.len())
                    .filter(|&j| {
                        let (g, k) = mine[j];
                        groups[g].looked[k] != releases
                    })
                    .collect();
                let mut outcomes: Vec<Option<Evaluation>> = vec![None; mine.len()];
                if !stale.is_empty() {
                    let keys: Vec<EvaluationKey> = stale.iter().map(|&j| my_keys[j]).collect();
                    for (j, found) in stale.into_iter().zip(self.lookup(&keys)) {
                        outcomes[j] = found;
                    }
                }
                // Per group, the positions in `mine` still to simulate.
                let mut to_simulate: Vec<Vec<usize>> = vec![Vec::new(); groups.len()];
                for (j, &(g, _)) in mine.iter().enumerate() {
                    if outcomes[j].is_none() {
                        to_simulate[g].push(j);
                    }
                }
                let batches: Vec<(usize, Vec<Vec<f64>>)> = to_simulate
                    .iter()
                    .enumerate()
                    .filter(|(_, js)| !js.is_empty())
                    .map(|(g, js)| {
                        let points = js
                            .iter()
                            .map(|&j| groups[g].points[mine[j].1].clone())
                            .collect();
                        (g, points)
                    })
                    .collect();
                let fresh = self.simulate_side_by_side(&groups, &batches);
                arrival.arrived();
                let mut entries: Vec<(EvaluationKey, Evaluation)> = Vec::new();
                for ((g, _), result) in batches.iter().zip(fresh) {
                    let wanted = to_simulate[*g].len();
                    let result = result.and_then(|evaluations| {
                        if evaluations.len() == wanted {
                            Ok(evaluations)
                        } else {
                            Err(Fault::unavailable(format!(
                                "{} answers for {wanted} points",
                                evaluations.len()
                            )))
                        }
                    });
                    match result {
                        Ok(evaluations) => {
                            let failed = evaluations.iter().filter(|e| e.failure.is_some());
                            let failed = failed.count() as u64;
                            if failed > 0 {
                                let first = evaluations.iter().find_map(|e| e.failure.as_ref());
                                tracing::info!(failed, first = ?first, "simulations failed");
                                self.failed.fetch_add(failed, Ordering::Relaxed);
                            }
                            let n = evaluations.len() as u64;
                            self.simulated.fetch_add(n, Ordering::Relaxed);
                            simulated[*g] += n;
                            for (&j, e) in to_simulate[*g].iter().zip(evaluations) {
                                entries.push((my_keys[j], e.clone()));
                                outcomes[j] = Some(e);
                            }
                        }
                        Err(fault) => faults[*g] = Some(fault),
                    }
                }
                if !entries.is_empty() {
                    if let Err(e) = self.store.put_evaluations(&entries) {
                        self.note(e);
                    }
                }
                // A faulted group stores nothing: its claimed keys are abandoned (whoever
                // waits on them tries for itself).
                guard.disarm();
                self.release(&my_keys, &outcomes);
                for (&(g, k), outcome) in mine.iter().zip(outcomes) {
                    answers[g][k] = outcome;
                }
            }
            for (j, slot) in theirs {
                let (g, k) = open[j];
                if faults[g].is_some() {
                    continue;
                }
                let mut state = slot.outcome.lock().expect("slot lock");
                while matches!(*state, SlotState::Pending) {
                    state = slot.ready.wait(state).expect("slot lock");
                }
                match &*state {
                    SlotState::Done(e) => answers[g][k] = Some(e.clone()),
                    _ => retry.push((g, k)),
                }
            }
            open = retry
                .into_iter()
                .filter(|&(g, _)| faults[g].is_none())
                .collect();
        }
        // Every point asked of an answered group that this round did not simulate came from
        // the store or from another thread's simulation.
        let hits: u64 = groups
            .iter()
            .zip(&simulated)
            .zip(&faults)
            .filter(|(_, fault)| fault.is_none())
            .map(|((group, n), _)| group.distinct.len() as u64 - n)
            .sum();
        self.store.count_lookups(hits, simulated.iter().sum());
        groups
            .iter()
            .zip(answers)
            .zip(faults)
            .map(|((group, answers), fault)| match fault {
                Some(fault) => Err(fault),
                None => Ok(group
                    .distinct
                    .iter()
                    .map(|&k| answers[k].clone().expect("every point answered"))
                    .collect()),
            })
            .collect()
    }

    /// Each batch (a group's points) simulated with its group's objective; more than one
    /// at once, each from its own thread, so that they travel side by side.
    fn simulate_side_by_side(
        &self,
        groups: &[RoundGroup],
        batches: &[(usize, Vec<Vec<f64>>)],
    ) -> Vec<Result<Vec<Evaluation>, Fault>> {
        let run = |(g, points): &(usize, Vec<Vec<f64>>)| {
            self.inner.evaluate(&groups[*g].objective, points)
        };
        match batches {
            [] => Vec::new(),
            [one] => vec![run(one)],
            [first, rest @ ..] => std::thread::scope(|scope| {
                let others: Vec<_> = rest.iter().map(|b| scope.spawn(move || run(b))).collect();
                let mut results = vec![run(first)];
                for other in others {
                    match other.join() {
                        Ok(result) => results.push(result),
                        Err(panic) => std::panic::resume_unwind(panic),
                    }
                }
                results
            }),
        }
    }
}

/// One objective's points in a round: their distinct keys, and for each point which.
struct RoundGroup {
    objective: Arc<Objective>,
    /// Distinct keys, each with the first point that has it and the earliest
    /// [`StoredEvaluator::releases`] its callers looked it up at.
    keys: Vec<EvaluationKey>,
    points: Vec<Vec<f64>>,
    looked: Vec<u64>,
    /// For each point of the round, the index of its key in `keys`.
    distinct: Vec<usize>,
}

impl RoundGroup {
    fn new(objective: Arc<Objective>, asked: Vec<Missing>) -> Self {
        let mut index: HashMap<EvaluationKey, usize> = HashMap::with_capacity(asked.len());
        let mut keys = Vec::new();
        let mut points = Vec::new();
        let mut looked: Vec<u64> = Vec::new();
        let distinct = asked
            .into_iter()
            .map(|missing| {
                let k = *index.entry(missing.key).or_insert_with(|| {
                    keys.push(missing.key);
                    points.push(missing.point);
                    looked.push(missing.looked);
                    keys.len() - 1
                });
                looked[k] = looked[k].min(missing.looked);
                k
            })
            .collect();
        Self {
            objective,
            keys,
            points,
            looked,
            distinct,
        }
    }
}

/// Marks claimed keys abandoned if the thread unwinds or returns a fault before publishing
/// them, so that no other run waits forever.
struct ReleaseOnPanic<'a, 's, E: Evaluator> {
    evaluator: &'a StoredEvaluator<'s, E>,
    keys: &'a [EvaluationKey],
    armed: bool,
}

impl<E: Evaluator> ReleaseOnPanic<'_, '_, E> {
    fn disarm(mut self) {
        self.armed = false;
    }
}

impl<E: Evaluator> Drop for ReleaseOnPanic<'_, '_, E> {
    fn drop(&mut self) {
        if self.armed {
            let abandoned = vec![None; self.keys.len()];
            self.evaluator.release(self.keys, &abandoned);
        }
    }
}

impl<E: Evaluator> Evaluator for StoredEvaluator<'_, E> {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        self.requested
            .fetch_add(points.len() as u64, Ordering::Relaxed);
        let keys: Vec<EvaluationKey> = points
            .iter()
            .map(|p| evaluation_key(objective, p))
            .collect();
        let looked = self.releases.load(Ordering::SeqCst);
        let mut answers = self.lookup(&keys);
        let missing: Vec<usize> = (0..points.len())
            .filter(|&i| answers[i].is_none())
            .collect();
        if !missing.is_empty() {
            self.remember(objective);
            let asked: Vec<Missing> = missing
                .iter()
                .map(|&i| Missing {
                    key: keys[i],
                    point: points[i].clone(),
                    looked,
                })
                .collect();
            let resolved = self.rounds.evaluate(
                objective.fingerprint(),
                asked,
                self.inner.has_room(),
                |groups, arrival| self.resolve_round(groups, arrival),
            )?;
            for (i, evaluation) in missing.iter().zip(resolved) {
                answers[*i] = Some(evaluation);
            }
        }
        // Hits of the first look, once the batch is answered; the round counted its own.
        self.store
            .count_lookups((points.len() - missing.len()) as u64, 0);
        Ok(answers
            .into_iter()
            .map(|a| a.expect("every point answered"))
            .collect())
    }

    fn has_room(&self) -> bool {
        self.inner.has_room()
    }
}
