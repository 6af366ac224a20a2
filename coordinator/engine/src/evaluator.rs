//! Where objective evaluations run.
//!
//! The optimisers hand batches of points to an [`Evaluator`] and never learn where they
//! were simulated: on this machine's cores ([`LocalEvaluator`]), on remote workers, or
//! nowhere at all because the evaluation store already holds the point
//! ([`crate::store::StoredEvaluator`]).
//!
//! Two kinds of trouble are kept apart. A simulation that ran and failed (the solver
//! diverged, ran out of steps) is a result: an [`Evaluation`] carrying its reason, scored
//! with a penalty, stored and replayed like any other. A [`Fault`] (no worker reachable, a
//! request refused, the campaign cancelled) means no result exists for the batch: it is
//! never stored and never scored; the campaign stops and can be resumed later.

use crate::objective::{Evaluation, Objective};
use rayon::prelude::*;

/// Why a batch has no results at all: nothing was simulated, or nothing came back. Unlike a
/// failed simulation, a fault says nothing about the points, so it is never stored.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct Fault {
    pub kind: FaultKind,
    pub message: String,
}

/// What kind of [`Fault`] stopped a batch.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// No worker could do the work in time (none up, connections lost, deadlines missed,
    /// queues full): the same batch may succeed later, once workers are back.
    Unavailable,
    /// A worker refused the request as invalid: asking again gives the same answer.
    Rejected,
    /// The campaign was cancelled while the batch waited.
    Cancelled,
}

impl Fault {
    pub fn unavailable(message: impl Into<String>) -> Self {
        Self {
            kind: FaultKind::Unavailable,
            message: message.into(),
        }
    }

    pub fn rejected(message: impl Into<String>) -> Self {
        Self {
            kind: FaultKind::Rejected,
            message: message.into(),
        }
    }

    pub fn cancelled(message: impl Into<String>) -> Self {
        Self {
            kind: FaultKind::Cancelled,
            message: message.into(),
        }
    }

    /// True when the same batch may succeed later (on workers that came back).
    pub fn is_retryable(&self) -> bool {
        self.kind == FaultKind::Unavailable
    }
}

/// Evaluates batches of points of an objective.
pub trait Evaluator: Send + Sync {
    /// Evaluate `objective` at each point (values of its free parameters), answers in order,
    /// or the fault that kept the batch from being evaluated. The points of a batch are
    /// independent: implementations run them in parallel.
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault>;

    /// Whether a batch sent now would find capacity idle (a free worker slot). Callers that
    /// gather many runs' points into shared batches send a second batch while one travels
    /// only when it has somewhere to go; otherwise its points wait to join the next, larger
    /// batch. A hint: it never changes an answer.
    fn has_room(&self) -> bool {
        true
    }

    /// The work on `objective` is over (its campaign ended): what the evaluator keeps to
    /// evaluate it (its record in the form workers take it, say) may go. A hint: a later
    /// batch of it is still answered.
    fn release(&self, _objective: &Objective) {}
}

impl<E: Evaluator + ?Sized> Evaluator for &E {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        (**self).evaluate(objective, points)
    }

    fn has_room(&self) -> bool {
        (**self).has_room()
    }

    fn release(&self, objective: &Objective) {
        (**self).release(objective)
    }
}

/// Simulated outputs of one point (one series per mapped output), or why the simulation
/// failed.
pub type Outputs = Result<Vec<Vec<f64>>, String>;

/// Simulates batches of points and returns the mapped outputs themselves, for sensitivities,
/// residuals and plots.
pub trait Simulator: Send + Sync {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Result<Vec<Outputs>, Fault>;
}

impl<S: Simulator + ?Sized> Simulator for &S {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Result<Vec<Outputs>, Fault> {
        (**self).simulate(objective, points)
    }
}

/// Simulates in this process, spreading a batch over the machine's cores.
#[derive(Debug, Default, Clone, Copy)]
pub struct LocalEvaluator;

impl Evaluator for LocalEvaluator {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        Ok(points.par_iter().map(|p| objective.evaluate(p)).collect())
    }
}

impl Simulator for LocalEvaluator {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Result<Vec<Outputs>, Fault> {
        Ok(points
            .par_iter()
            .map(|p| objective.simulate(p).map_err(|e| e.to_string()))
            .collect())
    }
}

/// Counts of an evaluator that remembers points ([`crate::store::StoredEvaluator`]).
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct CacheStats {
    /// Points asked for.
    pub requested: u64,
    /// Points that had to be simulated.
    pub simulated: u64,
    /// Points answered from the cache (including repeats within one batch).
    pub cached: u64,
    /// Points simulated here whose simulation failed (scored with the penalty).
    pub failed: u64,
}
