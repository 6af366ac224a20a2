//! Nelder–Mead on the unit box, as an argmin [`Solver`].
//!
//! J. A. Nelder, R. Mead, "A simplex method for function minimization", The Computer
//! Journal 7 (1965) 308–313, with the coefficients of Lagarias et al. (reflection 1,
//! expansion 2, contraction ½, shrink ½): J. C. Lagarias, J. A. Reeds, M. H. Wright,
//! P. E. Wright, "Convergence properties of the Nelder–Mead simplex method in low
//! dimensions", SIAM J. Optim. 9 (1998) 112–147.
//!
//! One iteration reflects the worst vertex through the centroid of the others and then
//! expands, contracts (outside or inside) or, when no trial point beats the worst vertex,
//! shrinks every vertex towards the best. The vertices of a shrink do not depend on each
//! other, so they are evaluated as **one batch** ([`Problem::bulk_cost`]), as is the initial
//! simplex: on a cluster each is one round trip, not `n`. Reflection, expansion and
//! contraction each depend on the previous result and are evaluated one at a time.
//!
//! Points may leave `[0, 1]^n`: the unit box folds them back inside
//! ([`super::space::UnitBox::to_physical`]), so the search sees a continuous objective.
//!
//! **Termination**: *converged* when the standard deviation of the (scaled) objectives over
//! the simplex falls below [`SD_TOLERANCE`], or when the simplex has collapsed to a diameter
//! below [`X_TOLERANCE`] (max-norm, unit box) around its best vertex. A simplex that never
//! had objective spread does not get here: [`departure`] moves it first.

mod departure;

pub use departure::{depart, initial_simplex, is_flat, Departure, FLAT_SPREAD};

use super::{invalid, sanitize};
use argmin::core::{
    CostFunction, Error, IterState, Problem, Solver, TerminationReason, TerminationStatus, KV,
};

/// Convergence: standard deviation of the (scaled) costs over the simplex.
pub const SD_TOLERANCE: f64 = 1e-12;

/// Convergence: largest distance (max-norm, unit box) of a vertex from the best one.
pub const X_TOLERANCE: f64 = 1e-10;

/// The termination words when the simplex collapsed before its costs agreed.
pub const SIMPLEX_COLLAPSED: &str = "simplex diameter below tolerance";

/// The state of argmin's iteration for this solver.
pub type NmState = IterState<Vec<f64>, (), (), (), (), f64>;

const REFLECTION: f64 = 1.0;
const EXPANSION: f64 = 2.0;
const CONTRACTION: f64 = 0.5;
const SHRINK: f64 = 0.5;

/// Nelder–Mead from a given initial simplex of `n + 1` vertices in `n` dimensions.
#[derive(Debug, Clone)]
pub struct NelderMead {
    /// Vertices and their costs, best first once evaluated.
    vertices: Vec<(Vec<f64>, f64)>,
    sd_tolerance: f64,
    x_tolerance: f64,
    /// Shrinks done so far.
    shrinks: u64,
}

/// What one iteration did to the simplex.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Step {
    Reflection,
    Expansion,
    ContractionOutside,
    ContractionInside,
    Shrink,
}

impl NelderMead {
    pub fn new(simplex: Vec<Vec<f64>>) -> Result<Self, Error> {
        let n = simplex.first().map_or(0, Vec::len);
        if n == 0 || simplex.len() != n + 1 || simplex.iter().any(|v| v.len() != n) {
            return Err(invalid(
                "`Nelder-Mead`: the initial simplex needs n + 1 vertices of n > 0 coordinates.",
            ));
        }
        if simplex.iter().flatten().any(|v| !v.is_finite()) {
            return Err(invalid("`Nelder-Mead`: the initial simplex is not finite."));
        }
        Ok(Self {
            vertices: simplex.into_iter().map(|v| (v, f64::NAN)).collect(),
            sd_tolerance: SD_TOLERANCE,
            x_tolerance: X_TOLERANCE,
            shrinks: 0,
        })
    }

    /// How many shrink steps the run took (each one batch of `n` evaluations).
    pub fn shrinks(&self) -> u64 {
        self.shrinks
    }

