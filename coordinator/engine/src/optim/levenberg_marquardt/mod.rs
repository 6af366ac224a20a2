//! Levenberg–Marquardt for the calibration's least-squares objective, bounded to the unit
//! box, one batch of evaluations per iteration.
//!
//! The objective `f = Σ_i k_i Σ_t (y_i − w_i)²` is the sum of squares of the weighted
//! residuals `r = sqrt(k_i) (y_i − w_i)` (per output and sample, the experiments' one after
//! another), which the evaluations of this method return beside the objective
//! ([`Residuals`]). From the residuals `r` and their Jacobian `J` at the current point `x`,
//! a step solves the damped normal equations `(JᵀJ + λ D) δ = −Jᵀr` with Marquardt's
//! scaling `D = diag(JᵀJ)` (K. Levenberg, Q. Appl. Math. 2 (1944) 164–168; D. W.
//! Marquardt, J. SIAM 11 (1963) 431–441).
//!
//! **Bounds**: a parameter at a bound whose gradient pushes it outward is held there for
//! the step (an active set), the others solve the reduced system, and the trial point is
//! projected onto `[0, 1]^n`. A minimum outside the box therefore ends on its bound.
//!
//! **One batch per iteration**: each iteration evaluates, together, three trial points
//! (damping `λ/10`, `λ`, `10 λ`) and, when the Jacobian at `x` is not yet known, the
//! forward differences around `x` ([`jacobian`]). The trials of an iteration use the
//! Jacobian of the previous point carried over to `x` by Broyden's rank-one update (the
//! secant condition along the step just taken); the differences evaluated beside them give
//! the exact Jacobian at `x`, which the next iteration carries over in turn. If no trial
//! lowers the objective, the next iteration retries with that exact Jacobian, and only
//! steps computed from an exact Jacobian that fail raise `λ`. The first batch holds the start
//! point and its differences: a run of `k` iterations is `k + 1` rounds of evaluations.
//!
//! **Termination** (the words a run reports):
//! * `converged: relative objective change below tolerance`: an accepted step lowered the
//!   (scaled) objective by less than [`F_TOLERANCE`] of itself;
//! * `converged: step below tolerance`: the step (max-norm, unit box) is below
//!   [`X_TOLERANCE`], accepted or refused at an exact Jacobian;
//! * `stalled: no damped step lowers the objective`: `λ` passed [`MAX_LAMBDA`];
//! * `plateau: singular Jacobian, no parameter moves the residuals`;
//! * `iterations: iteration limit reached` after [`MAX_ITERATIONS`];
//! * the evaluation budget and stall rule of the run ([`super::budget`]).
//!
//! A run that ends with parameters whose Jacobian column is zero (they move no residual)
//! says so after its reason.

mod jacobian;
mod linear;
#[cfg(test)]
mod tests;

pub use jacobian::STEP;

use super::{check_start, sanitize};
use argmin::core::{Error, IterState, Problem, Solver, TerminationReason, TerminationStatus, KV};
use linear::Columns;

/// Weighted residuals of unit-box points, for least-squares methods.
pub trait Residuals {
    /// Each point's cost and weighted residuals (`cost = Σ r²` up to rounding), in order;
    /// the residuals are empty where the evaluation failed (its cost is then the penalty).
    fn residuals(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Error>;
}

/// The state of argmin's iteration for this solver.
pub type LmState = IterState<Vec<f64>, (), (), (), (), f64>;

/// Convergence: relative fall of the objective of an accepted step.
pub const F_TOLERANCE: f64 = 1e-10;

/// Convergence: the fall of the objective the linear model at the optimum's exact Jacobian
/// predicts for the best step, relative to the objective, once no trial lowered it. A
/// parameter one standard error from its optimum raises the objective by about `1/n` of it
/// (`n` the samples, thousands in the examples), so a fall of 10⁻⁹ is far inside the
/// confidence intervals; it is also about the objective's own jitter (the integrator's
/// tolerance and the differences' steps), below which no damping makes progress.
pub const PREDICTED_TOLERANCE: f64 = 1e-9;

/// Convergence: largest step (max-norm, unit box).
pub const X_TOLERANCE: f64 = 1e-10;

/// Iterations at most (each one batch).
pub const MAX_ITERATIONS: u64 = 200;

/// Damping beyond which no step is tried: the objective does not fall along any.
pub const MAX_LAMBDA: f64 = 1e10;

const START_LAMBDA: f64 = 1e-3;
const MIN_LAMBDA: f64 = 1e-12;
/// The trials of an iteration are damped by `λ / TRIAL_SPREAD`, `λ`, `λ · TRIAL_SPREAD`.
const TRIAL_SPREAD: f64 = 10.0;

pub const CONVERGED_OBJECTIVE: &str = "converged: relative objective change below tolerance";
pub const CONVERGED_STEP: &str = "converged: step below tolerance";
pub const STALLED: &str = "stalled: no damped step lowers the objective";
pub const CONVERGED_PREDICTED: &str =
    "converged: no step lowers the objective, and the linear model predicts a fall below tolerance";
pub const SINGULAR: &str = "plateau: singular Jacobian, no parameter moves the residuals";
pub const ITERATION_LIMIT: &str = "iterations: iteration limit reached";
pub const START_FAILED: &str = "failures: the simulation of the start point failed";

/// Levenberg–Marquardt from a start point in the unit box.
#[derive(Debug, Clone)]
pub struct LevenbergMarquardt {
    x: Vec<f64>,
    cost: f64,
    r: Vec<f64>,
    /// The Jacobian at `x`: exact (differences at `x`) or carried over by Broyden.
    columns: Columns,
    exact: bool,
    lambda: f64,
    step: f64,
    max_iterations: u64,
    iterations: u64,
    stop: Option<&'static str>,
}

impl LevenbergMarquardt {
    pub fn new(start: Vec<f64>) -> Result<Self, Error> {
        check_start("Levenberg-Marquardt", &start)?;
        Ok(Self {
            x: start,
            cost: f64::MAX,
            r: Vec::new(),
            columns: Vec::new(),
            exact: false,
            lambda: START_LAMBDA,
            step: STEP,
            max_iterations: MAX_ITERATIONS,
            iterations: 0,
            stop: None,
        })
    }

