//! Where objective evaluations run.
//!
//! The optimisers hand batches of points to an [`Evaluator`] and never learn where they
//! were simulated: on this machine's cores ([`LocalEvaluator`]), on remote workers, or
//! nowhere at all because the evaluation store already holds the point
//! ([`crate::store::StoredEvaluator`]).

use crate::objective::{Evaluation, Objective};
use rayon::prelude::*;

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

/// Simulated outputs of one point (one series per mapped output), or why there are none.
pub type Outputs = Result<Vec<Vec<f64>>, String>;

/// Simulates batches of points and returns the mapped outputs themselves, for sensitivities,
/// residuals and plots.
pub trait Simulator: Send + Sync {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Outputs>;
}

impl<S: Simulator + ?Sized> Simulator for &S {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Outputs> {
        (**self).simulate(objective, points)
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

impl Simulator for LocalEvaluator {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Vec<Outputs> {
        points
            .par_iter()
            .map(|p| objective.simulate(p).map_err(|e| e.to_string()))
            .collect()
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
}
