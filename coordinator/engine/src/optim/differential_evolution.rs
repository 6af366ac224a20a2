//! # Differential evolution in the unit box
//!
//! Population-based global minimiser on `[0, 1]^n`, after Storn and Price.
//!
//! ## Algorithm
//!
//! The population holds `NP` points: the caller's start point plus `NP - 1` points of
//! a Latin hypercube in `[0, 1]^n` (each axis is cut into `NP - 1` equal strata and
//! every stratum holds exactly one point, placed uniformly inside it), all drawn from
//! a `ChaCha8Rng` seeded with the caller's seed. One solver iteration is one
//! generation: for every target `x_i`
//!
//! 1. **Mutation.** With [`Strategy::Rand1Bin`] (the default) three distinct
//!    members `r1, r2, r3`, all different from `i`, give the mutant
//!    `v = x_r1 + F (x_r2 - x_r3)`; with [`Strategy::Best1Bin`] the base is the
//!    generation's best member: `v = x_best + F (x_r1 - x_r2)`. `F` is `0.7` by
//!    default ([`DifferentialEvolution::with_mutation_factor`]); with
//!    [`DifferentialEvolution::with_dither`] it is instead drawn uniformly from an
//!    interval once per generation.
//! 2. **Binomial crossover.** The trial vector takes each coordinate from the
//!    mutant with probability `CR` (`0.9` by default), and one randomly chosen
//!    coordinate always, the others from the target.
//! 3. **Bounce-back.** A mutant coordinate beyond a bound is replaced by a uniformly
//!    random point between the base vector's coordinate and that bound (Price,
//!    Storn and Lampinen 2005). Trial vectors therefore always lie in the box,
//!    without any penalty, and the search can approach a bound closely.
//! 4. **Selection.** All `NP` trial vectors are evaluated with one
//!    [`Problem::bulk_cost`] call (the initial population, too), so the problem can
//!    evaluate them in parallel. A trial replaces its target if its cost is lower
//!    or equal (equal lets the population drift across plateaus).
//!
//! The state's `individual` and `cost` are set to the best member after every
//! generation, so the executor's best parameter vector and best cost are the best
//! point evaluated so far (selection never loses it). The state's `population`
//! holds the current population.
//!
//! ## Termination
//!
//! * Converged ([`TerminationReason::SolverConverged`]) when the population has
//!   collapsed: on every axis the members span at most `xtol`, *and* their costs
//!   span at most `ftol_rel·|f_best| + ftol_abs`. Requiring both keeps a
//!   population on a plateau of equal costs (for instance all failures with the
//!   same penalty) searching.
//! * Stalled ([`TerminationReason::SolverExit`]) when the best cost has not
//!   improved by more than `ftol_rel·|f_best| + ftol_abs` for `max_stall`
//!   generations; this ends runs on flat or unidentifiable objectives where the
//!   positions never collapse.
//!
//! Costs that are NaN or `+∞` are treated as `f64::MAX`; errors from the cost
//! function are propagated. Same seed and same problem give bit-identical runs.
//!
//! ## References
//!
//! * R. Storn, K. Price (1997): Differential Evolution – A Simple and Efficient
//!   Heuristic for global Optimization over Continuous Spaces. Journal of Global
//!   Optimization 11, 341–359.
//! * K. V. Price, R. M. Storn, J. A. Lampinen (2005): Differential Evolution – A
//!   Practical Approach to Global Optimization. Springer (bounce-back boundary
//!   handling, dither).

use super::{check_start, invalid, sanitize};
use argmin::core::{
    CostFunction, Error, PopulationState, Problem, Solver, SyncAlias, TerminationReason,
    TerminationStatus, KV,
};
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// The argmin state differential evolution works with.
pub type DifferentialEvolutionState = PopulationState<Vec<f64>, f64>;

/// How mutants are formed.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Strategy {
    /// `v = x_r1 + F (x_r2 - x_r3)`: explores, robust on multimodal problems.
    #[default]
    Rand1Bin,
    /// `v = x_best + F (x_r1 - x_r2)`: converges faster, more easily trapped.
    Best1Bin,
}

/// The mutation factor `F`.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Mutation {
    Constant(f64),
    /// Drawn uniformly from `[min, max)` once per generation.
    Dither {
        min: f64,
        max: f64,
    },
}

