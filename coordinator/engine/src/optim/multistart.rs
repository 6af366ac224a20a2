//! Multistart: every method from every start point, run concurrently; minima clustered.
//!
//! Start points: the nominal point first, then points of a scrambled Sobol sequence
//! (Burley's Owen-scrambled Sobol, seeded by the campaign) so that extra starts cover the box
//! evenly. A run is one method from one start; all runs are independent and deterministic
//! for a given seed, so running them concurrently changes nothing but the wall time.
//!
//! I. M. Sobol', "On the distribution of points in a cube and the approximate evaluation of
//! integrals", USSR Comput. Math. Math. Phys. 7 (1967) 86–112; B. Burley, "Practical
//! Hash-based Owen Scrambling", JCGT 9(4) (2020).

use super::budget::Budgeted;
use super::budget::{Stall, BUDGET_USED, STALLED};
use super::problem::{Progress, RunLog, RunProblem};
use super::space::{self, UnitBox};
use super::{cma_es, differential_evolution, levenberg_marquardt, nelder_mead, powell};
use crate::campaign::Method;
use crate::evaluator::Evaluator;
use crate::objective::Objective;
use argmin::core::{
    Executor, IterState, PopulationState, Solver, State, TerminationReason, TerminationStatus,
};
use serde::Serialize;

/// Hard cap on iterations, far above what any budget allows; argmin needs one.
const MAX_ITERS: u64 = 1_000_000;

/// Start points in the unit box: the nominal point, then `starts − 1` Sobol points.
pub fn start_points(nominal_unit: &[f64], starts: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut points = vec![nominal_unit.to_vec()];
    let dim = nominal_unit.len() as u32;
    let scramble = (seed ^ (seed >> 32)) as u32;
    for i in 1..starts {
        points.push(
            (0..dim)
                .map(|d| f64::from(sobol_burley::sample(i as u32, d, scramble)))
                .collect(),
        );
    }
    points
}

/// One method from one start point.
#[derive(Debug, Clone)]
pub struct RunSpec {
    /// Position in the plan.
    pub index: usize,
    pub method: Method,
    pub start: usize,
    pub start_unit: Vec<f64>,
    pub seed: u64,
}

/// What a run found.
#[derive(Debug, Clone, Serialize)]
pub struct RunOutcome {
    pub method: Method,
    pub start: usize,
    /// Physical values of the free parameters at the start.
    pub start_point: Vec<f64>,
    /// Physical values at the best point the run saw.
    pub point: Vec<f64>,
    pub objective: f64,
    pub evaluations: usize,
    /// Batches of evaluations the run sent and waited for, one after another (see
    /// [`super::problem::RunLog::rounds`]).
    pub rounds: usize,
    pub iterations: u64,
    /// Why the run stopped: `converged: …` (on which tolerance), `budget`, `plateau` (no
    /// objective spread around any of its starts), `failures` (every simulation failed).
    pub termination: String,
    /// Times the run left a plateau for a fresh start point.
    pub restarts: usize,
    /// Whether the run found a minimum or stalled (plateau, failures).
    pub stop: Stop,
}

/// Whether a run ended at a minimum it found, or never found one to converge to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Stop {
    /// Converged, or out of budget while descending: its point is a candidate minimum.
    Minimum,
    /// No objective spread around any start of the run.
    Plateau,
    /// Every simulation of the run failed.
    Failures,
}

/// Every method × start of a campaign, in a fixed order.
pub fn plan(methods: &[Method], starts: &[Vec<f64>], seed: u64) -> Vec<RunSpec> {
    let mut runs = Vec::new();
    for &method in methods {
        for (start, unit) in starts.iter().enumerate() {
            runs.push(RunSpec {
                index: runs.len(),
                method,
                start,
                start_unit: unit.clone(),
                seed: seed
                    .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                    .wrapping_add(start as u64),
            });
        }
    }
    runs
}

/// Settings shared by the runs of a campaign.
pub struct RunContext<'a> {
    pub objective: &'a Objective,
    pub evaluator: &'a dyn Evaluator,
    pub space: &'a UnitBox,
    /// Objective at the nominal point: solver tolerances are relative to it.
    pub scale: f64,
    pub max_evaluations: usize,
    pub progress: &'a dyn Progress,
    /// How fresh points are drawn when a run restarts (see [`super::screening`]).
    pub screening: &'a [Option<f64>],
    /// Stop each run when its objective stops moving, before its budget is used.
    pub stall: Option<Stall>,
    /// Smallest population of CMA-ES (the search's `cma_population`).
    pub cma_population: Option<usize>,
}

