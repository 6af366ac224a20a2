//! The solver on test problems whose minima are known.

use super::*;
use crate::optim::test_problems::{Recorder, Rosenbrock, Sphere};
use argmin::core::{Executor, State};

/// What a run ended with.
struct Outcome {
    point: Vec<f64>,
    cost: f64,
    iterations: u64,
    evaluations: u64,
    termination: String,
    batches: Vec<usize>,
}

fn run<O: Residuals>(problem: O, start: Vec<f64>) -> Outcome {
    let recorder = Recorder::new(problem);
    let solver = LevenbergMarquardt::new(start).unwrap();
    let mut result = Executor::new(recorder, solver)
        .configure(|s| s.max_iters(10_000).counting(true))
        .run()
        .unwrap();
    let state = result.state();
    let termination = match state.get_termination_status() {
        TerminationStatus::Terminated(TerminationReason::SolverExit(why)) => why.clone(),
        other => format!("{other:?}"),
    };
    let outcome = Outcome {
        point: state.get_best_param().unwrap().clone(),
        cost: state.get_best_cost(),
        iterations: state.get_iter(),
        evaluations: state.get_func_counts()["cost_count"],
        termination,
        batches: Vec::new(),
    };
    let recorder = result.problem.take_problem().unwrap();
    let batches = recorder.batch_sizes.lock().unwrap().clone();
    Outcome { batches, ..outcome }
}

/// Residuals that are a function of the point, for one-off problems.
struct ResidualFn(fn(&[f64]) -> Vec<f64>);

impl Residuals for ResidualFn {
    fn residuals(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Error> {
        Ok(points
            .iter()
            .map(|p| {
                let r = (self.0)(p);
                (r.iter().map(|v| v * v).sum(), r)
            })
            .collect())
    }
}

#[test]
fn finds_the_rosenbrock_minimum_from_the_classic_start() {
    // (−1.2, 1) in Rosenbrock's own coordinates.
    let o = run(Rosenbrock, vec![0.2, 0.75]);
    println!(
        "{:?} cost {:e}: {} iterations, {} evaluations, {}",
        o.point, o.cost, o.iterations, o.evaluations, o.termination
    );
    assert!(o.termination.starts_with("converged"), "{}", o.termination);
    assert!(o.cost < 1e-20, "{}", o.cost);
    assert!((o.point[0] - 0.75).abs() < 1e-10 && (o.point[1] - 0.75).abs() < 1e-10);
    assert!(o.iterations <= 60, "{} iterations", o.iterations);
}

#[test]
fn every_iteration_is_one_batch_of_trials_and_differences() {
    let o = run(Rosenbrock, vec![0.2, 0.75]);
    // The start and its two differences, then one batch per iteration: at most three
    // trials and two differences.
    assert_eq!(o.batches.len() as u64, o.iterations + 1, "{:?}", o.batches);
    assert_eq!(o.batches[0], 3);
    assert!(
        o.batches[1..].iter().all(|&b| (1..=5).contains(&b)),
        "{:?}",
        o.batches
    );
    assert_eq!(o.batches.iter().sum::<usize>() as u64, o.evaluations);
}

#[test]
fn a_linear_least_squares_problem_takes_a_few_iterations() {
    // r = A x − b, solution (0.3, 0.6, 0.45) inside the box.
    fn linear(x: &[f64]) -> Vec<f64> {
        let a = [
            [1.0, 2.0, 0.0],
            [0.0, 1.0, -1.0],
            [3.0, 0.0, 1.0],
            [1.0, 1.0, 1.0],
        ];
        let solution = [0.3, 0.6, 0.45];
        a.iter()
            .map(|row| (0..3).map(|k| row[k] * (x[k] - solution[k])).sum())
            .collect()
    }
    let o = run(ResidualFn(linear), vec![0.9, 0.1, 0.9]);
    println!(
        "{:?}: {} iterations, {}",
        o.point, o.iterations, o.termination
    );
    for (x, s) in o.point.iter().zip([0.3, 0.6, 0.45]) {
        assert!((x - s).abs() < 1e-9, "{:?}", o.point);
    }
    assert!(o.iterations <= 6, "{} iterations", o.iterations);
}

#[test]
fn a_minimum_outside_the_box_ends_on_its_bound() {
    let o = run(
        Sphere {
            centre: vec![1.3, 0.4, -0.2],
        },
        vec![0.5, 0.5, 0.5],
    );
    assert_eq!(o.point[0], 1.0, "{:?}", o.point);
    assert_eq!(o.point[2], 0.0, "{:?}", o.point);
    assert!((o.point[1] - 0.4).abs() < 1e-9, "{:?}", o.point);
    assert!((o.cost - (0.09 + 0.04)).abs() < 1e-12, "{}", o.cost);
    assert!(o.termination.starts_with("converged"), "{}", o.termination);
}

#[test]
fn residuals_that_no_parameter_moves_stop_on_a_plateau() {
    let o = run(ResidualFn(|_| vec![1.0, 2.0]), vec![0.5, 0.5]);
    assert_eq!(o.termination, SINGULAR);
    assert_eq!(o.point, vec![0.5, 0.5]);
}

#[test]
fn a_parameter_without_influence_is_named_in_the_termination() {
    let o = run(
        ResidualFn(|x| vec![x[0] - 0.25, 2.0 * (x[0] - 0.25)]),
        vec![0.5, 0.5],
    );
    assert!((o.point[0] - 0.25).abs() < 1e-9, "{:?}", o.point);
    assert_eq!(o.point[1], 0.5);
    assert!(
        o.termination.starts_with("converged")
            && o.termination
                .ends_with("(singular Jacobian: parameter #1 moves no residual)"),
        "{}",
        o.termination
    );
}

#[test]
fn a_failed_start_stops_the_run() {
    struct Fails;
    impl Residuals for Fails {
        fn residuals(&self, points: &[Vec<f64>]) -> Result<Vec<(f64, Vec<f64>)>, Error> {
            Ok(points.iter().map(|_| (f64::MAX, Vec::new())).collect())
        }
    }
    let o = run(Fails, vec![0.5]);
    assert_eq!(o.termination, START_FAILED);
    assert_eq!(o.batches, vec![2]);
}

#[test]
fn rejects_a_start_outside_the_box() {
    assert!(LevenbergMarquardt::new(vec![]).is_err());
    assert!(LevenbergMarquardt::new(vec![1.5]).is_err());
}