/// Differential evolution (rand/1/bin or best/1/bin) on the unit box `[0, 1]^n`.
///
/// The population of `n` parameters by default, `max(15, 10 n)`: one round of points.
pub fn default_population(n: usize) -> usize {
    (10 * n).max(15)
}

/// See the [module documentation](self) for the algorithm. Defaults:
///
/// * population size `max(15, 10 n)`, including the start point,
/// * `F = 0.7` (constant), `CR = 0.9`, [`Strategy::Rand1Bin`],
/// * `xtol = 1e-6` (population extent per axis),
/// * `ftol = 1e-8` relative plus `1e-12` absolute (cost spread and improvement),
/// * `max_stall = 50` generations.
#[derive(Clone, Debug)]
pub struct DifferentialEvolution {
    start: Vec<f64>,
    seed: u64,
    population_size: usize,
    mutation: Mutation,
    crossover: f64,
    strategy: Strategy,
    xtol: f64,
    ftol_rel: f64,
    ftol_abs: f64,
    max_stall: u64,
    rng: ChaCha8Rng,
    population: Vec<Vec<f64>>,
    costs: Vec<f64>,
    best: usize,
    stall: u64,
}

impl DifferentialEvolution {
    /// Creates the solver; `start` (which must lie in `[0, 1]^n`, checked when the
    /// solver is initialised) becomes a member of the initial population and
    /// `seed` determines every random choice.
    pub fn new(start: Vec<f64>, seed: u64) -> Self {
        let population_size = default_population(start.len());
        DifferentialEvolution {
            start,
            seed,
            population_size,
            mutation: Mutation::Constant(0.7),
            crossover: 0.9,
            strategy: Strategy::Rand1Bin,
            xtol: 1e-6,
            ftol_rel: 1e-8,
            ftol_abs: 1e-12,
            max_stall: 50,
            rng: ChaCha8Rng::seed_from_u64(seed),
            population: Vec::new(),
            costs: Vec::new(),
            best: 0,
            stall: 0,
        }
    }

    /// Number of members, including the start point. Must be `>= 4`; defaults to
    /// `max(15, 10 n)`.
    pub fn with_population_size(mut self, size: usize) -> Result<Self, Error> {
        if size < 4 {
            return Err(invalid(
                "`DifferentialEvolution`: population size must be >= 4.",
            ));
        }
        self.population_size = size;
        Ok(self)
    }

    /// Constant mutation factor `F`. Must be in `(0, 2]`; defaults to `0.7`.
    pub fn with_mutation_factor(mut self, f: f64) -> Result<Self, Error> {
        if !(f > 0.0 && f <= 2.0) {
            return Err(invalid(
                "`DifferentialEvolution`: mutation factor must be in (0, 2].",
            ));
        }
        self.mutation = Mutation::Constant(f);
        Ok(self)
    }

    /// Draw `F` uniformly from `[min, max)` once per generation instead of using a
    /// constant (Price et al. suggest `[0.5, 1.0]`). Requires
    /// `0 < min <= max <= 2`.
    pub fn with_dither(mut self, min: f64, max: f64) -> Result<Self, Error> {
        if !(min > 0.0 && min <= max && max <= 2.0) {
            return Err(invalid(
                "`DifferentialEvolution`: dither needs 0 < min <= max <= 2.",
            ));
        }
        self.mutation = Mutation::Dither { min, max };
        Ok(self)
    }

    /// Crossover probability `CR`. Must be in `[0, 1]`; defaults to `0.9`.
    pub fn with_crossover(mut self, cr: f64) -> Result<Self, Error> {
        if !(0.0..=1.0).contains(&cr) {
            return Err(invalid(
                "`DifferentialEvolution`: crossover probability must be in [0, 1].",
            ));
        }
        self.crossover = cr;
        Ok(self)
    }

    /// Mutation strategy; defaults to [`Strategy::Rand1Bin`].
    #[must_use]
    pub fn with_strategy(mut self, strategy: Strategy) -> Self {
        self.strategy = strategy;
        self
    }