/// Most runs in flight at once. Runs spend their time waiting for evaluations (on this
/// machine's cores or on remote workers), so they each get a thread, not a core: enough
/// concurrent batches to keep every worker busy.
pub const MAX_CONCURRENT_RUNS: usize = 64;

/// Rounds the runs of a plan take together, given each run's rounds in plan order: runs go
/// [`MAX_CONCURRENT_RUNS`] at a time ([`run_all`]), each group waiting for its longest run,
/// so the sum over groups of the group's most rounds. (With at most
/// [`MAX_CONCURRENT_RUNS`] runs: the longest run's rounds.)
pub fn plan_rounds(run_rounds: &[usize]) -> usize {
    run_rounds
        .chunks(MAX_CONCURRENT_RUNS)
        .map(|group| group.iter().copied().max().unwrap_or(0))
        .sum()
}

/// Run all `runs` concurrently; outcomes in the order of `runs`.
pub fn run_all(
    context: &RunContext,
    runs: &[RunSpec],
) -> Result<Vec<RunOutcome>, argmin::core::Error> {
    let mut outcomes = Vec::with_capacity(runs.len());
    for chunk in runs.chunks(MAX_CONCURRENT_RUNS) {
        let results: Vec<_> = std::thread::scope(|scope| {
            let handles: Vec<_> = chunk
                .iter()
                .map(|spec| scope.spawn(move || run_one(context, spec)))
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|panic| std::panic::resume_unwind(panic))
                })
                .collect()
        });
        for result in results {
            outcomes.push(result?);
        }
    }
    Ok(outcomes)
}

/// Run one method from one start.
pub fn run_one(context: &RunContext, spec: &RunSpec) -> Result<RunOutcome, argmin::core::Error> {
    // Levenberg–Marquardt reads the weighted residuals: its evaluations return them.
    let residual_objective =
        (spec.method == Method::LevenbergMarquardt).then(|| context.objective.with_residuals());
    let objective = residual_objective.as_ref().unwrap_or(context.objective);
    let mut problem = RunProblem::new(
        objective,
        context.evaluator,
        context.space,
        context.scale,
        context.progress,
    );
    problem.run = spec.index;
    let budget = context.max_evaluations as u64;
    let mut restarts = 0;
    let (log, iterations, termination) = match spec.method {
        Method::NelderMead => {
            let departure =
                nelder_mead::depart(&problem, &spec.start_unit, context.screening, spec.seed)?;
            restarts = departure.restarts;
            if departure.flat {
                (problem.take_log(), 0, Termination::Plateau)
            } else {
                let inner = nelder_mead::NelderMead::new(departure.simplex)?;
                execute(problem, Budgeted::new(inner, budget, context.stall), |s| s)?
            }
        }
        Method::Powell => {
            let inner = powell::Powell::new(spec.start_unit.clone())
                .with_initial_steps(space::initial_steps(&spec.start_unit))?;
            let start = spec.start_unit.clone();
            execute(problem, Budgeted::new(inner, budget, context.stall), |s| {
                s.param(start)
            })?
        }
        Method::DifferentialEvolution => {
            let inner = differential_evolution::DifferentialEvolution::new(
                spec.start_unit.clone(),
                spec.seed,
            );
            execute(problem, Budgeted::new(inner, budget, context.stall), |s| s)?
        }
        Method::LevenbergMarquardt => {
            let inner = levenberg_marquardt::LevenbergMarquardt::new(spec.start_unit.clone())?;
            execute(problem, Budgeted::new(inner, budget, context.stall), |s| s)?
        }
        Method::CmaEs => {
            let inner = cma_es::CmaEs::new(spec.start_unit.clone(), spec.seed).with_population(
                context.cma_population.unwrap_or_else(|| {
                    differential_evolution::default_population(spec.start_unit.len())
                }),
            );
            execute(problem, Budgeted::new(inner, budget, context.stall), |s| s)?
        }
    };
    let termination = if !log.best_objective.is_finite() || log.best_objective >= f64::MAX {
        Termination::Failures
    } else {
        termination
    };
    Ok(RunOutcome {
        method: spec.method,
        start: spec.start,
        start_point: context.space.to_physical(&spec.start_unit),
        point: log.best_point,
        objective: log.best_objective,
        evaluations: log.evaluations,
        rounds: log.rounds,
        iterations,
        stop: match &termination {
            Termination::Plateau => Stop::Plateau,
            Termination::Failures => Stop::Failures,
            Termination::Other(why) if why.starts_with(PLATEAU) => Stop::Plateau,
            _ => Stop::Minimum,
        },
        termination: termination.describe(spec.method),
        restarts,
    })
}

/// How the words of a solver's own termination begin when it found no slope to follow.
const PLATEAU: &str = "plateau:";

