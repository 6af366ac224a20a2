//! Where objective evaluations run.
//!
//! The optimisers hand batches of points to an [`Evaluator`] and never learn where they
//! were simulated: on this machine's cores ([`LocalEvaluator`]), on remote workers, or
//! nowhere at all because the point was seen before ([`CachedEvaluator`]).

use crate::objective::{Evaluation, Objective};
use rayon::prelude::*;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Evaluates batches of points of an objective.
pub trait Evaluator: Send + Sync {
    /// Evaluate `objective` at each point (values of its free parameters), answers in order.
    /// The points of a batch are independent: implementations run them in parallel.
    fn evaluate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Evaluation>;
}

impl<E: Evaluator + ?Sized> Evaluator for &E {
    fn evaluate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Evaluation> {
        (**self).evaluate(objective, points)
    }
}

/// Simulates in this process, spreading a batch over the machine's cores.
#[derive(Debug, Default, Clone, Copy)]
pub struct LocalEvaluator;

impl Evaluator for LocalEvaluator {
    fn evaluate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Evaluation> {
        points.par_iter().map(|p| objective.evaluate(p)).collect()
    }
}

/// Counts of a [`CachedEvaluator`].
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct CacheStats {
    /// Points asked for.
    pub requested: u64,
    /// Points that had to be simulated.
    pub simulated: u64,
    /// Points answered from the cache (including repeats within one batch).
    pub cached: u64,
}

/// Remembers every evaluation, keyed by the objective's fingerprint and the exact bits of
/// the point, so that concurrent runs and repeated points never simulate twice.
pub struct CachedEvaluator<E> {
    inner: E,
    entries: Mutex<HashMap<CacheKey, Evaluation>>,
    requested: AtomicU64,
    simulated: AtomicU64,
}

impl<E: Evaluator> CachedEvaluator<E> {
    pub fn new(inner: E) -> Self {
        Self {
            inner,
            entries: Mutex::new(HashMap::new()),
            requested: AtomicU64::new(0),
            simulated: AtomicU64::new(0),
        }
    }

    pub fn stats(&self) -> CacheStats {
        let requested = self.requested.load(Ordering::Relaxed);
        let simulated = self.simulated.load(Ordering::Relaxed);
        CacheStats {
            requested,
            simulated,
            cached: requested - simulated,
        }
    }
}

/// Objective fingerprint and the bits of the point.
type CacheKey = ([u8; 32], Vec<u64>);

fn key(objective: &Objective, point: &[f64]) -> CacheKey {
    (
        objective.fingerprint(),
        point.iter().map(|v| v.to_bits()).collect(),
    )
}

impl<E: Evaluator> Evaluator for CachedEvaluator<E> {
    fn evaluate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Evaluation> {
        self.requested
            .fetch_add(points.len() as u64, Ordering::Relaxed);
        let keys: Vec<_> = points.iter().map(|p| key(objective, p)).collect();
        let mut answers: Vec<Option<Evaluation>> = {
            let entries = self.entries.lock().expect("cache lock");
            keys.iter().map(|k| entries.get(k).cloned()).collect()
        };
        // Simulate each distinct missing point once.
        let mut missing: Vec<usize> = Vec::new();
        for (i, answer) in answers.iter().enumerate() {
            if answer.is_none() && !missing.iter().any(|&j| keys[j] == keys[i]) {
                missing.push(i);
            }
        }
        if !missing.is_empty() {
            let batch: Vec<Vec<f64>> = missing.iter().map(|&i| points[i].clone()).collect();
            let fresh = self.inner.evaluate(objective, &batch);
            self.simulated
                .fetch_add(missing.len() as u64, Ordering::Relaxed);
            let mut entries = self.entries.lock().expect("cache lock");
            for (&i, evaluation) in missing.iter().zip(fresh) {
                entries.insert(keys[i].clone(), evaluation);
            }
            for (i, answer) in answers.iter_mut().enumerate() {
                if answer.is_none() {
                    *answer = entries.get(&keys[i]).cloned();
                }
            }
        }
        answers
            .into_iter()
            .map(|a| a.expect("every point answered"))
            .collect()
    }
}
