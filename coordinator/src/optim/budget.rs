//! An evaluation budget for any argmin solver.

use argmin::core::{Error, Problem, Solver, State, TerminationReason, TerminationStatus, KV};

/// The words of the budget's termination.
pub const BUDGET_USED: &str = "evaluation budget used";

/// Wraps a solver so that it stops at the first iteration boundary at which the problem has
/// been evaluated `max_evaluations` times or more.
pub struct Budgeted<S> {
    pub inner: S,
    pub max_evaluations: u64,
}

impl<O, I, S> Solver<O, I> for Budgeted<S>
where
    S: Solver<O, I>,
    I: State,
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
        TerminationStatus::NotTerminated
    }
}
