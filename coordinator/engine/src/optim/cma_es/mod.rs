//! # CMA-ES with IPOP restarts in the unit box
//!
//! Hansen's (μ/μ_w, λ)-CMA-ES on `[0, 1]^n`: each generation samples `λ` points from
//! `N(m, σ² C)`, evaluates them as **one batch** ([`Problem::bulk_cost`], one round), and
//! moves the mean to the weighted mean of the best `μ = ⌊λ/2⌋`; the covariance `C` learns
//! from the evolution path (rank-one update) and from the selected steps (rank-μ update),
//! and the step size `σ` follows cumulative step-size adaptation (CSA). Parameters are
//! Hansen's defaults ([`strategy`]), population `λ = max(4 + ⌊3 ln n⌋, population)`.
//!
//! **Start.** The first descent starts at the run's start point with a spread per
//! coordinate of [`SPREAD`] × its distance from the lower bound (at least
//! [`super::space::STEP_AT_BOUND`]): the convention of the other local starts, scaled up for
//! a population.
//!
//! **Bounds.** Projection with a penalty ([`boundary`]): a sample outside the box is
//! simulated at its projection and ranked a little worse the further out it lies.
//!
//! **Stops and IPOP restarts.** A descent ends on TolFun, TolX, stagnation or an
//! ill-conditioned `C` ([`stop`]). It then restarts from the run's start point with twice
//! the population (Auger and Hansen 2005, who draw the restart's mean uniformly in the box;
//! here the multistart's starts spread the runs, and a larger population from the same start
//! looks past the local minima near it). The run ends when [`PATIENCE`] restarts in a row
//! did not improve its best by more than [`super::multistart::EQUAL_OBJECTIVE`] of it (the
//! share by which the multistart tells two minima apart), after [`MAX_RESTARTS`]
//! restarts, or when its evaluation budget is used ([`super::budget`]).
//!
//! Every random draw comes from one `ChaCha8Rng` seeded by the run: the same seed and
//! problem give bit-identical runs, so a resumed campaign replays its runs from the store.
//!
//! * N. Hansen (2016): The CMA Evolution Strategy: A Tutorial. arXiv:1604.00772.
//! * A. Auger, N. Hansen (2005): A Restart CMA Evolution Strategy With Increasing
//!   Population Size. IEEE CEC 2005, 1769–1776.
//!
//! [`Problem::bulk_cost`]: argmin::core::Problem::bulk_cost

pub mod boundary;
pub mod stop;
pub mod strategy;
#[cfg(test)]
mod tests;

use super::{check_start, sanitize};
use argmin::core::{
    CostFunction, Error, PopulationState, Problem, Solver, SyncAlias, TerminationReason,
    TerminationStatus, KV,
};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use strategy::Descent;

/// The argmin state CMA-ES works with.
pub type CmaEsState = PopulationState<Vec<f64>, f64>;

/// First spread of a coordinate, as a share of its distance from the lower bound.
pub const SPREAD: f64 = 0.25;
/// Restarts in a row that found nothing better before the run ends.
pub const PATIENCE: usize = 2;
/// Most restarts of a run (the population then is `2⁹ λ`).
pub const MAX_RESTARTS: usize = 9;

/// CMA-ES with IPOP restarts on the unit box (see the [module documentation](self)).
#[derive(Clone, Debug)]
pub struct CmaEs {
    start: Vec<f64>,
    seed: u64,
    population: usize,
    restarts_allowed: usize,
    rng: ChaCha8Rng,
    descent: Option<Descent>,
    history: stop::History,
    /// Restarts so far (IPOP), and those in a row that did not improve the best.
    restarts: usize,
    idle: usize,
    /// Best cost of the run, and the best when the current descent began.
    best: f64,
    best_at_restart: f64,
    best_point: Vec<f64>,
    done: bool,
}

impl CmaEs {
    /// From `start` (in the unit box), seeded by `seed`, with the default population.
    pub fn new(start: Vec<f64>, seed: u64) -> Self {
        Self {
            start,
            seed,
            population: 0,
            restarts_allowed: MAX_RESTARTS,
            rng: ChaCha8Rng::seed_from_u64(seed),
            descent: None,
            history: stop::History::default(),
            restarts: 0,
            idle: 0,
            best: f64::INFINITY,
            best_at_restart: f64::INFINITY,
            best_point: Vec::new(),
            done: false,
        }
    }

