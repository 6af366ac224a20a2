//! Dormand–Prince 5(4): an explicit embedded Runge–Kutta pair for non-stiff systems.
//!
//! Order 5 with an error estimate of order 4, local extrapolation, first same as last (the
//! seventh stage is the next step's first, so a step costs six right-hand sides), a PI
//! step-size controller and the continuous extension of order 4 of Hairer's `DOPRI5`, on
//! which [`super::driver::drive`] reads the outputs and locates the events.
//!
//! References:
//! - J. R. Dormand, P. J. Prince, "A family of embedded Runge–Kutta formulae",
//!   J. Comp. Appl. Math. 6 (1980) 19–26.
//! - E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*,
//!   2nd ed., Springer 1993, §II.4–II.6 (step control, dense output) and the `DOPRI5` code.

use super::driver::{drive, Interpolant, Stepper, Trial};
use super::HybridSystem;
use crate::model::{SimulationError, SolverOptions, SolverStats};

// Dormand–Prince 5(4) tableau.
const C2: f64 = 1.0 / 5.0;
const C3: f64 = 3.0 / 10.0;
const C4: f64 = 4.0 / 5.0;
const C5: f64 = 8.0 / 9.0;
const A21: f64 = 1.0 / 5.0;
const A31: f64 = 3.0 / 40.0;
const A32: f64 = 9.0 / 40.0;
const A41: f64 = 44.0 / 45.0;
const A42: f64 = -56.0 / 15.0;
const A43: f64 = 32.0 / 9.0;
const A51: f64 = 19372.0 / 6561.0;
const A52: f64 = -25360.0 / 2187.0;
const A53: f64 = 64448.0 / 6561.0;
const A54: f64 = -212.0 / 729.0;
const A61: f64 = 9017.0 / 3168.0;
const A62: f64 = -355.0 / 33.0;
const A63: f64 = 46732.0 / 5247.0;
const A64: f64 = 49.0 / 176.0;
const A65: f64 = -5103.0 / 18656.0;
const A71: f64 = 35.0 / 384.0;
const A73: f64 = 500.0 / 1113.0;
const A74: f64 = 125.0 / 192.0;
const A75: f64 = -2187.0 / 6784.0;
const A76: f64 = 11.0 / 84.0;
const E1: f64 = 71.0 / 57600.0;
const E3: f64 = -71.0 / 16695.0;
const E4: f64 = 71.0 / 1920.0;
const E5: f64 = -17253.0 / 339200.0;
const E6: f64 = 22.0 / 525.0;
const E7: f64 = -1.0 / 40.0;
const D1: f64 = -12715105075.0 / 11282082432.0;
const D3: f64 = 87487479700.0 / 32700410799.0;
const D4: f64 = -10690763975.0 / 1880347072.0;
const D5: f64 = 701980252875.0 / 199316789632.0;
const D6: f64 = -1453857185.0 / 822651844.0;
const D7: f64 = 69997945.0 / 29380423.0;

// Step-size controller (Hairer's defaults).
const SAFETY: f64 = 0.9;
const BETA: f64 = 0.04;
const EXPO1: f64 = 0.2 - BETA * 0.75;
const FAC_MIN: f64 = 0.2; // smallest ratio h_new / h
const FAC_MAX: f64 = 10.0; // largest ratio h_new / h

/// Integrate `system` by Dormand–Prince from `t = 0`, state `y0`, and call `out(i, y)` with
/// the state at each `grid[i]` (non-decreasing, ≥ 0).
pub fn integrate<S, F>(
    system: &mut S,
    y0: &[f64],
    grid: &[f64],
    options: &SolverOptions,
    out: F,
) -> Result<SolverStats, SimulationError>
where
    S: HybridSystem,
    F: FnMut(usize, &[f64]),
{
    drive(
        system,
        &mut DormandPrince::new(y0.len()),
        y0,
        grid,
        options,
        out,
    )
}

/// The continuous extension of one accepted step.
struct Dense {
    t0: f64,
    h: f64,
    r: [Vec<f64>; 5],
}

/// The method's state: the stages of the last attempt, the state at its start and end, the
/// continuous extension of the last accepted step, and the PI controller's previous error.
struct DormandPrince {
    y: Vec<f64>,
    ynew: Vec<f64>,
    ytmp: Vec<f64>,
    yerr: Vec<f64>,
    /// The stages; `k[0]` is `F(t, y)`, `k[6]` is `F(t + h, ynew)`.
    k: [Vec<f64>; 7],
    dense: Dense,
    fac_old: f64,
}

