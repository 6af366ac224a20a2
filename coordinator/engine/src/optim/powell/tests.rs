//! Powell's method on the test problems: convergence, bounds, batching, determinism and
//! errors.

use super::*;
use crate::optim::test_problems::{Recorder, Rosenbrock, Sphere};
use argmin::core::{Executor, State};

fn run<O>(problem: O, solver: Powell, max_iters: u64) -> (Vec<f64>, f64, u64, u64)
where
    O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
{
    let res = Executor::new(problem, solver)
        .configure(|s| s.max_iters(max_iters))
        .run()
        .unwrap();
    let evals = res.problem.counts["cost_count"];
    let state = res.state();
    assert_eq!(
        state.get_termination_reason(),
        Some(&TerminationReason::SolverConverged)
    );
    (
        state.get_best_param().unwrap().clone(),
        state.get_best_cost(),
        state.get_iter(),
        evals,
    )
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
    let (x, f, sweeps, evals) = run(problem, Powell::new(vec![0.9, 0.1]), 100);
    println!("Powell sphere 2-D: {evals} evaluations, {sweeps} sweeps, f = {f:e}, x = {x:?}");
    assert_close(&x, &centre, 1e-6);
    assert!(evals <= 100, "{evals} evaluations");
}

#[test]
fn sphere_5d_converges() {
    let centre = vec![0.1, 0.2, 0.5, 0.7, 0.95];
    let problem = Sphere {
        centre: centre.clone(),
    };
    let (x, f, sweeps, evals) = run(problem, Powell::new(vec![0.5; 5]), 100);
    println!("Powell sphere 5-D: {evals} evaluations, {sweeps} sweeps, f = {f:e}");
    assert_close(&x, &centre, 1e-6);
}

#[test]
fn rosenbrock_2d_converges() {
    // Start at (-1.2, 1) in the original coordinates.
    let (x, f, sweeps, evals) = run(Rosenbrock, Powell::new(vec![0.2, 0.75]), 500);
    println!("Powell Rosenbrock 2-D: {evals} evaluations, {sweeps} sweeps, f = {f:e}, x = {x:?}");
    assert_close(&x, &[0.75, 0.75], 1e-6);
}

#[test]
fn minimum_on_bounds() {
    // Unconstrained minimum at (1.3, -0.2, 0.4); in the box (1, 0, 0.4).
    let problem = Sphere {
        centre: vec![1.3, -0.2, 0.4],
    };
    let (x, _, _, evals) = run(problem, Powell::new(vec![0.5, 0.5, 0.5]), 100);
    println!("Powell minimum on bounds: {evals} evaluations, x = {x:?}");
    assert_eq!(x[0], 1.0);
    assert_eq!(x[1], 0.0);
    assert!((x[2] - 0.4).abs() < 1e-6);
}

#[test]
fn tilted_valley_into_a_corner() {
    // Correlated quadratic whose unconstrained minimum lies outside the box;
    // the constrained minimum is on the face x0 = 1.
    struct Tilted;
    impl CostFunction for Tilted {
        type Param = Vec<f64>;
        type Output = f64;
        fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
            let (a, b) = (x[0] - 1.5, x[1] - 0.2);
            Ok(a * a + 1.8 * a * b + b * b)
        }
    }
    let (x, _, _, _) = run(Tilted, Powell::new(vec![0.1, 0.9]), 200);
    // On x0 = 1: d/dx1 = 1.8 a + 2 b = 0 with a = -0.5 gives x1 = 0.65.
    assert_eq!(x[0], 1.0);
    assert!((x[1] - 0.65).abs() < 1e-6, "{x:?}");
}

#[test]
fn deterministic() {
    let a = run(Rosenbrock, Powell::new(vec![0.2, 0.75]), 500);
    let b = run(Rosenbrock, Powell::new(vec![0.2, 0.75]), 500);
    assert_eq!(a.0, b.0);
    assert_eq!(a.1.to_bits(), b.1.to_bits());
    assert_eq!(a.3, b.3);
}

#[test]
fn stays_in_box_and_batches() {
    let problem = Recorder::new(Rosenbrock);
    let res = Executor::new(problem, Powell::new(vec![0.05, 0.95]))
        .configure(|s| s.max_iters(500))
        .run()
        .unwrap();
    let evals = res.problem.counts["cost_count"] as usize;
    let recorder = res.problem.problem.as_ref().unwrap();
    let points = recorder.points.lock().unwrap();
    let batches = recorder.batch_sizes.lock().unwrap();
    let singles = *recorder.single_calls.lock().unwrap();
    assert_eq!(points.len(), evals);
    assert!(points
        .iter()
        .all(|p| p.iter().all(|v| (0.0..=1.0).contains(v))));
    let batched: usize = batches.iter().sum();
    assert_eq!(batched + singles, evals);
    println!(
        "Powell batching: {evals} evaluations, {batched} in {} batches, {singles} single",
        batches.len()
    );
    assert!(!batches.is_empty());
    assert!(batches.iter().all(|&b| b >= 1));
    assert!(batched * 3 >= evals, "too few batched evaluations");
}