/// Why a run stopped.
enum Termination {
    /// The method's own convergence test held.
    Converged,
    /// The simplex shrank to a point before its objectives agreed.
    Collapsed,
    /// The evaluation budget was used up.
    Budget,
    /// The best objective stopped moving (a [`Stall`] rule).
    Stalled,
    /// No objective spread around any start point of the run.
    Plateau,
    /// Every simulation of the run failed.
    Failures,
    /// Anything else the solver said (its own words).
    Other(String),
}

impl Termination {
    fn from_status(status: &TerminationStatus) -> Self {
        match status {
            TerminationStatus::Terminated(TerminationReason::SolverConverged) => Self::Converged,
            TerminationStatus::Terminated(TerminationReason::SolverExit(why))
                if why == BUDGET_USED =>
            {
                Self::Budget
            }
            TerminationStatus::Terminated(TerminationReason::SolverExit(why)) if why == STALLED => {
                Self::Stalled
            }
            TerminationStatus::Terminated(TerminationReason::SolverExit(why))
                if why == nelder_mead::SIMPLEX_COLLAPSED =>
            {
                Self::Collapsed
            }
            TerminationStatus::Terminated(reason) => Self::Other(reason.to_string()),
            TerminationStatus::NotTerminated => Self::Other("not terminated".into()),
        }
    }

    /// Short, stable words for tables and `result.json`.
    fn describe(&self, method: Method) -> String {
        match self {
            Self::Converged => match method {
                Method::NelderMead => "converged: simplex objective spread below tolerance",
                Method::Powell => "converged: a sweep moved x and f below tolerance",
                Method::DifferentialEvolution => "converged: population spread below tolerance",
                Method::LevenbergMarquardt => levenberg_marquardt::CONVERGED_OBJECTIVE,
                Method::CmaEs => "converged: descents ended and restarts stopped improving",
            }
            .into(),
            Self::Collapsed => "converged: simplex diameter below tolerance".into(),
            Self::Budget => "budget: evaluation budget used".into(),
            Self::Stalled => "converged: objective stopped moving".into(),
            Self::Plateau => "plateau: no objective spread around any start".into(),
            Self::Failures => "failures: every simulation failed".into(),
            Self::Other(why) => why.clone(),
        }
    }
}

/// Run `solver` on `problem` to termination; the run's log, iterations and why it stopped.
fn execute<'a, S, I>(
    problem: RunProblem<'a>,
    solver: S,
    configure: impl FnOnce(I) -> I,
) -> Result<(RunLog, u64, Termination), argmin::core::Error>
where
    S: Solver<RunProblem<'a>, I>,
    I: State<Float = f64> + Capped,
{
    let mut result = Executor::new(problem, solver)
        .configure(|state| configure(state.capped(MAX_ITERS)))
        .run()?;
    let iterations = result.state().get_iter();
    let termination = Termination::from_status(result.state().get_termination_status());
    let log = result
        .problem
        .take_problem()
        .map(|p| p.take_log())
        .unwrap_or_default();
    Ok((log, iterations, termination))
}

/// The states of argmin that take an iteration cap and count evaluations (the evaluation
/// budget reads the counts, which argmin leaves empty unless asked to keep them).
pub trait Capped {
    fn capped(self, iters: u64) -> Self;
}

impl Capped for IterState<Vec<f64>, (), (), (), (), f64> {
    fn capped(self, iters: u64) -> Self {
        self.max_iters(iters).counting(true)
    }
}

impl Capped for PopulationState<Vec<f64>, f64> {
    fn capped(self, iters: u64) -> Self {
        self.max_iters(iters).counting(true)
    }
}

/// Runs whose optima coincide, or the runs that stalled the same way.
#[derive(Debug, Clone, Serialize)]
pub struct Cluster {
    /// Index (into the runs) of the cluster's best run.
    pub best_run: usize,
    pub objective: f64,
    pub point: Vec<f64>,
    /// Indices of every run in the cluster.
    pub runs: Vec<usize>,
    /// `Minimum`: runs whose best points coincide. `Plateau` / `Failures`: every run that
    /// stalled that way, wherever it stopped (their points are not minima).
    pub kind: Stop,
    /// Smallest and largest physical value of each parameter over the cluster's runs: a
    /// wide range at one objective is a valley the data do not pin down.
    pub extent: Vec<(f64, f64)>,
}

/// Objectives closer than this (relative) are one minimum wherever their points lie: the
/// parameters that differ between them do not change the fit (a joint held still by any
/// friction above its breakaway, say), so the runs found one valley, not many minima.
pub const EQUAL_OBJECTIVE: f64 = 1e-7;