    pub fn with_max_iterations(mut self, iterations: u64) -> Self {
        self.max_iterations = iterations;
        self
    }

    /// The damping the next iteration centres its trials on.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// The trial points of this iteration and their damping, each distinct from `x`;
    /// `None` when the normal equations are singular.
    fn trials(&self) -> Option<Vec<(f64, Vec<f64>)>> {
        let (a, g) = linear::normal_equations(&self.columns, &self.r);
        let free: Vec<bool> = self
            .x
            .iter()
            .zip(&g)
            .map(|(&x, &g)| linear::is_free(x, g))
            .collect();
        let mut trials: Vec<(f64, Vec<f64>)> = Vec::new();
        for lambda in [
            self.lambda / TRIAL_SPREAD,
            self.lambda,
            self.lambda * TRIAL_SPREAD,
        ] {
            let step = linear::damped_step(&a, &g, lambda, &free)?;
            let point: Vec<f64> = self
                .x
                .iter()
                .zip(&step)
                .map(|(x, d)| (x + d).clamp(0.0, 1.0))
                .collect();
            if point != self.x && trials.iter().all(|(_, p)| *p != point) {
                trials.push((lambda, point));
            }
        }
        Some(trials)
    }

    /// The fall of the objective the linear model at `x` predicts for the least damped step
    /// (`‖r‖² − ‖r + Jδ‖²`, the step as the bounds clip it); `None` when the normal
    /// equations are singular.
    fn predicted_fall(&self) -> Option<f64> {
        let (a, g) = linear::normal_equations(&self.columns, &self.r);
        let free: Vec<bool> = self
            .x
            .iter()
            .zip(&g)
            .map(|(&x, &g)| linear::is_free(x, g))
            .collect();
        let step = linear::damped_step(&a, &g, MIN_LAMBDA, &free)?;
        let dx: Vec<f64> = self
            .x
            .iter()
            .zip(&step)
            .map(|(x, d)| (x + d).clamp(0.0, 1.0) - x)
            .collect();
        let quadratic: f64 = a
            .iter()
            .zip(&dx)
            .map(|(row, di)| di * linear::dot(row, &dx))
            .sum();
        Some(-(2.0 * linear::dot(&g, &dx) + quadratic))
    }

    /// Take the trial `(lambda, point)` whose evaluation `(cost, r)` lowered the objective;
    /// `columns` is the Jacobian at the current point, carried over to the trial.
    fn accept(&mut self, lambda: f64, point: Vec<f64>, cost: f64, r: Vec<f64>, columns: Columns) {
        let dx: Vec<f64> = point.iter().zip(&self.x).map(|(a, b)| a - b).collect();
        let dr: Vec<f64> = r.iter().zip(&self.r).map(|(a, b)| a - b).collect();
        let mut columns = columns;
        linear::broyden(&mut columns, &dx, &dr);
        let fall = (self.cost - cost) / self.cost.abs().max(f64::MIN_POSITIVE);
        let size = max_norm(&dx);
        self.x = point;
        self.cost = cost;
        self.r = r;
        self.columns = columns;
        self.exact = false;
        self.lambda = (lambda / TRIAL_SPREAD.sqrt()).max(MIN_LAMBDA);
        if fall < F_TOLERANCE {
            self.stop = Some(CONVERGED_OBJECTIVE);
        } else if size < X_TOLERANCE {
            self.stop = Some(CONVERGED_STEP);
        }
    }

