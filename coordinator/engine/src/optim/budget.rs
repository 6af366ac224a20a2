//! An evaluation budget for any argmin solver.

use argmin::core::{Error, Problem, Solver, State, TerminationReason, TerminationStatus, KV};

/// The words of the budget's termination.
pub const BUDGET_USED: &str = "evaluation budget used";

/// The words of a stall's termination.
pub const STALLED: &str = "objective stopped moving";

pub use crate::campaign::Stall;

/// Wraps a solver so that it stops at the first iteration boundary at which the problem has
/// been evaluated `max_evaluations` times or more, or, with a [`Stall`] rule, at which its
/// best objective has stopped moving.
pub struct Budgeted<S> {
    pub inner: S,
    pub max_evaluations: u64,
    pub stall: Option<Stall>,
    /// The best objective when it last moved by more than the stall's share, and the
    /// evaluations used then.
    pub moved: Option<(f64, u64)>,
}

impl<S> Budgeted<S> {
    pub fn new(inner: S, max_evaluations: u64, stall: Option<Stall>) -> Self {
        Self {
            inner,
            max_evaluations,
            stall,
            moved: None,
        }
    }
}

impl<O, I, S> Solver<O, I> for Budgeted<S>
where
    S: Solver<O, I>,
    I: State<Float = f64>,
{
    fn name(&self) -> &str {
        self.inner.name()
    }

    fn init(&mut self, problem: &mut Problem<O>, state: I) -> Result<(I, Option<KV>), Error> {
        self.inner.init(problem, state)
    }

    fn next_iter(&mut self, problem: &mut Problem<O>, state: I) -> Result<(I, Option<KV>), Error> {
        self.inner.next_iter(problem, state)
    }

    fn terminate(&mut self, state: &I) -> TerminationStatus {
        let status = self.inner.terminate(state);
        if status.terminated() {
            return status;
        }
        let used = state
            .get_func_counts()
            .get("cost_count")
            .copied()
            .unwrap_or(0);
        if used >= self.max_evaluations {
            return TerminationStatus::Terminated(TerminationReason::SolverExit(
                BUDGET_USED.into(),
            ));
        }
        if let Some(stall) = self.stall {
            let best = state.get_best_cost();
            if best.is_finite() {
                let moved = match self.moved {
                    Some((last, _)) => best < last - stall.relative * last.abs(),
                    None => true,
                };
                if moved {
                    self.moved = Some((best, used));
                }
            }
            if let Some((_, at)) = self.moved {
                if used >= at + stall.window {
                    return TerminationStatus::Terminated(TerminationReason::SolverExit(
                        STALLED.into(),
                    ));
                }
            }
        }
        TerminationStatus::NotTerminated
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::nelder_mead::NelderMead;
    use crate::optim::test_problems::Sphere;
    use argmin::core::Executor;

    /// Nelder–Mead on a bowl with a roughness of 10⁻⁷ at every scale, so that its own
    /// tolerances are met late: run to its budget (or its simplex's collapse), and with a
    /// stall rule stopped once the objective stops moving, near the same minimum.
    fn run(stall: Option<Stall>) -> (f64, u64, TerminationStatus) {
        struct Floored(Sphere);
        impl argmin::core::CostFunction for Floored {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
                // A deterministic roughness at every scale, 10⁻⁷ high.
                let rough = (1e7 * (x[0] + 2.0 * x[1])).sin() * 43_758.547;
                Ok(1.0 + self.0.cost(x)? + 1e-7 * (rough - rough.floor()))
            }
        }
        let simplex = vec![vec![0.1, 0.1], vec![0.3, 0.1], vec![0.1, 0.3]];
        let solver = Budgeted::new(NelderMead::new(simplex).unwrap(), 2_000, stall);
        let problem = Floored(Sphere {
            centre: vec![0.6, 0.7],
        });
        let result = Executor::new(problem, solver)
            .configure(|s| s.max_iters(100_000).counting(true))
            .run()
            .unwrap();
        let state = result.state();
        (
            state.get_best_cost(),
            state.get_func_counts()["cost_count"],
            state.get_termination_status().clone(),
        )
    }

    #[test]
    fn a_stall_rule_stops_a_run_once_its_objective_stops_moving() {
        let (full, used_full, _) = run(None);
        let (stalled, used, status) = run(Some(Stall {
            window: 30,
            relative: 1e-6,
        }));
        assert_eq!(
            status,
            TerminationStatus::Terminated(TerminationReason::SolverExit(STALLED.into()))
        );
        println!("{used} of {used_full} evaluations, {stalled} against {full}");
        assert!(used < used_full / 2, "{used} of {used_full} evaluations");
        // Within ten times the stall's share of what the full run reaches.
        assert!(stalled - full <= 1e-5 * full, "{stalled} vs {full}");
    }
}
