//! The RKC method against the heat equation's closed form, its order, events and limits.

use super::*;
use std::cell::Cell;

/// The heat equation `u_t = u_xx` on `(0, 1)`, `u = 0` at both ends, by central
/// differences on `n` interior points: stiff (spectral radius `≈ 4 (n + 1)²`), with the
/// exact solution of the semi-discrete system in closed form, since the grid functions
/// `sin(kπx)` are its eigenvectors with eigenvalues `−4 (n + 1)² sin²(kπ/(2(n + 1)))`.
struct Heat {
    n: usize,
    calls: Cell<usize>,
}

/// Initial state: the first and the fifth mode.
const MODES: [(usize, f64); 2] = [(1, 1.0), (5, 0.5)];

impl Heat {
    fn new(n: usize) -> Self {
        Self {
            n,
            calls: Cell::new(0),
        }
    }

    fn exact(&self, t: f64) -> Vec<f64> {
        let m = (self.n + 1) as f64;
        (1..=self.n)
            .map(|j| {
                MODES
                    .iter()
                    .map(|&(k, a)| {
                        let k = k as f64;
                        let lambda =
                            -4.0 * m * m * (k * std::f64::consts::PI / (2.0 * m)).sin().powi(2);
                        a * (lambda * t).exp() * (k * std::f64::consts::PI * j as f64 / m).sin()
                    })
                    .sum()
            })
            .collect()
    }
}

impl HybridSystem for Heat {
    fn dim(&self) -> usize {
        self.n
    }

    fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
        self.calls.set(self.calls.get() + 1);
        let m2 = ((self.n + 1) * (self.n + 1)) as f64;
        for j in 0..self.n {
            let left = if j > 0 { y[j - 1] } else { 0.0 };
            let right = if j + 1 < self.n { y[j + 1] } else { 0.0 };
            dy[j] = m2 * (left - 2.0 * y[j] + right);
        }
    }
}

/// Largest error against the exact solution on a grid, and the right-hand sides used.
fn heat_run(rtol: f64, rkc: bool) -> (f64, usize, SolverStats) {
    let mut heat = Heat::new(40);
    let grid: Vec<f64> = (0..=20).map(|i| i as f64 * 0.01).collect();
    let opts = SolverOptions {
        rtol,
        atol: rtol,
        max_steps: 100_000,
        ..SolverOptions::default()
    };
    let mut states = vec![Vec::new(); grid.len()];
    let record = |i: usize, y: &[f64]| states[i] = y.to_vec();
    let y0 = heat.exact(0.0);
    let stats = if rkc {
        integrate(&mut heat, &y0, &grid, &opts, record)
    } else {
        super::super::integrate(&mut heat, &y0, &grid, &opts, record)
    }
    .unwrap();
    let mut worst: f64 = 0.0;
    for (t, y) in grid.iter().zip(&states) {
        for (a, b) in y.iter().zip(heat.exact(*t)) {
            worst = worst.max((a - b).abs());
        }
    }
    (worst, heat.calls.get(), stats)
}

#[test]
fn stiff_heat_equation_matches_the_exact_solution() {
    let (err, calls, stats) = heat_run(1e-6, true);
    assert!(err < 1e-4, "max error {err}");
    assert_eq!(calls, stats.rhs_evaluations, "{stats:?}");
    // Dormand–Prince is held to steps of about 3.3/ρ by its stability: RKC needs a
    // fraction of its right-hand sides (measured: 710 against 2426).
    let (dp_err, dp_calls, _) = heat_run(1e-6, false);
    assert!(dp_err < 1e-4, "Dormand–Prince: max error {dp_err}");
    assert!(calls * 3 < dp_calls, "RKC {calls} against {dp_calls}");
}

#[test]
fn error_falls_with_tolerance_at_second_order() {
    let (loose, _, s1) = heat_run(1e-4, true);
    let (tight, _, s2) = heat_run(1e-7, true);
    assert!(tight < loose / 100.0, "errors {loose} and {tight}");
    // Second order: a thousandth of the tolerance takes about ten times the steps.
    let ratio = s2.accepted_steps as f64 / s1.accepted_steps as f64;
    assert!((5.0..20.0).contains(&ratio), "{s1:?} {s2:?}");
}

/// `y' = −y` from 1 with an event where `y` falls through 1/2, at `ln 2`.
struct Decay {
    fired: Vec<f64>,
}

impl HybridSystem for Decay {
    fn dim(&self) -> usize {
        1
    }
    fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
        dy[0] = -y[0];
    }
    fn event_count(&self) -> usize {
        1
    }
    fn events(&self, _t: f64, y: &[f64], g: &mut [f64]) {
        g[0] = y[0] - 0.5;
    }
    fn on_event(&mut self, t: f64, y: &mut [f64], _event: usize) {
        self.fired.push(t);
        // Reset, so that the event fires again one ln 2 later.
        y[0] = 1.0;
    }
}

#[test]
fn events_are_located_on_the_hermite_interpolant() {
    let mut decay = Decay { fired: Vec::new() };
    let opts = SolverOptions {
        rtol: 1e-8,
        atol: 1e-10,
        max_steps: 100_000,
        ..SolverOptions::default()
    };
    let grid = [0.5, 1.0, 2.0];
    let mut out = [f64::NAN; 3];
    let stats = integrate(&mut decay, &[1.0], &grid, &opts, |i, y| out[i] = y[0]).unwrap();
    let ln2 = std::f64::consts::LN_2;
    assert_eq!(decay.fired.len(), 2, "{:?}", decay.fired);
    assert_eq!(stats.events, 2);
    for (k, t) in decay.fired.iter().enumerate() {
        assert!((t - (k + 1) as f64 * ln2).abs() < 1e-5, "{:?}", decay.fired);
    }
    // Outputs after the resets follow the restarted solution.
    assert!((out[0] - (-0.5f64).exp()).abs() < 1e-5, "{out:?}");
    assert!((out[1] - (-(1.0 - ln2)).exp()).abs() < 1e-5, "{out:?}");
    assert!(
        (out[2] - (-(2.0 - 2.0 * ln2)).exp()).abs() < 1e-5,
        "{out:?}"
    );
}

#[test]
fn step_limit_is_a_typed_error() {
    let opts = SolverOptions {
        max_steps: 3,
        ..SolverOptions::default()
    };
    let mut heat = Heat::new(10);
    let y0 = heat.exact(0.0);
    let r = integrate(&mut heat, &y0, &[1.0], &opts, |_, _| {});
    assert!(matches!(r, Err(SimulationError::StepLimit { .. })), "{r:?}");
}
