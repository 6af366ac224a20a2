//! One run's view of the objective: the unit box, the evaluator, and a log of what it saw.

use super::levenberg_marquardt::Residuals;
use super::space::UnitBox;
use crate::evaluator::{Evaluator, Fault};
use crate::objective::{Evaluation, Objective};
use argmin::core::{CostFunction, Error, SyncAlias};
use std::borrow::Borrow;
use std::sync::Mutex;

/// Told of every batch a run evaluates, for progress display.
pub trait Progress: Sync {
    fn evaluated(&self, count: usize, best_objective: f64);

    /// The same, told which run (its index in the campaign's plan) evaluated the batch and
    /// that run's best objective so far. By default, [`Progress::evaluated`].
    fn run_evaluated(&self, run: usize, count: usize, run_best_objective: f64) {
        let _ = run;
        self.evaluated(count, run_best_objective);
    }

    /// The campaign's runs, before any starts: each one's method and start index, in plan
    /// order. By default, nothing.
    fn planned(&self, runs: &[(String, usize)]) {
        let _ = runs;
    }

    /// A run's best point so far (physical values of the free parameters) and its
    /// objective, each time it improves; told before [`Progress::run_evaluated`] of the
    /// batch that found it. By default, nothing.
    fn run_improved(&self, run: usize, point: &[f64], objective: f64) {
        let _ = (run, point, objective);
    }

    /// A run (its index in the campaign's plan) sent a batch and waited for it: one more of
    /// its rounds ([`RunLog::rounds`]). By default, nothing.
    fn run_round(&self, run: usize) {
        let _ = run;
    }
}

/// Progress that goes nowhere.
pub struct Silent;

impl Progress for Silent {
    fn evaluated(&self, _count: usize, _best_objective: f64) {}
}

/// What a run has seen so far.
#[derive(Debug, Clone, Default)]
pub struct RunLog {
    pub evaluations: usize,
    /// Batches the run sent and waited for, one after another: a batch of points it had
    /// already been answered (a peeked simplex it then asks for) is no new round.
    pub rounds: usize,
    pub best_objective: f64,
    /// Physical values of the free parameters at the best point.
    pub best_point: Vec<f64>,
}

/// The cost function the solvers of a run see: unit-box points in, scaled objective out.
pub struct RunProblem<'a> {
    pub objective: &'a Objective,
    pub evaluator: &'a dyn Evaluator,
    pub space: &'a UnitBox,
    /// Divisor applied to the objective so that solver tolerances are relative to the
    /// objective at the nominal point.
    pub scale: f64,
    pub progress: &'a dyn Progress,
    pub log: Mutex<RunLog>,
    /// Index of the run in the campaign's plan, for progress.
    pub run: usize,
    /// The points of the last [`RunProblem::peek`]: asked for again, they cost no round.
    peeked: Mutex<Vec<Vec<f64>>>,
}

impl<'a> RunProblem<'a> {
    pub fn new(
        objective: &'a Objective,
        evaluator: &'a dyn Evaluator,
        space: &'a UnitBox,
        scale: f64,
        progress: &'a dyn Progress,
    ) -> Self {
        Self {
            objective,
            evaluator,
            space,
            scale,
            progress,
            log: Mutex::new(RunLog {
                evaluations: 0,
                rounds: 0,
                best_objective: f64::INFINITY,
                best_point: Vec::new(),
            }),
            run: 0,
            peeked: Mutex::new(Vec::new()),
        }
    }

    /// Evaluate unit-box points, returning the scaled objectives, or the fault that kept
    /// them from being evaluated (the run then stops with it).
    pub fn batch(&self, units: &[&Vec<f64>]) -> Result<Vec<f64>, Fault> {
        self.evaluate(units, true)
    }

    /// Evaluate unit-box points the solver will ask for again (it is then answered from the
    /// cache, and counted then): the scaled objectives.
    pub fn peek(&self, units: &[Vec<f64>]) -> Result<Vec<f64>, Fault> {
        let units: Vec<&Vec<f64>> = units.iter().collect();
        self.evaluate(&units, false)
    }