/// Group runs whose best points lie within `radius` of each other in the unit box
/// (max-norm), or whose objectives agree within [`EQUAL_OBJECTIVE`], best cluster first.
/// Runs that stalled on a plateau form one cluster, and runs whose simulations all failed
/// another: they found no minimum to tell apart.
pub fn cluster(outcomes: &[RunOutcome], space: &UnitBox, radius: f64) -> Vec<Cluster> {
    let mut order: Vec<usize> = (0..outcomes.len()).collect();
    order.sort_by(|&a, &b| outcomes[a].objective.total_cmp(&outcomes[b].objective));
    let mut clusters: Vec<(Vec<f64>, Cluster)> = Vec::new();
    for i in order {
        let outcome = &outcomes[i];
        if outcome.point.is_empty() {
            continue;
        }
        let u = space.to_unit(&outcome.point);
        let home = clusters.iter_mut().find(|(centre, c)| {
            c.kind == outcome.stop
                && (outcome.stop != Stop::Minimum
                    || centre.iter().zip(&u).all(|(a, b)| (a - b).abs() <= radius)
                    || (outcome.objective - c.objective).abs()
                        <= EQUAL_OBJECTIVE * c.objective.abs())
        });
        match home {
            Some((_, c)) => {
                c.runs.push(i);
                for ((lo, hi), &v) in c.extent.iter_mut().zip(&outcome.point) {
                    *lo = lo.min(v);
                    *hi = hi.max(v);
                }
            }
            None => clusters.push((
                u,
                Cluster {
                    best_run: i,
                    objective: outcome.objective,
                    point: outcome.point.clone(),
                    runs: vec![i],
                    kind: outcome.stop,
                    extent: outcome.point.iter().map(|&v| (v, v)).collect(),
                },
            )),
        }
    }
    clusters.into_iter().map(|(_, c)| c).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::campaign::{FreeParameter, Scale};

    fn run(point: [f64; 2], objective: f64, stop: Stop) -> RunOutcome {
        RunOutcome {
            method: Method::NelderMead,
            start: 0,
            start_point: vec![0.5, 0.5],
            point: point.to_vec(),
            objective,
            evaluations: 10,
            rounds: 4,
            iterations: 3,
            termination: String::new(),
            restarts: 0,
            stop,
        }
    }

    fn unit_square() -> UnitBox {
        let free = |index| FreeParameter {
            index,
            name: format!("p{index}"),
            nominal: 0.5,
            min: 0.0,
            max: 1.0,
            effect: false,
            scale: Scale::Lin,
            experiment: None,
        };
        UnitBox::new(&[free(0), free(1)])
    }

    #[test]
    fn a_plans_rounds_are_its_longest_runs_per_group_of_concurrent_runs() {
        assert_eq!(plan_rounds(&[]), 0);
        assert_eq!(plan_rounds(&[3, 9, 4]), 9);
        let mut many = vec![1; MAX_CONCURRENT_RUNS + 2];
        many[5] = 7;
        many[MAX_CONCURRENT_RUNS + 1] = 4;
        assert_eq!(plan_rounds(&many), 7 + 4);
    }

    #[test]
    fn runs_stalled_on_a_plateau_form_one_cluster_wherever_they_stopped() {
        let runs = vec![
            run([0.30, 0.30], 1.0, Stop::Minimum),
            run([0.9, 0.1], 50.0, Stop::Plateau),
            run([0.30, 0.3000001], 1.0 + 1e-9, Stop::Minimum),
            run([0.1, 0.9], 50.0, Stop::Plateau),
            run([0.5, 0.5], 50.0, Stop::Plateau),
            run([0.7, 0.7], 2.0, Stop::Minimum),
            run([0.2, 0.8], f64::MAX, Stop::Failures),
            // A valley: one objective along a line of the first parameter.
            run([0.2, 0.6], 3.0, Stop::Minimum),
            run([0.8, 0.6], 3.0 * (1.0 + 1e-9), Stop::Minimum),
        ];
        let clusters = cluster(&runs, &unit_square(), 1e-3);
        let summary: Vec<(Stop, Vec<usize>)> =
            clusters.iter().map(|c| (c.kind, c.runs.clone())).collect();
        assert_eq!(
            summary,
            vec![
                (Stop::Minimum, vec![0, 2]),
                (Stop::Minimum, vec![5]),
                (Stop::Minimum, vec![7, 8]),
                (Stop::Plateau, vec![1, 3, 4]),
                (Stop::Failures, vec![6]),
            ]
        );
        assert_eq!(clusters[0].best_run, 0);
        assert_eq!(clusters[2].extent, vec![(0.2, 0.8), (0.6, 0.6)]);
    }
}
