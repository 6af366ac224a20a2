//! The evaluator the optimisers talk to: the store first, the simulator for the misses.

use super::{evaluation_key, EvaluationKey, Store, StoreError};
use crate::evaluator::{CacheStats, Evaluator, Fault};
use crate::objective::{Evaluation, Objective};
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};

/// Answers each point from the store when it is there; simulates the others with the inner
/// evaluator, stores them durably, and only then answers. A point that another thread is
/// already simulating is waited for, not simulated again, so concurrent runs that ask for
/// the same point share one simulation.
///
/// A store failure does not stop the optimisers (their answers are still right), but the
/// first one is kept and reported by [`StoredEvaluator::error`].
pub struct StoredEvaluator<'s, E> {
    inner: E,
    store: &'s dyn Store,
    in_flight: Mutex<HashMap<EvaluationKey, Arc<Slot>>>,
    requested: AtomicU64,
    simulated: AtomicU64,
    failed: AtomicU64,
    error: Mutex<Option<StoreError>>,
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
    fn claim(&self, keys: &[EvaluationKey]) -> (Vec<usize>, Vec<(usize, Arc<Slot>)>) {
        let mut in_flight = self.in_flight.lock().expect("in-flight lock");
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
        (mine, theirs)
    }

    /// Publish the outcome of claimed keys (`None`: abandoned) and release them.
    fn release(&self, keys: &[EvaluationKey], outcomes: Option<&[Evaluation]>) {
        let mut in_flight = self.in_flight.lock().expect("in-flight lock");
        for (i, key) in keys.iter().enumerate() {
            if let Some(slot) = in_flight.remove(key) {
                *slot.outcome.lock().expect("slot lock") = match outcomes {
                    Some(o) => SlotState::Done(o[i].clone()),
                    None => SlotState::Abandoned,
                };
                slot.ready.notify_all();
            }
        }
    }

    /// Evaluate distinct keys absent from the store at the last look. A fault of the inner
    /// evaluator stores nothing: the claimed keys are abandoned (whoever waits on them tries
    /// for itself) and the fault returned.
    fn resolve_missing(
        &self,
        objective: &Objective,
        keys: &[EvaluationKey],
        points: &[&Vec<f64>],
    ) -> Result<(Vec<Evaluation>, u64), Fault> {
        let mut simulated_here = 0;
        let mut answers: Vec<Option<Evaluation>> = vec![None; keys.len()];
        let mut open: Vec<usize> = (0..keys.len()).collect();
        while !open.is_empty() {
            let open_keys: Vec<EvaluationKey> = open.iter().map(|&i| keys[i]).collect();
            let (mine, theirs) = self.claim(&open_keys);
            let mine: Vec<usize> = mine.into_iter().map(|j| open[j]).collect();
            let theirs: Vec<(usize, Arc<Slot>)> =
                theirs.into_iter().map(|(j, s)| (open[j], s)).collect();
            let mut retry = Vec::new();
            if !mine.is_empty() {
                let my_keys: Vec<EvaluationKey> = mine.iter().map(|&i| keys[i]).collect();
                let guard = ReleaseOnPanic {
                    evaluator: self,
                    keys: &my_keys,
                    armed: true,
                };
                // Another thread may have stored it between our lookup and our claim.
                let again = self.lookup(&my_keys);
                let to_simulate: Vec<usize> =
                    (0..mine.len()).filter(|&j| again[j].is_none()).collect();
                let mut outcomes: Vec<Option<Evaluation>> = again;
                if !to_simulate.is_empty() {
                    let batch: Vec<Vec<f64>> = to_simulate
                        .iter()
                        .map(|&j| points[mine[j]].clone())
                        .collect();
                    // On a fault, `guard` abandons the claimed keys as it drops.
                    let fresh = self.inner.evaluate(objective, &batch)?;
                    self.simulated
                        .fetch_add(to_simulate.len() as u64, Ordering::Relaxed);
                    simulated_here += to_simulate.len() as u64;
                    let failed: Vec<&String> =
                        fresh.iter().filter_map(|e| e.failure.as_ref()).collect();
                    if let Some(first) = failed.first() {
                        tracing::info!(failed = failed.len(), first = %first, "simulations failed");
                        self.failed
                            .fetch_add(failed.len() as u64, Ordering::Relaxed);
                    }
                    let entries: Vec<(EvaluationKey, Evaluation)> = to_simulate
                        .iter()
                        .zip(fresh)
                        .map(|(&j, e)| (my_keys[j], e))
                        .collect();
                    if let Err(e) = self.store.put_evaluations(&entries) {
                        self.note(e);
                    }
                    for (j, e) in to_simulate.iter().zip(entries.into_iter().map(|(_, e)| e)) {
                        outcomes[*j] = Some(e);
                    }
                }
                let outcomes: Vec<Evaluation> = outcomes
                    .into_iter()
                    .map(|o| o.expect("every claimed point resolved"))
                    .collect();
                guard.disarm();
                self.release(&my_keys, Some(&outcomes));
                for (&i, e) in mine.iter().zip(outcomes) {
                    answers[i] = Some(e);
                }
            }
            for (i, slot) in theirs {
                let mut state = slot.outcome.lock().expect("slot lock");
                while matches!(*state, SlotState::Pending) {
                    state = slot.ready.wait(state).expect("slot lock");
                }
                match &*state {
                    SlotState::Done(e) => answers[i] = Some(e.clone()),
                    _ => retry.push(i),
                }
            }
            open = retry;
        }
        let answers = answers
            .into_iter()
            .map(|a| a.expect("every point answered"))
            .collect();
        Ok((answers, simulated_here))
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
            self.evaluator.release(self.keys, None);
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
        let mut answers = self.lookup(&keys);
        // Distinct keys still missing, each with the first point that asked for it.
        let mut missing: Vec<EvaluationKey> = Vec::new();
        let mut missing_points: Vec<&Vec<f64>> = Vec::new();
        for (i, answer) in answers.iter().enumerate() {
            if answer.is_none() && !missing.contains(&keys[i]) {
                missing.push(keys[i]);
                missing_points.push(&points[i]);
            }
        }
        let mut simulated = 0;
        if !missing.is_empty() {
            let (resolved, simulated_here) =
                self.resolve_missing(objective, &missing, &missing_points)?;
            simulated = simulated_here;
            let by_key: HashMap<EvaluationKey, Evaluation> =
                missing.into_iter().zip(resolved).collect();
            for (answer, key) in answers.iter_mut().zip(&keys) {
                if answer.is_none() {
                    *answer = by_key.get(key).cloned();
                }
            }
        }
        self.store
            .count_lookups(points.len() as u64 - simulated, simulated);
        Ok(answers
            .into_iter()
            .map(|a| a.expect("every point answered"))
            .collect())
    }
}