    fn sort(&mut self) {
        self.vertices.sort_by(|a, b| a.1.total_cmp(&b.1));
    }

    /// Centroid of every vertex but the worst.
    fn centroid(&self) -> Vec<f64> {
        let n = self.vertices.len() - 1;
        let mut c = vec![0.0; n];
        for (v, _) in &self.vertices[..n] {
            for (ci, vi) in c.iter_mut().zip(v) {
                *ci += vi;
            }
        }
        c.iter_mut().for_each(|ci| *ci /= n as f64);
        c
    }

    /// Standard deviation of the costs over the simplex; infinite while any vertex failed.
    fn cost_spread(&self) -> f64 {
        let costs: Vec<f64> = self.vertices.iter().map(|(_, c)| *c).collect();
        if costs.iter().any(|&c| c >= f64::MAX || !c.is_finite()) {
            return f64::INFINITY;
        }
        let n = costs.len() as f64;
        let mean = costs.iter().sum::<f64>() / n;
        (costs.iter().map(|c| (c - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    }

    /// Largest max-norm distance of a vertex from the best.
    fn diameter(&self) -> f64 {
        let best = &self.vertices[0].0;
        self.vertices[1..]
            .iter()
            .flat_map(|(v, _)| v.iter().zip(best).map(|(a, b)| (a - b).abs()))
            .fold(0.0, f64::max)
    }
}

/// `from + t (to − from)`.
fn along(from: &[f64], to: &[f64], t: f64) -> Vec<f64> {
    from.iter().zip(to).map(|(a, b)| a + t * (b - a)).collect()
}

impl<O> Solver<O, NmState> for NelderMead
where
    O: CostFunction<Param = Vec<f64>, Output = f64>,
{
    fn name(&self) -> &str {
        "Nelder-Mead"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: NmState,
    ) -> Result<(NmState, Option<KV>), Error> {
        let points: Vec<Vec<f64>> = self.vertices.iter().map(|(v, _)| v.clone()).collect();
        let costs = problem.bulk_cost(&points)?;
        for ((_, c), cost) in self.vertices.iter_mut().zip(costs) {
            *c = sanitize(cost);
        }
        self.sort();
        let (best, cost) = self.vertices[0].clone();
        Ok((state.param(best).cost(cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        state: NmState,
    ) -> Result<(NmState, Option<KV>), Error> {
        let n = self.vertices.len() - 1;
        let centroid = self.centroid();
        let best = self.vertices[0].1;
        let second_worst = self.vertices[n - 1].1;
        let (worst_point, worst) = self.vertices[n].clone();

        let reflected = along(&centroid, &worst_point, -REFLECTION);
        let fr = sanitize(problem.cost(&reflected)?);
        let step = if fr < best {
            let expanded = along(&centroid, &reflected, EXPANSION);
            let fe = sanitize(problem.cost(&expanded)?);
            self.vertices[n] = if fe < fr {
                (expanded, fe)
            } else {
                (reflected, fr)
            };
            Step::Expansion
        } else if fr < second_worst {
            self.vertices[n] = (reflected, fr);
            Step::Reflection
        } else if fr < worst {
            let contracted = along(&centroid, &reflected, CONTRACTION);
            let fc = sanitize(problem.cost(&contracted)?);
            if fc <= fr {
                self.vertices[n] = (contracted, fc);
                Step::ContractionOutside
            } else {
                Step::Shrink
            }
        } else {
            let contracted = along(&centroid, &worst_point, CONTRACTION);
            let fc = sanitize(problem.cost(&contracted)?);
            if fc < worst {
                self.vertices[n] = (contracted, fc);
                Step::ContractionInside
            } else {
                Step::Shrink
            }
        };
        if step == Step::Shrink {
            let best_point = self.vertices[0].0.clone();
            let shrunk: Vec<Vec<f64>> = self.vertices[1..]
                .iter()
                .map(|(v, _)| along(&best_point, v, SHRINK))
                .collect();
            let costs = problem.bulk_cost(&shrunk)?;
            for ((vertex, point), cost) in self.vertices[1..].iter_mut().zip(shrunk).zip(costs) {
                *vertex = (point, sanitize(cost));
            }
            self.shrinks += 1;
        }
        self.sort();
        let (best, cost) = self.vertices[0].clone();
        Ok((
            state.param(best).cost(cost),
            Some(argmin::kv!("step" => format!("{step:?}");)),
        ))
    }

    fn terminate(&mut self, _state: &NmState) -> TerminationStatus {
        if self.cost_spread() < self.sd_tolerance {
            return TerminationStatus::Terminated(TerminationReason::SolverConverged);
        }
        if self.diameter() < self.x_tolerance {
            return TerminationStatus::Terminated(TerminationReason::SolverExit(
                SIMPLEX_COLLAPSED.into(),
            ));
        }
        TerminationStatus::NotTerminated
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use argmin::core::{Executor, State};
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A cost function (the Rosenbrock function unless said), counting batches and single
    /// evaluations.
    struct Counted {
        f: fn(&[f64]) -> f64,
        batches: AtomicUsize,
        batch_sizes: std::sync::Mutex<Vec<usize>>,
    }

    fn rosenbrock(x: &[f64]) -> f64 {
        // Shifted into the unit box: minimum 0 at (0.5, 0.5).
        let (a, b) = (2.0 * x[0], 2.0 * x[1]);
        (1.0 - a).powi(2) + 100.0 * (b - a * a).powi(2)
    }

    impl CostFunction for Counted {
        type Param = Vec<f64>;
        type Output = f64;
        fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
            self.batch_sizes.lock().unwrap().push(1);
            Ok((self.f)(x))
        }
        fn bulk_cost<P>(&self, params: &[P]) -> Result<Vec<f64>, Error>
        where
            P: std::borrow::Borrow<Vec<f64>> + argmin::core::SyncAlias,
            f64: argmin::core::SendAlias,
            Self: argmin::core::SyncAlias,
        {
            self.batches.fetch_add(1, Ordering::Relaxed);
            self.batch_sizes.lock().unwrap().push(params.len());
            Ok(params.iter().map(|p| (self.f)(p.borrow())).collect())
        }
    }

    fn run(simplex: Vec<Vec<f64>>) -> (Vec<f64>, f64, u64, Counted) {
        let problem = Counted {
            f: rosenbrock,
            batches: AtomicUsize::new(0),
            batch_sizes: Default::default(),
        };
        let solver = NelderMead::new(simplex).unwrap();
        let mut result = Executor::new(problem, solver)
            .configure(|s| s.max_iters(10_000).counting(true))
            .run()
            .unwrap();
        let state = result.state();
        let best = state.get_best_param().unwrap().clone();
        let cost = state.get_best_cost();
        let evals = state.get_func_counts()["cost_count"];
        let problem = result.problem.take_problem().unwrap();
        (best, cost, evals, problem)
    }

    #[test]
    fn finds_the_rosenbrock_minimum() {
        let (best, cost, _, _) = run(vec![vec![0.1, 0.9], vec![0.15, 0.9], vec![0.1, 0.95]]);
        assert!(cost < 1e-10, "{cost}");
        assert!(
            (best[0] - 0.5).abs() < 1e-5 && (best[1] - 0.5).abs() < 1e-5,
            "{best:?}"
        );
    }

    #[test]
    fn shrinks_and_the_initial_simplex_are_single_batches() {
        // A bowl in a flat plateau: only the first vertex lies in the bowl, so no reflection
        // or contraction beats the worst vertex and the search shrinks until the simplex is
        // in the bowl, then descends it with single points.
        fn well(x: &[f64]) -> f64 {
            let r2: f64 = x.iter().map(|v| (v - 0.3).powi(2)).sum();
            if r2 < 0.1f64.powi(2) {
                r2
            } else {
                1.0
            }
        }
        let problem_simplex = vec![
            vec![0.32, 0.3, 0.3],
            vec![0.8, 0.3, 0.3],
            vec![0.32, 0.8, 0.3],
            vec![0.32, 0.3, 0.8],
        ];
        let solver = NelderMead::new(problem_simplex.clone()).unwrap();
        let problem = Counted {
            f: well,
            batches: AtomicUsize::new(0),
            batch_sizes: Default::default(),
        };
        let mut result = Executor::new(problem, solver)
            .configure(|s| s.max_iters(10_000).counting(true))
            .run()
            .unwrap();
        let shrinks = result.solver.shrinks() as usize;
        let problem = result.problem.take_problem().unwrap();
        let sizes = problem.batch_sizes.lock().unwrap().clone();
        // The first evaluation is the whole simplex; every other batch is a shrink of n.
        assert_eq!(sizes[0], 4);
        let shrink_batches = sizes[1..].iter().filter(|&&s| s > 1).count();
        assert!(shrinks >= 1, "the search never shrank: {sizes:?}");
        assert_eq!(shrink_batches, shrinks, "{sizes:?}");
        assert!(
            sizes.contains(&1),
            "the search never left shrinking: {sizes:?}"
        );
        assert!(sizes[1..].iter().all(|&s| s == 1 || s == 3), "{sizes:?}");
        assert_eq!(problem.batches.load(Ordering::Relaxed), shrink_batches + 1);
        let evals = result.state().get_func_counts()["cost_count"] as usize;
        assert_eq!(evals, sizes.iter().sum::<usize>());
    }

    #[test]
    fn a_shrink_batches_its_vertices() {
        // f is 0 at the best vertex and 1 everywhere else: neither the reflection nor the
        // inside contraction beats the worst vertex, so the first iteration must shrink.
        fn spike(x: &[f64]) -> f64 {
            if x == [0.3, 0.3] {
                0.0
            } else {
                1.0
            }
        }
        struct Spike(std::sync::Mutex<Vec<usize>>);
        impl CostFunction for Spike {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
                self.0.lock().unwrap().push(1);
                Ok(spike(x))
            }
            fn bulk_cost<P>(&self, params: &[P]) -> Result<Vec<f64>, Error>
            where
                P: std::borrow::Borrow<Vec<f64>> + argmin::core::SyncAlias,
                f64: argmin::core::SendAlias,
                Self: argmin::core::SyncAlias,
            {
                self.0.lock().unwrap().push(params.len());
                Ok(params.iter().map(|p| spike(p.borrow())).collect())
            }
        }
        let simplex = vec![vec![0.3, 0.3], vec![0.5, 0.3], vec![0.3, 0.5]];
        let mut solver = NelderMead::new(simplex).unwrap();
        let mut problem = Problem::new(Spike(Default::default()));
        let (state, _) = solver.init(&mut problem, NmState::new()).unwrap();
        let _ = solver.next_iter(&mut problem, state).unwrap();
        assert_eq!(solver.shrinks(), 1);
        assert_eq!(solver.vertices[0].0, vec![0.3, 0.3]);
        assert!(solver.diameter() <= 0.1 + 1e-15);
        let sizes = problem.take_problem().unwrap().0.into_inner().unwrap();
        // The simplex, the reflection, the inside contraction, then both shrunk vertices.
        assert_eq!(sizes, vec![3, 1, 1, 2]);
    }

    #[test]
    fn a_collapsed_simplex_stops_with_its_own_reason() {
        let mut solver = NelderMead::new(vec![vec![0.5], vec![0.5 + 1e-12]]).unwrap();
        solver.vertices[0].1 = 0.0;
        solver.vertices[1].1 = 1.0;
        let status = Solver::<Counted, NmState>::terminate(&mut solver, &NmState::new());
        assert_eq!(
            status,
            TerminationStatus::Terminated(TerminationReason::SolverExit(SIMPLEX_COLLAPSED.into()))
        );
    }

    #[test]
    fn rejects_a_malformed_simplex() {
        assert!(NelderMead::new(vec![]).is_err());
        assert!(NelderMead::new(vec![vec![0.1, 0.2], vec![0.3, 0.4]]).is_err());
        assert!(NelderMead::new(vec![vec![f64::NAN], vec![0.3]]).is_err());
    }

    #[test]
    fn counts_every_evaluation() {
        let (_, _, evals, problem) = run(vec![vec![0.1, 0.9], vec![0.15, 0.9], vec![0.1, 0.95]]);
        let sizes = problem.batch_sizes.lock().unwrap();
        assert_eq!(evals as usize, sizes.iter().sum::<usize>());
    }
}