    /// Converged when on every axis the population spans at most `xtol` (and the
    /// cost spread is within `ftol`). Must be finite and `>= 0`; defaults to `1e-6`.
    pub fn with_xtol(mut self, xtol: f64) -> Result<Self, Error> {
        if !(xtol.is_finite() && xtol >= 0.0) {
            return Err(invalid(
                "`DifferentialEvolution`: xtol must be finite and >= 0.",
            ));
        }
        self.xtol = xtol;
        Ok(self)
    }

    /// Cost tolerance `rel·|f_best| + abs`, used for the spread of the population's
    /// costs and for what counts as an improvement of the best cost. Both must be
    /// finite and `>= 0`; defaults to `rel = 1e-8`, `abs = 1e-12`.
    pub fn with_ftol(mut self, rel: f64, abs: f64) -> Result<Self, Error> {
        if !(rel.is_finite() && rel >= 0.0 && abs.is_finite() && abs >= 0.0) {
            return Err(invalid(
                "`DifferentialEvolution`: ftol must be finite and >= 0.",
            ));
        }
        self.ftol_rel = rel;
        self.ftol_abs = abs;
        Ok(self)
    }

    /// Stop after this many consecutive generations without improvement of the
    /// best cost. Must be `>= 1`; defaults to 50.
    pub fn with_max_stall(mut self, generations: u64) -> Result<Self, Error> {
        if generations == 0 {
            return Err(invalid("`DifferentialEvolution`: max_stall must be >= 1."));
        }
        self.max_stall = generations;
        Ok(self)
    }

    fn cost_tolerance(&self, best: f64) -> f64 {
        self.ftol_rel * best.abs() + self.ftol_abs
    }

    /// `count` points of a Latin hypercube in `[0, 1]^n`.
    fn latin_hypercube(&mut self, n: usize, count: usize) -> Vec<Vec<f64>> {
        let mut points = vec![vec![0.0; n]; count];
        let mut strata: Vec<usize> = (0..count).collect();
        for j in 0..n {
            strata.shuffle(&mut self.rng);
            for (point, &stratum) in points.iter_mut().zip(&strata) {
                let u: f64 = self.rng.random();
                point[j] = ((stratum as f64 + u) / count as f64).min(1.0);
            }
        }
        points
    }

    /// `K` distinct member indices, all different from `exclude`.
    fn distinct_indices<const K: usize>(&mut self, exclude: usize) -> [usize; K] {
        let mut picked = [usize::MAX; K];
        for k in 0..K {
            picked[k] = loop {
                let r = self.rng.random_range(0..self.population_size);
                if r != exclude && !picked[..k].contains(&r) {
                    break r;
                }
            };
        }
        picked
    }

    /// The trial vector for target `i`.
    fn trial(&mut self, i: usize, f: f64) -> Vec<f64> {
        let (base, a, b) = match self.strategy {
            Strategy::Rand1Bin => {
                let [r1, r2, r3] = self.distinct_indices::<3>(i);
                (r1, r2, r3)
            }
            Strategy::Best1Bin => {
                let [r1, r2] = self.distinct_indices::<2>(i);
                (self.best, r1, r2)
            }
        };
        let n = self.start.len();
        let forced = self.rng.random_range(0..n);
        let mut trial = self.population[i].clone();
        for (j, t) in trial.iter_mut().enumerate() {
            if j != forced && self.rng.random::<f64>() >= self.crossover {
                continue;
            }
            let origin = self.population[base][j];
            let mut v = origin + f * (self.population[a][j] - self.population[b][j]);
            if v > 1.0 {
                v = origin + self.rng.random::<f64>() * (1.0 - origin);
            } else if v < 0.0 {
                v = origin - self.rng.random::<f64>() * origin;
            }
            *t = v.clamp(0.0, 1.0);
        }
        trial
    }

    fn best_index(&self) -> usize {
        let mut best = 0;
        for (i, &c) in self.costs.iter().enumerate() {
            if c < self.costs[best] {
                best = i;
            }
        }
        best
    }

    fn publish(&self, state: DifferentialEvolutionState) -> DifferentialEvolutionState {
        state
            .individual(self.population[self.best].clone())
            .cost(self.costs[self.best])
            .population(self.population.clone())
    }
}