#[test]
fn nan_costs_are_avoided() {
    // NaN outside a disc around the start: the solver must stay inside it.
    struct Holey;
    impl CostFunction for Holey {
        type Param = Vec<f64>;
        type Output = f64;
        fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
            if (x[0] - 0.5).powi(2) + (x[1] - 0.5).powi(2) > 0.16 {
                Ok(f64::NAN)
            } else {
                Ok((x[0] - 0.6).powi(2) + (x[1] - 0.45).powi(2))
            }
        }
    }
    let (x, _, _, _) = run(Holey, Powell::new(vec![0.5, 0.5]), 100);
    assert_close(&x, &[0.6, 0.45], 1e-6);
}

#[test]
fn errors_propagate() {
    struct Failing;
    impl CostFunction for Failing {
        type Param = Vec<f64>;
        type Output = f64;
        fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
            if x[0] > 0.6 {
                Err(Error::msg("simulation failed"))
            } else {
                Ok(x[0])
            }
        }
    }
    let res = Executor::new(Failing, Powell::new(vec![0.5]))
        .configure(|s| s.max_iters(10))
        .run();
    assert!(res.is_err());
}

#[test]
fn invalid_settings_are_rejected() {
    assert!(Powell::new(vec![0.5]).with_xtol(0.0).is_err());
    assert!(Powell::new(vec![0.5]).with_xtol(f64::NAN).is_err());
    assert!(Powell::new(vec![0.5]).with_ftol(-1.0, 0.0).is_err());
    assert!(Powell::new(vec![0.5]).with_bracket_points(1).is_err());
    assert!(Powell::new(vec![0.5]).with_initial_step(0.0).is_err());
    assert!(Powell::new(vec![0.5]).with_initial_step(1.5).is_err());
    assert!(Powell::new(vec![0.5])
        .with_xtol(1e-6)
        .and_then(|p| p.with_ftol(1e-8, 0.0))
        .and_then(|p| p.with_bracket_points(6))
        .and_then(|p| p.with_initial_step(0.1))
        .is_ok());
    let outside = Executor::new(
        Sphere {
            centre: vec![0.5, 0.5],
        },
        Powell::new(vec![0.5, 1.2]),
    )
    .configure(|s| s.max_iters(10))
    .run();
    assert!(outside.is_err());
}

#[test]
fn rosenbrock_2d_from_many_starts() {
    let mut total = 0;
    for i in 0..7 {
        for j in 0..7 {
            let start = vec![0.05 + 0.15 * i as f64, 0.05 + 0.15 * j as f64];
            let (x, _, _, evals) = run(Rosenbrock, Powell::new(start), 1000);
            assert_close(&x, &[0.75, 0.75], 1e-6);
            total += evals;
        }
    }
    println!(
        "Powell Rosenbrock 2-D, 49 starts: {} evaluations on average",
        total / 49
    );
}

#[test]
fn ill_conditioned_quadratic_6d() {
    // Eigenvalues spread over four decades; many starts run into bounds on
    // the way to the interior minimum.
    struct IllConditioned;
    impl CostFunction for IllConditioned {
        type Param = Vec<f64>;
        type Output = f64;
        fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
            let n = u.len();
            Ok((0..n)
                .map(|k| {
                    let s: f64 = (0..n)
                        .map(|j| {
                            let a = ((k * k * 7 + j * j * 3 + k * j * 5 + j) as f64 * 0.61).sin();
                            a * (u[j] - 0.3 - 0.05 * j as f64)
                        })
                        .sum();
                    10f64.powf(0.8 * k as f64) * s * s
                })
                .sum())
        }
    }
    let mut total = 0;
    for i in 0..10 {
        let start: Vec<f64> = (0..6)
            .map(|j| ((i * 7 + j * 3) % 10) as f64 / 10.0 + 0.05)
            .collect();
        let (x, _, _, evals) = run(IllConditioned, Powell::new(start), 3000);
        let expected: Vec<f64> = (0..6).map(|j| 0.3 + 0.05 * j as f64).collect();
        assert_close(&x, &expected, 1e-6);
        total += evals;
    }
    println!(
        "Powell ill-conditioned 6-D quadratic: {} evaluations on average",
        total / 10
    );
}