    fn evaluate(&self, units: &[&Vec<f64>], count: bool) -> Result<Vec<f64>, Fault> {
        let evaluations = self.evaluations(units, count)?;
        Ok(evaluations.iter().map(|e| self.scaled(e)).collect())
    }

    /// The objective as the solvers see it: divided by the scale, NaN the largest value.
    fn scaled(&self, e: &Evaluation) -> f64 {
        if e.objective.is_nan() {
            f64::MAX
        } else {
            e.objective / self.scale
        }
    }

    /// Evaluate unit-box points with their weighted residuals (the run's objective must
    /// return them: [`Objective::with_residuals`]): each point's scaled objective and
    /// residuals, scaled alike (divided by the square root of the scale), counted as the
    /// run's evaluations.
    pub fn batch_residuals(&self, units: &[&Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Fault> {
        let root = self.scale.sqrt();
        Ok(self
            .evaluations(units, true)?
            .into_iter()
            .map(|e| {
                let cost = self.scaled(&e);
                (cost, e.residuals.iter().map(|r| r / root).collect())
            })
            .collect())
    }

    fn evaluations(&self, units: &[&Vec<f64>], count: bool) -> Result<Vec<Evaluation>, Fault> {
        let points: Vec<Vec<f64>> = units.iter().map(|u| self.space.to_physical(u)).collect();
        let evaluations = self.evaluator.evaluate(self.objective, &points)?;
        self.count_round(units, count);
        if !count {
            return Ok(evaluations);
        }
        let mut log = self.log.lock().expect("run log lock");
        log.evaluations += points.len();
        let was = log.best_objective;
        for (point, e) in points.iter().zip(&evaluations) {
            if e.objective < log.best_objective {
                log.best_objective = e.objective;
                log.best_point = point.clone();
            }
        }
        if log.best_objective < was {
            self.progress
                .run_improved(self.run, &log.best_point, log.best_objective);
        }
        self.progress
            .run_evaluated(self.run, points.len(), log.best_objective);
        drop(log);
        Ok(evaluations)
    }

    /// Count a round for a batch just answered, unless every point of it was peeked or
    /// prefetched (the run already waited for it then); a peek remembers its points.
    fn count_round(&self, units: &[&Vec<f64>], count: bool) {
        let mut peeked = self.peeked.lock().expect("peeked lock");
        let waited = if count {
            let answered = units.iter().all(|u| peeked.contains(u));
            if answered {
                peeked.retain(|p| !units.contains(&p));
            } else {
                peeked.clear();
            }
            !answered
        } else {
            *peeked = units.iter().map(|u| (*u).clone()).collect();
            true
        };
        drop(peeked);
        if waited {
            self.log.lock().expect("run log lock").rounds += 1;
            self.progress.run_round(self.run);
        }
    }

    /// Evaluate points ahead of the solver asking for them one by one (they are then
    /// answered from the cache); not counted as the run's evaluations until asked for.
    pub fn prefetch(&self, units: &[Vec<f64>]) -> Result<(), Fault> {
        let points: Vec<Vec<f64>> = units.iter().map(|u| self.space.to_physical(u)).collect();
        self.evaluator.evaluate(self.objective, &points)?;
        let units: Vec<&Vec<f64>> = units.iter().collect();
        self.count_round(&units, false);
        Ok(())
    }

    pub fn take_log(&self) -> RunLog {
        self.log.lock().expect("run log lock").clone()
    }
}

impl CostFunction for RunProblem<'_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
        Ok(self.batch(&[u])?[0])
    }

    fn bulk_cost<P>(&self, params: &[P]) -> Result<Vec<f64>, Error>
    where
        P: Borrow<Vec<f64>> + SyncAlias,
        f64: argmin::core::SendAlias,
        Self: SyncAlias,
    {
        let units: Vec<&Vec<f64>> = params.iter().map(|p| p.borrow()).collect();
        Ok(self.batch(&units)?)
    }
}

impl Residuals for RunProblem<'_> {
    fn residuals(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Error> {
        let units: Vec<&Vec<f64>> = points.iter().collect();
        Ok(self.batch_residuals(&units)?)
    }
}
