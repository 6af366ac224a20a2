//! The engine a diagnosis runs on: every objective evaluation (the baseline and refit
//! calibrations, the ranking's scans and descents) goes through the evaluation store, so a
//! repeated or interrupted diagnosis simulates only the points the store lacks. Trajectories
//! (sensitivities, residuals, the held-out window) are not stored: they are simulated again
//! and counted apart.

use crate::evaluator::{CacheStats, Evaluator, Fault, Outputs, Simulator};
use crate::objective::{Evaluation, Objective};
use crate::store::{Store, StoreError, Stored, StoredEvaluator};
use serde::Serialize;
use std::sync::atomic::{AtomicU64, Ordering};

/// What a diagnosis asked of its engine.
#[derive(Debug, Default, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct EngineStats {
    /// Objective evaluations: asked for, simulated, answered by the store.
    #[serde(flatten)]
    pub evaluations: CacheStats,
    /// Trajectories simulated (never stored).
    pub trajectories: u64,
}

/// Evaluations through a store, trajectories straight from the inner engine.
pub struct StoredEngine<'a, E> {
    evaluator: &'a dyn Stored,
    /// The evaluator's counts when this engine began: what came before is not its own.
    base: CacheStats,
    inner: &'a E,
    trajectories: AtomicU64,
}

impl<'a, E: Evaluator + Simulator> StoredEngine<'a, E> {
    /// Run `f` with an engine that evaluates through `store` (the store's dispatcher lives
    /// until `f` returns) and simulates trajectories with `inner`.
    pub fn with<R>(inner: &E, store: &dyn Store, f: impl FnOnce(&StoredEngine<'_, E>) -> R) -> R {
        StoredEvaluator::with(inner, store, |evaluator| {
            f(&StoredEngine::over(evaluator, inner))
        })
    }

    /// An engine that evaluates through `evaluator` (one of a dispatcher others share, a
    /// coordinator's) and simulates trajectories with `inner`; its counts are the points
    /// asked from now on (a calibration the evaluator ran before is not this engine's).
    pub fn over(evaluator: &'a dyn Stored, inner: &'a E) -> Self {
        StoredEngine {
            evaluator,
            base: evaluator.stats(),
            inner,
            trajectories: AtomicU64::new(0),
        }
    }

    pub fn stats(&self) -> EngineStats {
        let (now, base) = (self.evaluator.stats(), self.base);
        EngineStats {
            evaluations: CacheStats {
                requested: now.requested - base.requested,
                simulated: now.simulated - base.simulated,
                cached: now.cached - base.cached,
                failed: now.failed - base.failed,
            },
            trajectories: self.trajectories.load(Ordering::Relaxed),
        }
    }

    /// The first store failure met, if any.
    pub fn error(&self) -> Option<StoreError> {
        self.evaluator.error()
    }
}

impl<E: Evaluator + Simulator> Evaluator for StoredEngine<'_, E> {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        self.evaluator.evaluate(objective, points)
    }

    fn has_room(&self) -> bool {
        self.evaluator.has_room()
    }

    fn release(&self, objective: &Objective) {
        self.evaluator.release(objective)
    }
}

impl<E: Evaluator + Simulator> Simulator for StoredEngine<'_, E> {
    fn simulate(&self, objective: &Objective, points: &[Vec<f64>]) -> Result<Vec<Outputs>, Fault> {
        self.trajectories
            .fetch_add(points.len() as u64, Ordering::Relaxed);
        self.inner.simulate(objective, points)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::evaluator::LocalEvaluator;
    use crate::store::MemoryStore;
    use std::sync::atomic::AtomicUsize;

    /// Counts the points it evaluates and simulates.
    #[derive(Default)]
    struct Counting {
        evaluated: AtomicUsize,
        simulated: AtomicUsize,
    }

    impl Evaluator for Counting {
        fn evaluate(&self, o: &Objective, points: &[Vec<f64>]) -> Result<Vec<Evaluation>, Fault> {
            self.evaluated.fetch_add(points.len(), Ordering::Relaxed);
            LocalEvaluator.evaluate(o, points)
        }
    }

    impl Simulator for Counting {
        fn simulate(&self, o: &Objective, points: &[Vec<f64>]) -> Result<Vec<Outputs>, Fault> {
            self.simulated.fetch_add(points.len(), Ordering::Relaxed);
            LocalEvaluator.simulate(o, points)
        }
    }

    fn objective() -> Objective {
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
        let campaign = crate::campaign::Campaign::load(&dir.join("furuta.toml")).unwrap();
        let mut short = campaign.clone();
        short.window = (0.0, 2.0);
        short.stop_time = 2.0;
        let measurement = crate::calibration::load_measurement(&short).unwrap();
        Objective::new(&short, &measurement).unwrap()
    }

    #[test]
    fn a_second_engine_on_the_same_store_evaluates_nothing_again() {
        let objective = objective();
        let store = MemoryStore::new();
        let points = vec![vec![0.011, 0.0012], vec![0.012, 0.002]];
        let inner = Counting::default();
        let a = StoredEngine::with(&inner, &store, |first| {
            let a = first.evaluate(&objective, &points).unwrap();
            first.simulate(&objective, &points[..1]).unwrap();
            assert_eq!(first.stats().evaluations.simulated, 2);
            assert_eq!(first.stats().trajectories, 1);
            a
        });
        StoredEngine::with(&inner, &store, |again| {
            let b = again.evaluate(&objective, &points).unwrap();
            assert_eq!(inner.evaluated.load(Ordering::Relaxed), 2);
            assert_eq!(again.stats().evaluations.simulated, 0);
            assert_eq!(again.stats().evaluations.cached, 2);
            assert_eq!(
                a.iter().map(|e| e.objective).collect::<Vec<_>>(),
                b.iter().map(|e| e.objective).collect::<Vec<_>>()
            );
            // Trajectories go to the inner engine every time.
            again.simulate(&objective, &points[..1]).unwrap();
            assert_eq!(inner.simulated.load(Ordering::Relaxed), 2);
            assert!(again.error().is_none());
        });
    }
}