impl DormandPrince {
    fn new(n: usize) -> Self {
        let vector = || vec![0.0; n];
        Self {
            y: vector(),
            ynew: vector(),
            ytmp: vector(),
            yerr: vector(),
            k: std::array::from_fn(|_| vector()),
            dense: Dense {
                t0: 0.0,
                h: 0.0,
                r: std::array::from_fn(|_| vector()),
            },
            fac_old: 1e-4,
        }
    }

    /// Stages 2..7 of the step `[t, t + h]` (stage 1 is `k[0]`), the new state in `ynew` and
    /// the error estimate in `yerr`.
    fn stages<S: HybridSystem>(&mut self, system: &S, t: f64, h: f64) {
        // Slices, not the vectors behind `self`: the loops then keep their bounds in
        // registers rather than reloading them after every store.
        let n = self.y.len();
        let y: &[f64] = &self.y;
        let ytmp: &mut [f64] = &mut self.ytmp;
        let ynew: &mut [f64] = &mut self.ynew;
        let yerr: &mut [f64] = &mut self.yerr;
        let [k1, k2, k3, k4, k5, k6, k7] = self.k.each_mut().map(|k| k.as_mut_slice());
        for i in 0..n {
            ytmp[i] = y[i] + h * A21 * k1[i];
        }
        system.rhs(t + C2 * h, ytmp, k2);
        for i in 0..n {
            ytmp[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
        }
        system.rhs(t + C3 * h, ytmp, k3);
        for i in 0..n {
            ytmp[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
        }
        system.rhs(t + C4 * h, ytmp, k4);
        for i in 0..n {
            ytmp[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
        }
        system.rhs(t + C5 * h, ytmp, k5);
        for i in 0..n {
            ytmp[i] =
                y[i] + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
        }
        system.rhs(t + h, ytmp, k6);
        for i in 0..n {
            ynew[i] =
                y[i] + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
        }
        system.rhs(t + h, ynew, k7);
        for i in 0..n {
            yerr[i] =
                h * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
        }
    }
}

impl Interpolant for DormandPrince {
    fn eval(&self, t: f64, out: &mut [f64]) {
        let dense = &self.dense;
        let theta = (t - dense.t0) / dense.h;
        let theta1 = 1.0 - theta;
        let [r1, r2, r3, r4, r5] = &dense.r;
        for i in 0..out.len() {
            out[i] = r1[i] + theta * (r2[i] + theta1 * (r3[i] + theta * (r4[i] + theta1 * r5[i])));
        }
    }
}

impl Stepper for DormandPrince {
    fn state(&self) -> &[f64] {
        &self.y
    }

    fn proposed(&self) -> &[f64] {
        &self.ynew
    }

    fn restart<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        y: &[f64],
        stats: &mut SolverStats,
    ) -> Result<(), SimulationError> {
        self.y.copy_from_slice(y);
        system.rhs(t, &self.y, &mut self.k[0]);
        stats.rhs_evaluations += 1;
        self.fac_old = 1e-4;
        Ok(())
    }

    fn initial_step<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        span: f64,
        options: &SolverOptions,
        stats: &mut SolverStats,
    ) -> f64 {
        initial_step(system, t, &self.y, &self.k[0], span, options, stats)
    }

    fn attempt<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        h: f64,
        options: &SolverOptions,
        stats: &mut SolverStats,
    ) -> Result<Trial, SimulationError> {
        self.stages(system, t, h);
        stats.rhs_evaluations += 6;
        let (y, ynew, yerr): (&[f64], &[f64], &[f64]) = (&self.y, &self.ynew, &self.yerr);
        let n = y.len();
        let mut err = 0.0;
        for i in 0..n {
            let sk = options.atol + options.rtol * y[i].abs().max(ynew[i].abs());
            let e = yerr[i] / sk;
            err += e * e;
        }
        let err = (err / n as f64).sqrt();
        if !err.is_finite() || ynew.iter().any(|v| !v.is_finite()) {
            // Shrink hard; a truly diverging state ends in a step-size underflow.
            if ynew.iter().any(|v| !v.is_finite()) && h < 1e-10 {
                return Err(SimulationError::Diverged { time: t });
            }
            return Ok(Trial::NonFinite);
        }
        Ok(Trial::Error(err))
    }

    fn after_non_finite(&mut self, h: f64) -> f64 {
        h * FAC_MIN
    }

    fn after_rejected(&mut self, h: f64, err: f64, _again: bool) -> f64 {
        h / (err.powf(EXPO1) / SAFETY).min(1.0 / FAC_MIN)
    }