    /// The words of the termination, with the parameters that move no residual.
    fn describe(&self, words: &str) -> String {
        let idle: Vec<String> = self
            .columns
            .iter()
            .enumerate()
            .filter(|(_, c)| c.iter().all(|v| *v == 0.0))
            .map(|(j, _)| format!("#{j}"))
            .collect();
        if idle.is_empty() || words == SINGULAR || words == START_FAILED {
            words.to_string()
        } else {
            format!(
                "{words} (singular Jacobian: parameter {} moves no residual)",
                idle.join(", ")
            )
        }
    }
}

fn max_norm(v: &[f64]) -> f64 {
    v.iter().fold(0.0, |m, x| m.max(x.abs()))
}

/// Evaluate `points` as one batch, each counted.
fn evaluate<O: Residuals>(
    problem: &mut Problem<O>,
    points: &[Vec<f64>],
) -> Result<Vec<(f64, Vec<f64>)>, Error> {
    let answers = problem.bulk_problem("cost_count", points.len(), |p| p.residuals(points))?;
    Ok(answers
        .into_iter()
        .map(|(cost, r)| {
            let cost = sanitize(cost);
            let failed = cost >= f64::MAX || r.iter().any(|v| !v.is_finite());
            (cost, if failed { Vec::new() } else { r })
        })
        .collect())
}

impl<O: Residuals> Solver<O, LmState> for LevenbergMarquardt {
    fn name(&self) -> &str {
        "Levenberg-Marquardt"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: LmState,
    ) -> Result<(LmState, Option<KV>), Error> {
        let steps = jacobian::steps(&self.x, self.step);
        let mut batch = vec![self.x.clone()];
        batch.extend(jacobian::points(&self.x, &steps));
        let mut answers = evaluate(problem, &batch)?;
        let around: Vec<Vec<f64>> = answers.drain(1..).map(|(_, r)| r).collect();
        let (cost, r) = answers.pop().expect("the start point");
        self.cost = cost;
        if r.is_empty() {
            self.stop = Some(START_FAILED);
        } else {
            self.columns = jacobian::columns(&r, &around, &steps);
            self.r = r;
            self.exact = true;
        }
        Ok((state.param(self.x.clone()).cost(self.cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: LmState,
    ) -> Result<(LmState, Option<KV>), Error> {
        let trials = match self.trials() {
            Some(trials) => trials,
            None if self.exact => {
                self.stop = Some(SINGULAR);
                return Ok((state.param(self.x.clone()).cost(self.cost), None));
            }
            None => Vec::new(),
        };
        if trials.is_empty() && self.exact {
            self.stop = Some(CONVERGED_STEP);
            return Ok((state.param(self.x.clone()).cost(self.cost), None));
        }
        let steps = jacobian::steps(&self.x, self.step);
        let mut batch: Vec<Vec<f64>> = trials.iter().map(|(_, p)| p.clone()).collect();
        if !self.exact {
            batch.extend(jacobian::points(&self.x, &steps));
        }
        let mut answers = evaluate(problem, &batch)?;
        let around: Vec<Vec<f64>> = answers.drain(trials.len()..).map(|(_, r)| r).collect();
        let exact = (!self.exact).then(|| jacobian::columns(&self.r, &around, &steps));
        let best = answers
            .iter()
            .enumerate()
            .filter(|(_, (cost, r))| !r.is_empty() && *cost < self.cost)
            .min_by(|a, b| a.1 .0.total_cmp(&b.1 .0))
            .map(|(i, _)| i);
        let were_exact = self.exact;
        match best {
            Some(i) => {
                let (lambda, point) = trials[i].clone();
                let (cost, r) = std::mem::take(&mut answers[i]);
                let columns = exact.unwrap_or_else(|| std::mem::take(&mut self.columns));
                self.accept(lambda, point, cost, r, columns);
            }
            None => {
                let largest = trials
                    .iter()
                    .map(|(_, p)| {
                        let dx: Vec<f64> = p.iter().zip(&self.x).map(|(a, b)| a - b).collect();
                        max_norm(&dx)
                    })
                    .fold(0.0, f64::max);
                match exact {
                    // Retry with the Jacobian at x itself.
                    Some(columns) => {
                        self.columns = columns;
                        self.exact = true;
                    }
                    None => self.lambda *= TRIAL_SPREAD * TRIAL_SPREAD,
                }
                // At the Jacobian of x itself, the best any step can do by the linear model
                // is below tolerance: x is the optimum up to the objective's own jitter
                // (the integrator's), which no damping would get past.
                let hopeless = self
                    .predicted_fall()
                    .is_some_and(|fall| fall < PREDICTED_TOLERANCE * self.cost.abs());
                if were_exact && largest < X_TOLERANCE {
                    self.stop = Some(CONVERGED_STEP);
                } else if hopeless {
                    self.stop = Some(CONVERGED_PREDICTED);
                } else if self.lambda > MAX_LAMBDA {
                    self.stop = Some(STALLED);
                }
            }
        }
        self.iterations += 1;
        if self.stop.is_none() && self.iterations >= self.max_iterations {
            self.stop = Some(ITERATION_LIMIT);
        }
        let kv = argmin::kv!("lambda" => self.lambda; "trials" => trials.len() as u64;);
        Ok((state.param(self.x.clone()).cost(self.cost), Some(kv)))
    }

    fn terminate(&mut self, _state: &LmState) -> TerminationStatus {
        match self.stop {
            None => TerminationStatus::NotTerminated,
            Some(words) => {
                TerminationStatus::Terminated(TerminationReason::SolverExit(self.describe(words)))
            }
        }
    }
}