impl<O> Solver<O, DifferentialEvolutionState> for DifferentialEvolution
where
    O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
{
    fn name(&self) -> &str {
        "Differential evolution"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: DifferentialEvolutionState,
    ) -> Result<(DifferentialEvolutionState, Option<KV>), Error> {
        check_start("DifferentialEvolution", &self.start)?;
        let n = self.start.len();
        self.rng = ChaCha8Rng::seed_from_u64(self.seed);
        let mut population = Vec::with_capacity(self.population_size);
        population.push(self.start.clone());
        population.extend(self.latin_hypercube(n, self.population_size - 1));
        self.costs = problem
            .bulk_cost(&population)?
            .into_iter()
            .map(sanitize)
            .collect();
        self.population = population;
        self.best = self.best_index();
        self.stall = 0;
        Ok((self.publish(state), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: DifferentialEvolutionState,
    ) -> Result<(DifferentialEvolutionState, Option<KV>), Error> {
        let f = match self.mutation {
            Mutation::Constant(f) => f,
            Mutation::Dither { min, max } => min + (max - min) * self.rng.random::<f64>(),
        };
        let trials: Vec<Vec<f64>> = (0..self.population_size)
            .map(|i| self.trial(i, f))
            .collect();
        let trial_costs = problem.bulk_cost(&trials)?;

        let mut replaced = 0u64;
        for (i, (trial, cost)) in trials.into_iter().zip(trial_costs).enumerate() {
            let cost = sanitize(cost);
            if cost <= self.costs[i] {
                self.population[i] = trial;
                self.costs[i] = cost;
                replaced += 1;
            }
        }

        let previous_best = self.costs[self.best];
        self.best = self.best_index();
        let best = self.costs[self.best];
        if best < previous_best - self.cost_tolerance(previous_best) {
            self.stall = 0;
        } else {
            self.stall += 1;
        }

        let kv = argmin::kv!(
            "F" => f;
            "replaced" => replaced;
            "stall" => self.stall;
        );
        Ok((self.publish(state), Some(kv)))
    }

    fn terminate(&mut self, _state: &DifferentialEvolutionState) -> TerminationStatus {
        if self.costs.is_empty() {
            return TerminationStatus::NotTerminated;
        }
        let best = self.costs[self.best];
        let worst = self.costs.iter().fold(best, |a, &c| a.max(c));
        let collapsed = (0..self.start.len()).all(|j| {
            let (lo, hi) = self
                .population
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
                    (lo.min(p[j]), hi.max(p[j]))
                });
            hi - lo <= self.xtol
        });
        if collapsed && worst - best <= self.cost_tolerance(best) {
            return TerminationStatus::Terminated(TerminationReason::SolverConverged);
        }
        if self.stall >= self.max_stall {
            return TerminationStatus::Terminated(TerminationReason::SolverExit(format!(
                "best cost did not improve for {} generations",
                self.stall
            )));
        }
        TerminationStatus::NotTerminated
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::test_problems::{Recorder, Rosenbrock, Sphere};
    use argmin::core::{Executor, State};

    struct Outcome {
        best: Vec<f64>,
        cost: f64,
        generations: u64,
        evaluations: u64,
        reason: TerminationReason,
    }

    fn run<O>(problem: O, solver: DifferentialEvolution, max_iters: u64) -> Outcome
    where
        O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
    {
        let res = Executor::new(problem, solver)
            .configure(|s| s.max_iters(max_iters))
            .run()
            .unwrap();
        let state = res.state();
        Outcome {
            best: state.get_best_param().unwrap().clone(),
            cost: state.get_best_cost(),
            generations: state.get_iter(),
            evaluations: res.problem.counts["cost_count"],
            reason: state.get_termination_reason().unwrap().clone(),
        }
    }

    fn assert_close(x: &[f64], expected: &[f64], tol: f64) {
        for (a, b) in x.iter().zip(expected) {
            assert!((a - b).abs() < tol, "{x:?} vs {expected:?}");
        }
    }

    #[test]
    fn sphere_2d_converges() {
        let centre = vec![0.3, 0.65];
        let problem = Sphere {
            centre: centre.clone(),
        };
        let out = run(problem, DifferentialEvolution::new(vec![0.9, 0.1], 1), 1000);
        println!(
            "DE sphere 2-D: {} evaluations, {} generations, f = {:e}",
            out.evaluations, out.generations, out.cost
        );
        assert_eq!(out.reason, TerminationReason::SolverConverged);
        assert_close(&out.best, &centre, 1e-6);
    }

    #[test]
    fn rosenbrock_2d_converges() {
        let out = run(
            Rosenbrock,
            DifferentialEvolution::new(vec![0.2, 0.75], 7),
            2000,
        );
        println!(
            "DE Rosenbrock 2-D: {} evaluations, {} generations, f = {:e}, x = {:?}",
            out.evaluations, out.generations, out.cost, out.best
        );
        assert_eq!(out.reason, TerminationReason::SolverConverged);
        assert_close(&out.best, &[0.75, 0.75], 1e-6);
    }

    #[test]
    fn rosenbrock_5d_best1bin_with_dither() {
        struct Rosenbrock5;
        impl CostFunction for Rosenbrock5 {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
                let x: Vec<f64> = u.iter().map(|v| 4.0 * v - 2.0).collect();
                Ok(x.windows(2)
                    .map(|w| (1.0 - w[0]).powi(2) + 100.0 * (w[1] - w[0] * w[0]).powi(2))
                    .sum())
            }
        }
        let solver = DifferentialEvolution::new(vec![0.5; 5], 3)
            .with_strategy(Strategy::Best1Bin)
            .with_dither(0.5, 1.0)
            .unwrap();
        let out = run(Rosenbrock5, solver, 5000);
        println!(
            "DE best/1/bin Rosenbrock 5-D: {} evaluations, {} generations, f = {:e}",
            out.evaluations, out.generations, out.cost
        );
        assert_close(&out.best, &[0.75; 5], 1e-4);
    }

    #[test]
    fn minimum_on_bounds() {
        // Unconstrained minimum at (1.3, -0.2, 0.4); in the box (1, 0, 0.4).
        let problem = Sphere {
            centre: vec![1.3, -0.2, 0.4],
        };
        let out = run(problem, DifferentialEvolution::new(vec![0.5; 3], 11), 1000);
        println!(
            "DE minimum on bounds: {} evaluations, x = {:?}",
            out.evaluations, out.best
        );
        assert_close(&out.best, &[1.0, 0.0, 0.4], 1e-6);
    }

    #[test]
    fn finds_the_global_of_several_minima() {
        // Rastrigin-like: many local minima, global one at (0.7, 0.2).
        struct Bumpy;
        impl CostFunction for Bumpy {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
                Ok([0.7, 0.2]
                    .iter()
                    .zip(u)
                    .map(|(c, x)| {
                        let z = 5.0 * (x - c);
                        z * z + 2.0 * (1.0 - (2.0 * std::f64::consts::PI * z).cos())
                    })
                    .sum())
            }
        }
        let out = run(Bumpy, DifferentialEvolution::new(vec![0.05, 0.95], 5), 1000);
        assert_close(&out.best, &[0.7, 0.2], 1e-6);
    }

    #[test]
    fn start_point_is_a_member() {
        // The start is the minimum: it must be the best member right away.
        let centre = vec![0.123, 0.456, 0.789];
        let problem = Sphere {
            centre: centre.clone(),
        };
        let res = Executor::new(problem, DifferentialEvolution::new(centre.clone(), 2))
            .configure(|s| s.max_iters(0))
            .run()
            .unwrap();
        assert_eq!(res.state().get_best_param(), Some(&centre));
        assert_eq!(res.state().get_best_cost(), 0.0);
        assert_eq!(res.state().get_population().unwrap().len(), 30);
    }

    #[test]
    fn deterministic() {
        let a = run(
            Rosenbrock,
            DifferentialEvolution::new(vec![0.2, 0.75], 42),
            2000,
        );
        let b = run(
            Rosenbrock,
            DifferentialEvolution::new(vec![0.2, 0.75], 42),
            2000,
        );
        assert_eq!(a.best, b.best);
        assert_eq!(a.cost.to_bits(), b.cost.to_bits());
        assert_eq!(a.evaluations, b.evaluations);
        let c = run(
            Rosenbrock,
            DifferentialEvolution::new(vec![0.2, 0.75], 43),
            5,
        );
        let d = run(
            Rosenbrock,
            DifferentialEvolution::new(vec![0.2, 0.75], 42),
            5,
        );
        assert_ne!(c.best, d.best);
    }

    #[test]
    fn stays_in_box_and_batches() {
        // Minimum in a corner, so many mutants overshoot the bounds.
        let problem = Recorder::new(Sphere {
            centre: vec![1.5, -0.5],
        });
        let solver = DifferentialEvolution::new(vec![0.5, 0.5], 9)
            .with_population_size(12)
            .unwrap();
        let res = Executor::new(problem, solver)
            .configure(|s| s.max_iters(200).counting(true))
            .run()
            .unwrap();
        let evals = res.problem.counts["cost_count"];
        // Counts reach the state only with `counting(true)`.
        assert_eq!(res.state().get_func_counts()["cost_count"], evals);
        let generations = res.state().get_iter() as usize;
        let recorder = res.problem.problem.as_ref().unwrap();
        let points = recorder.points.lock().unwrap();
        let batches = recorder.batch_sizes.lock().unwrap();
        assert_eq!(points.len() as u64, evals);
        assert!(points
            .iter()
            .all(|p| p.iter().all(|v| (0.0..=1.0).contains(v))));
        assert_eq!(*recorder.single_calls.lock().unwrap(), 0);
        assert_eq!(batches.len(), generations + 1);
        assert!(batches.iter().all(|&b| b == 12));
        println!(
            "DE batching: {evals} evaluations in {} batches of 12",
            batches.len()
        );
    }

    #[test]
    fn nan_and_penalties_are_ranked_last() {
        struct Patchy;
        impl CostFunction for Patchy {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
                if x[0] < 0.2 {
                    Ok(f64::NAN)
                } else if x[1] > 0.8 {
                    Ok(1e10)
                } else {
                    Ok((x[0] - 0.25).powi(2) + (x[1] - 0.75).powi(2))
                }
            }
        }
        let out = run(Patchy, DifferentialEvolution::new(vec![0.1, 0.9], 4), 1000);
        assert_close(&out.best, &[0.25, 0.75], 1e-6);
    }

    #[test]
    fn plateau_stalls() {
        // Every evaluation fails with the same penalty: nothing to improve.
        struct Failing;
        impl CostFunction for Failing {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, _x: &Vec<f64>) -> Result<f64, Error> {
                Ok(1e10)
            }
        }
        let solver = DifferentialEvolution::new(vec![0.5, 0.5], 0)
            .with_max_stall(10)
            .unwrap();
        let out = run(Failing, solver, 1000);
        assert!(matches!(out.reason, TerminationReason::SolverExit(_)));
        assert_eq!(out.generations, 10);
    }

    #[test]
    fn errors_propagate() {
        struct Broken;
        impl CostFunction for Broken {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
                if x[0] > 0.9 {
                    Err(Error::msg("simulation failed"))
                } else {
                    Ok(x[0])
                }
            }
        }
        let res = Executor::new(Broken, DifferentialEvolution::new(vec![0.5], 0))
            .configure(|s| s.max_iters(100))
            .run();
        assert!(res.is_err());
    }

    #[test]
    fn invalid_settings_are_rejected() {
        let de = || DifferentialEvolution::new(vec![0.5, 0.5], 0);
        assert!(de().with_population_size(3).is_err());
        assert!(de().with_mutation_factor(0.0).is_err());
        assert!(de().with_mutation_factor(2.5).is_err());
        assert!(de().with_dither(0.9, 0.5).is_err());
        assert!(de().with_crossover(1.1).is_err());
        assert!(de().with_xtol(-1.0).is_err());
        assert!(de().with_ftol(f64::NAN, 0.0).is_err());
        assert!(de().with_max_stall(0).is_err());
        assert!(de()
            .with_population_size(8)
            .and_then(|d| d.with_mutation_factor(0.5))
            .and_then(|d| d.with_crossover(0.3))
            .and_then(|d| d.with_xtol(1e-4))
            .and_then(|d| d.with_ftol(1e-6, 0.0))
            .and_then(|d| d.with_max_stall(5))
            .is_ok());
        let outside = Executor::new(
            Sphere {
                centre: vec![0.5, 0.5],
            },
            DifferentialEvolution::new(vec![-0.1, 0.5], 0),
        )
        .configure(|s| s.max_iters(10))
        .run();
        assert!(outside.is_err());
    }
}