    fn accept(&mut self, t: f64, h: f64) {
        self.dense.t0 = t;
        self.dense.h = h;
        let (y, ynew): (&[f64], &[f64]) = (&self.y, &self.ynew);
        let [k1, _, k3, k4, k5, k6, k7] = self.k.each_ref().map(|k| k.as_slice());
        let [r1, r2, r3, r4, r5] = self.dense.r.each_mut().map(|r| r.as_mut_slice());
        for i in 0..y.len() {
            let ydiff = ynew[i] - y[i];
            let bspl = h * k1[i] - ydiff;
            r1[i] = y[i];
            r2[i] = ydiff;
            r3[i] = bspl;
            r4[i] = ydiff - h * k7[i] - bspl;
            r5[i] =
                h * (D1 * k1[i] + D3 * k3[i] + D4 * k4[i] + D5 * k5[i] + D6 * k6[i] + D7 * k7[i]);
        }
    }

    fn advance(&mut self) {
        std::mem::swap(&mut self.y, &mut self.ynew);
        self.k.swap(0, 6);
    }

    fn next_step(&mut self, h: f64, err: f64, after_rejection: bool) -> f64 {
        let fac11 = err.powf(EXPO1);
        let mut fac = fac11 / self.fac_old.powf(BETA);
        fac = (fac / SAFETY).clamp(1.0 / FAC_MAX, 1.0 / FAC_MIN);
        let mut h_new = h / fac;
        if after_rejection {
            h_new = h_new.min(h);
        }
        self.fac_old = err.max(1e-4);
        h_new
    }
}

/// Hairer's starting step: the step whose explicit Euler error would be about the tolerance.
fn initial_step<S: HybridSystem>(
    system: &S,
    t: f64,
    y: &[f64],
    f0: &[f64],
    span: f64,
    options: &SolverOptions,
    stats: &mut SolverStats,
) -> f64 {
    let n = y.len();
    let sk = |i: usize| options.atol + options.rtol * y[i].abs();
    let norm =
        |v: &dyn Fn(usize) -> f64| ((0..n).map(|i| v(i).powi(2)).sum::<f64>() / n as f64).sqrt();
    let d0 = norm(&|i| y[i] / sk(i));
    let d1 = norm(&|i| f0[i] / sk(i));
    let mut h0 = if d0 < 1e-5 || d1 < 1e-5 {
        1e-6
    } else {
        0.01 * d0 / d1
    };
    h0 = h0.min(span);
    let y1: Vec<f64> = (0..n).map(|i| y[i] + h0 * f0[i]).collect();
    let mut f1 = vec![0.0; n];
    system.rhs(t + h0, &y1, &mut f1);
    stats.rhs_evaluations += 1;
    let d2 = norm(&|i| (f1[i] - f0[i]) / sk(i)) / h0;
    let h1 = if d1.max(d2) <= 1e-15 {
        (h0 * 1e-3).max(1e-6)
    } else {
        (0.01 / d1.max(d2)).powf(0.2)
    };
    (100.0 * h0).min(h1).min(span)
}

#[cfg(test)]
mod tests {
    use super::*;

    struct Harmonic;
    impl HybridSystem for Harmonic {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
            dy[0] = y[1];
            dy[1] = -y[0];
        }
    }

    #[test]
    fn harmonic_oscillator_matches_closed_form_on_the_grid() {
        let grid: Vec<f64> = (0..=200).map(|i| i as f64 * 0.1).collect();
        let opts = SolverOptions {
            rtol: 1e-10,
            atol: 1e-12,
            max_steps: 100_000,
            ..SolverOptions::default()
        };
        let mut worst: f64 = 0.0;
        integrate(&mut Harmonic, &[1.0, 0.0], &grid, &opts, |i, y| {
            worst = worst.max((y[0] - grid[i].cos()).abs());
            worst = worst.max((y[1] + grid[i].sin()).abs());
        })
        .unwrap();
        assert!(worst < 1e-8, "max error {worst}");
    }

    #[test]
    fn error_falls_with_tolerance_at_fifth_order() {
        let grid = [10.0];
        let mut errs = Vec::new();
        for rtol in [1e-5, 1e-8] {
            let opts = SolverOptions {
                rtol,
                atol: rtol * 1e-2,
                max_steps: 100_000,
                ..SolverOptions::default()
            };
            let mut e = 0.0;
            integrate(&mut Harmonic, &[1.0, 0.0], &grid, &opts, |_, y| {
                e = (y[0] - 10f64.cos()).abs();
            })
            .unwrap();
            errs.push(e);
        }
        assert!(errs[1] < errs[0] / 100.0, "errors {errs:?}");
    }

    #[test]
    fn step_limit_is_a_typed_error() {
        let opts = SolverOptions {
            max_steps: 5,
            ..SolverOptions::default()
        };
        let r = integrate(&mut Harmonic, &[1.0, 0.0], &[100.0], &opts, |_, _| {});
        assert!(matches!(r, Err(SimulationError::StepLimit { .. })));
    }
}