    /// A first population of at least `population` (the default `4 + ⌊3 ln n⌋` if larger).
    pub fn with_population(mut self, population: usize) -> Self {
        self.population = population;
        self
    }

    /// At most `restarts` IPOP restarts (0: one descent alone).
    pub fn with_restarts(mut self, restarts: usize) -> Self {
        self.restarts_allowed = restarts;
        self
    }

    /// IPOP restarts so far.
    pub fn restarts(&self) -> usize {
        self.restarts
    }

    /// The first descent's population.
    pub fn lambda(&self) -> usize {
        strategy::default_lambda(self.start.len()).max(self.population)
    }

    fn spread(&self) -> Vec<f64> {
        self.start
            .iter()
            .map(|&u| (SPREAD * u).max(super::space::STEP_AT_BOUND))
            .collect()
    }

    fn begin(&mut self, lambda: usize) {
        self.descent = Some(Descent::new(&self.start, &self.spread(), lambda));
        self.history = stop::History::default();
        self.best_at_restart = self.best;
    }

    /// One generation: sample, evaluate as one batch, update; the best point and cost seen.
    fn generation<O>(&mut self, problem: &mut Problem<O>) -> Result<Option<stop::Reason>, Error>
    where
        O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
    {
        let descent = self.descent.as_mut().expect("a descent has begun");
        let samples = descent.sample(&mut self.rng);
        let projected: Vec<Vec<f64>> = samples.x.iter().map(|x| boundary::project(x)).collect();
        let costs: Vec<f64> = problem
            .bulk_cost(&projected)?
            .into_iter()
            .map(sanitize)
            .collect();
        let ranked: Vec<f64> = samples
            .x
            .iter()
            .zip(&costs)
            .map(|(x, &c)| boundary::penalised(x, c))
            .collect();
        let mut order: Vec<usize> = (0..ranked.len()).collect();
        order.sort_by(|&a, &b| ranked[a].total_cmp(&ranked[b]).then(a.cmp(&b)));
        let (first, middle) = (order[0], order[order.len() * 7 / 10]);
        if costs[first] < self.best {
            self.best = costs[first];
            self.best_point = projected[first].clone();
        }
        self.history.best.push(costs[first]);
        descent.update(&samples.y, &order);
        if ranked[first] == ranked[middle] {
            descent.widen();
        }
        Ok(stop::check(descent, &self.history, &costs))
    }

    fn publish(&self, state: CmaEsState) -> CmaEsState {
        state.individual(self.best_point.clone()).cost(self.best)
    }
}

impl<O> Solver<O, CmaEsState> for CmaEs
where
    O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
{
    fn name(&self) -> &str {
        "CMA-ES"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: CmaEsState,
    ) -> Result<(CmaEsState, Option<KV>), Error> {
        check_start("CmaEs", &self.start)?;
        self.rng = ChaCha8Rng::seed_from_u64(self.seed);
        self.best = f64::INFINITY;
        self.restarts = 0;
        self.idle = 0;
        self.done = false;
        self.begin(self.lambda());
        self.generation(problem)?;
        Ok((self.publish(state), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: CmaEsState,
    ) -> Result<(CmaEsState, Option<KV>), Error> {
        let ended = self.generation(problem)?;
        if let Some(reason) = ended {
            // A restart that ends within the multistart's "same minimum" share of the best
            // before it found that minimum again: it polished the point, found nothing new.
            let same = super::multistart::EQUAL_OBJECTIVE * self.best_at_restart.abs();
            if self.best < self.best_at_restart - same {
                self.idle = 0;
            } else {
                self.idle += 1;
            }
            if self.restarts >= self.restarts_allowed || self.idle >= PATIENCE {
                self.done = true;
            } else {
                self.restarts += 1;
                let lambda = self.descent.as_ref().map_or(0, |d| d.p.lambda) * 2;
                self.begin(lambda);
            }
            let kv =
                argmin::kv!("descent_end" => reason.words(); "restarts" => self.restarts as u64;);
            return Ok((self.publish(state), Some(kv)));
        }
        Ok((self.publish(state), None))
    }

    fn terminate(&mut self, _state: &CmaEsState) -> TerminationStatus {
        if self.done {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        } else {
            TerminationStatus::NotTerminated
        }
    }
}
