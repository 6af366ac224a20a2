//! RODAS4: a linearly implicit (Rosenbrock) method of order 4 with an embedded order-3
//! error estimate, for stiff systems.
//!
//! Each step solves six linear systems with the one matrix `I/(γh) − J`, `J = ∂f/∂y` at the
//! start of the step, and evaluates `f` six times; no Newton iteration, so no convergence
//! failures. The method is L-stable and stiffly accurate (the last stage is the solution),
//! so stiff components are damped at any step size and the step is set by the accuracy of
//! the smooth solution alone: the error control is that of [`crate::ode`] (the scaled RMS
//! norm of the embedded error, `atol + rtol·|y|`), with the usual controller of exponent
//! 1/4. Outputs on the grid come from the cubic Hermite interpolant of each step, built
//! from the values and derivatives at both ends (the derivative at the end is the next
//! step's first stage, so it costs nothing extra).
//!
//! The Jacobian comes from the system: [`StiffSystem::jacobian`] defaults to forward
//! differences, one `f` per state, and a system that knows its structure can do better.
//! Non-autonomous systems also pay one `f` per step for `∂f/∂t`.
//!
//! References:
//! - E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II: Stiff and
//!   Differential-Algebraic Problems*, 2nd ed., Springer 1996, §IV.7 (Rosenbrock methods,
//!   the coefficients of `RODAS4`, step-size control).
//! - G. Steinebach, "Order-reduction of ROW-methods for DAEs and method of lines
//!   applications", Preprint 1741, TH Darmstadt, 1995 (the RODAS family).

use crate::model::{SimulationError, SolverOptions, SolverStats};

/// A system `y' = f(t, y)` for the Rosenbrock integrator.
pub trait StiffSystem {
    /// Dimension of the state.
    fn dim(&self) -> usize;

    /// `dy = f(t, y)`.
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]);

    /// Whether `f` does not depend on `t` (then `∂f/∂t` is not computed).
    fn autonomous(&self) -> bool {
        false
    }

    /// The Jacobian `∂f/∂y` at `(t, y)`, where `f(t, y) = f0`, into `jac` (row-major,
    /// `jac[i·n + j] = ∂f_i/∂y_j`). Returns the cost in evaluations of `f` (for the
    /// statistics). The default takes forward differences, one column at a time.
    fn jacobian(&self, t: f64, y: &[f64], f0: &[f64], jac: &mut [f64]) -> usize {
        let n = y.len();
        let mut yp = y.to_vec();
        let mut fp = vec![0.0; n];
        for j in 0..n {
            let delta = (f64::EPSILON * y[j].abs().max(1e-5)).sqrt();
            yp[j] = y[j] + delta;
            self.rhs(t, &yp, &mut fp);
            yp[j] = y[j];
            for i in 0..n {
                jac[i * n + j] = (fp[i] - f0[i]) / delta;
            }
        }
        n
    }
}

// RODAS4 (Hairer & Wanner 1996, §IV.7), in the form with stages `k_i` solved from
// `(I/(γh) − J) k_i = f(t + c_i h, y + Σ a_ij k_j) + Σ (c_ij/h) k_j + h d_i f_t`.
const GAMMA: f64 = 0.25;
const C2: f64 = 0.386;
const C3: f64 = 0.21;
const C4: f64 = 0.63;
const D1: f64 = 0.25;
const D2: f64 = -0.1043;
const D3: f64 = 0.1035;
const D4: f64 = -0.3620000000000023e-1;
const A21: f64 = 1.544;
const A31: f64 = 0.9466785280815826;
const A32: f64 = 0.2557011698983284;
const A41: f64 = 3.314825187068521;
const A42: f64 = 2.896124015972201;
const A43: f64 = 0.9986419139977817;
const A51: f64 = 1.221224509226641;
const A52: f64 = 6.019134481288629;
const A53: f64 = 12.53708332932087;
const A54: f64 = -0.687886036105895;
const C21: f64 = -5.6688;
const C31: f64 = -2.430093356833875;
const C32: f64 = -0.2063599157091915;
const C41: f64 = -0.1073529058151375;
const C42: f64 = -9.594562251023355;
const C43: f64 = -20.47028614809616;
const C51: f64 = 7.496443313967647;
const C52: f64 = -10.24680431464352;
const C53: f64 = -33.99990352819905;
const C54: f64 = 11.7089089320616;
const C61: f64 = 8.083246795921522;
const C62: f64 = -7.981132988064893;
const C63: f64 = -31.52159432874371;
const C64: f64 = 16.31930543123136;
const C65: f64 = -6.058818238834054;

// Step-size controller.
const SAFETY: f64 = 0.9;
const FAC_MIN: f64 = 0.2;
const FAC_MAX: f64 = 6.0;

/// LU decomposition with partial pivoting of a dense row-major matrix, in place.
struct Lu {
    n: usize,
    a: Vec<f64>,
    pivot: Vec<usize>,
}

impl Lu {
    fn new(n: usize) -> Self {
        Self {
            n,
            a: vec![0.0; n * n],
            pivot: vec![0; n],
        }
    }

    /// Factor `diag·I − jac`; false when the matrix is singular.
    fn factor(&mut self, diag: f64, jac: &[f64]) -> bool {
        let n = self.n;
        for (a, j) in self.a.iter_mut().zip(jac) {
            *a = -j;
        }
        for i in 0..n {
            self.a[i * n + i] += diag;
        }
        for k in 0..n {
            let (mut p, mut best) = (k, self.a[k * n + k].abs());
            for i in k + 1..n {
                let v = self.a[i * n + k].abs();
                if v > best {
                    p = i;
                    best = v;
                }
            }
            if best == 0.0 || !best.is_finite() {
                return false;
            }
            self.pivot[k] = p;
            if p != k {
                for j in 0..n {
                    self.a.swap(k * n + j, p * n + j);
                }
            }
            let inv = 1.0 / self.a[k * n + k];
            for i in k + 1..n {
                let m = self.a[i * n + k] * inv;
                self.a[i * n + k] = m;
                if m != 0.0 {
                    for j in k + 1..n {
                        self.a[i * n + j] -= m * self.a[k * n + j];
                    }
                }
            }
        }
        true
    }

    /// Solve in place.
    #[allow(clippy::needless_range_loop)]
    fn solve(&self, b: &mut [f64]) {
        let n = self.n;
        for k in 0..n {
            b.swap(k, self.pivot[k]);
            let bk = b[k];
            if bk != 0.0 {
                for i in k + 1..n {
                    b[i] -= self.a[i * n + k] * bk;
                }
            }
        }
        for k in (0..n).rev() {
            let mut s = b[k];
            for j in k + 1..n {
                s -= self.a[k * n + j] * b[j];
            }
            b[k] = s / self.a[k * n + k];
        }
    }
}

/// Work space of one step.
struct Stages {
    k: [Vec<f64>; 6],
    ytmp: Vec<f64>,
    ftmp: Vec<f64>,
    ft: Vec<f64>,
    jac: Vec<f64>,
    lu: Lu,
}

impl Stages {
    fn new(n: usize) -> Self {
        Self {
            k: std::array::from_fn(|_| vec![0.0; n]),
            ytmp: vec![0.0; n],
            ftmp: vec![0.0; n],
            ft: vec![0.0; n],
            jac: vec![0.0; n * n],
            lu: Lu::new(n),
        }
    }
}

/// One RODAS4 step of size `h` from `(t, y)` with `f(t, y) = f0`, the Jacobian and `∂f/∂t`
/// already in `w`: writes the solution into `ynew` and the embedded error into `err`.
/// Returns false when the matrix is singular.
#[allow(clippy::too_many_arguments)]
fn step<S: StiffSystem + ?Sized>(
    system: &S,
    t: f64,
    h: f64,
    y: &[f64],
    f0: &[f64],
    w: &mut Stages,
    ynew: &mut [f64],
    err: &mut [f64],
    stats: &mut SolverStats,
) -> bool {
    let n = y.len();
    if !w.lu.factor(1.0 / (GAMMA * h), &w.jac) {
        return false;
    }
    let Stages {
        k, ytmp, ftmp, ft, ..
    } = w;
    let [k1, k2, k3, k4, k5, k6] = k;
    let lu = &w.lu;
    let hi = 1.0 / h;

    for i in 0..n {
        k1[i] = f0[i] + h * D1 * ft[i];
    }
    lu.solve(k1);

    for i in 0..n {
        ytmp[i] = y[i] + A21 * k1[i];
    }
    system.rhs(t + C2 * h, ytmp, ftmp);
    for i in 0..n {
        k2[i] = ftmp[i] + h * D2 * ft[i] + C21 * hi * k1[i];
    }
    lu.solve(k2);

    for i in 0..n {
        ytmp[i] = y[i] + A31 * k1[i] + A32 * k2[i];
    }
    system.rhs(t + C3 * h, ytmp, ftmp);
    for i in 0..n {
        k3[i] = ftmp[i] + h * D3 * ft[i] + hi * (C31 * k1[i] + C32 * k2[i]);
    }
    lu.solve(k3);

    for i in 0..n {
        ytmp[i] = y[i] + A41 * k1[i] + A42 * k2[i] + A43 * k3[i];
    }
    system.rhs(t + C4 * h, ytmp, ftmp);
    for i in 0..n {
        k4[i] = ftmp[i] + h * D4 * ft[i] + hi * (C41 * k1[i] + C42 * k2[i] + C43 * k3[i]);
    }
    lu.solve(k4);

    for i in 0..n {
        ytmp[i] = y[i] + A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i];
    }
    system.rhs(t + h, ytmp, ftmp);
    for i in 0..n {
        k5[i] = ftmp[i] + hi * (C51 * k1[i] + C52 * k2[i] + C53 * k3[i] + C54 * k4[i]);
    }
    lu.solve(k5);

    // Stiffly accurate: the stages 5 and 6 are the embedded and the main solution.
    for i in 0..n {
        ytmp[i] += k5[i];
    }
    system.rhs(t + h, ytmp, ftmp);
    for i in 0..n {
        k6[i] =
            ftmp[i] + hi * (C61 * k1[i] + C62 * k2[i] + C63 * k3[i] + C64 * k4[i] + C65 * k5[i]);
    }
    lu.solve(k6);
    for i in 0..n {
        ynew[i] = ytmp[i] + k6[i];
        err[i] = k6[i];
    }
    stats.rhs_evaluations += 5;
    true
}

/// Integrate `system` from `t = 0`, state `y0`, and call `out(i, y)` with the state at each
/// `grid[i]` (non-decreasing, ≥ 0). Same contract as [`crate::ode::integrate`] without
/// events; `stats.rhs_evaluations` includes the evaluations spent on Jacobians.
pub fn integrate<S, F>(
    system: &S,
    y0: &[f64],
    grid: &[f64],
    options: &SolverOptions,
    mut out: F,
) -> Result<SolverStats, SimulationError>
where
    S: StiffSystem + ?Sized,
    F: FnMut(usize, &[f64]),
{
    let n = system.dim();
    assert_eq!(y0.len(), n, "state dimension");
    let mut stats = SolverStats::default();
    let Some(&t_end) = grid.last() else {
        return Ok(stats);
    };
    let mut t = 0.0;
    let mut y = y0.to_vec();
    let mut next_out = 0;
    while next_out < grid.len() && grid[next_out] <= t {
        out(next_out, &y);
        next_out += 1;
    }
    if next_out == grid.len() {
        return Ok(stats);
    }

    let mut w = Stages::new(n);
    let mut f0 = vec![0.0; n];
    let mut f1 = vec![0.0; n];
    let mut ynew = vec![0.0; n];
    let mut err = vec![0.0; n];
    let mut yout = vec![0.0; n];
    system.rhs(t, &y, &mut f0);
    stats.rhs_evaluations += 1;

    let scale =
        |i: usize, a: &[f64], b: &[f64]| options.atol + options.rtol * a[i].abs().max(b[i].abs());
    let mut h = {
        let d0 = (0..n)
            .map(|i| (y[i] / scale(i, &y, &y)).powi(2))
            .sum::<f64>()
            / n as f64;
        let d1 = (0..n)
            .map(|i| (f0[i] / scale(i, &y, &y)).powi(2))
            .sum::<f64>()
            / n as f64;
        let (d0, d1) = (d0.sqrt(), d1.sqrt());
        let h0 = if d0 < 1e-5 || d1 < 1e-5 {
            1e-3 * (t_end - t)
        } else {
            0.01 * d0 / d1
        };
        h0.min(t_end - t)
    };
    let mut jacobian_current = false;
    let mut last_rejected = false;

    loop {
        if stats.accepted_steps + stats.rejected_steps >= options.max_steps {
            return Err(SimulationError::StepLimit {
                limit: options.max_steps,
                time: t,
            });
        }
        let remaining = t_end - t;
        let mut last_step = false;
        if h >= remaining * (1.0 - 1e-12) {
            h = remaining;
            last_step = true;
        }
        if h <= 1e-14 * t.abs().max(1.0) {
            return Err(SimulationError::StepTooSmall { time: t });
        }
        if !jacobian_current {
            stats.rhs_evaluations += system.jacobian(t, &y, &f0, &mut w.jac);
            if system.autonomous() {
                w.ft.fill(0.0);
            } else {
                // Relative to the time scale of the solution (the step), not to `t`
                // alone: near t = 0 that would put the difference in the rounding noise.
                let dt = f64::EPSILON.sqrt() * t.abs().max(h);
                system.rhs(t + dt, &y, &mut w.ftmp);
                stats.rhs_evaluations += 1;
                for ((ft, fp), f) in w.ft.iter_mut().zip(&w.ftmp).zip(&f0) {
                    *ft = (fp - f) / dt;
                }
            }
            jacobian_current = true;
        }

        let ok = step(
            system, t, h, &y, &f0, &mut w, &mut ynew, &mut err, &mut stats,
        );
        let e = if ok {
            ((0..n)
                .map(|i| (err[i] / scale(i, &y, &ynew)).powi(2))
                .sum::<f64>()
                / n as f64)
                .sqrt()
        } else {
            f64::INFINITY
        };
        if !e.is_finite() || ynew.iter().any(|v| !v.is_finite()) {
            stats.rejected_steps += 1;
            h *= FAC_MIN;
            last_rejected = true;
            continue;
        }
        let fac = (SAFETY * e.powf(-0.25)).clamp(FAC_MIN, FAC_MAX);
        if e > 1.0 {
            stats.rejected_steps += 1;
            h *= fac.min(1.0);
            last_rejected = true;
            continue;
        }

        // Accepted.
        stats.accepted_steps += 1;
        let t_new = if last_step { t_end } else { t + h };
        system.rhs(t_new, &ynew, &mut f1);
        stats.rhs_evaluations += 1;
        while next_out < grid.len() && grid[next_out] <= t_new {
            let tg = grid[next_out];
            if tg == t_new {
                out(next_out, &ynew);
            } else {
                hermite(t, h, &y, &ynew, &f0, &f1, tg, &mut yout);
                out(next_out, &yout);
            }
            next_out += 1;
        }
        if next_out == grid.len() {
            return Ok(stats);
        }
        t = t_new;
        std::mem::swap(&mut y, &mut ynew);
        std::mem::swap(&mut f0, &mut f1);
        jacobian_current = false;
        h *= if last_rejected { fac.min(1.0) } else { fac };
        last_rejected = false;
    }
}

/// Cubic Hermite interpolant of a step of size `h` from `(t0, y0, f0)` to `(y1, f1)`, at `t`.
#[allow(clippy::too_many_arguments)]
fn hermite(
    t0: f64,
    h: f64,
    y0: &[f64],
    y1: &[f64],
    f0: &[f64],
    f1: &[f64],
    t: f64,
    out: &mut [f64],
) {
    let s = (t - t0) / h;
    let s2 = s * s;
    let s3 = s2 * s;
    let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
    let h10 = s3 - 2.0 * s2 + s;
    let h01 = -2.0 * s3 + 3.0 * s2;
    let h11 = s3 - s2;
    for i in 0..out.len() {
        out[i] = h00 * y0[i] + h10 * h * f0[i] + h01 * y1[i] + h11 * h * f1[i];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `y' = λ (y − sin t) + cos t`: `y = sin t + y0 e^{λt}`, stiff for large `−λ`.
    struct Prothero {
        lambda: f64,
    }
    impl StiffSystem for Prothero {
        fn dim(&self) -> usize {
            1
        }
        fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
            dy[0] = self.lambda * (y[0] - t.sin()) + t.cos();
        }
    }

    fn exact(lambda: f64, y0: f64, t: f64) -> f64 {
        t.sin() + y0 * (lambda * t).exp()
    }

    /// Fixed steps of size `h` to `t_end`: the global error.
    fn fixed_step_error(lambda: f64, h: f64, t_end: f64) -> (f64, f64) {
        let sys = Prothero { lambda };
        let mut w = Stages::new(1);
        let mut stats = SolverStats::default();
        let (mut t, mut y) = (0.0, vec![1.0]);
        let (mut ynew, mut err) = (vec![0.0], vec![0.0]);
        let mut f0 = vec![0.0];
        let mut worst_estimate: f64 = 0.0;
        let steps = (t_end / h).round() as usize;
        for _ in 0..steps {
            sys.rhs(t, &y, &mut f0);
            sys.jacobian(t, &y, &f0, &mut w.jac);
            let dt = 1e-7;
            let mut fp = vec![0.0];
            sys.rhs(t + dt, &y, &mut fp);
            w.ft[0] = (fp[0] - f0[0]) / dt;
            assert!(step(
                &sys, t, h, &y, &f0, &mut w, &mut ynew, &mut err, &mut stats
            ));
            worst_estimate = worst_estimate.max(err[0].abs());
            t += h;
            y.copy_from_slice(&ynew);
        }
        ((y[0] - exact(lambda, 1.0, t)).abs(), worst_estimate)
    }

    #[test]
    fn converges_at_fourth_order_on_a_smooth_problem() {
        // Non-stiff (λ = −1): halving the step divides the global error by about 2⁴.
        let (e1, _) = fixed_step_error(-1.0, 0.2, 4.0);
        let (e2, _) = fixed_step_error(-1.0, 0.1, 4.0);
        let order = (e1 / e2).log2();
        assert!(
            (3.6..4.6).contains(&order),
            "order {order} ({e1:e}, {e2:e})"
        );
    }

    #[test]
    fn damps_stiff_components_at_large_steps() {
        // λ = −10⁶ with steps of 0.1: L-stability keeps the solution on sin t.
        let (e, _) = fixed_step_error(-1e6, 0.1, 2.0);
        assert!(e < 1e-4, "error {e}");
    }

    #[test]
    fn matches_closed_form_on_the_grid() {
        let grid: Vec<f64> = (0..=100).map(|i| i as f64 * 0.1).collect();
        for lambda in [-1.0, -1e4] {
            let opts = SolverOptions {
                rtol: 1e-8,
                atol: 1e-10,
                max_steps: 100_000,
            };
            let mut worst: f64 = 0.0;
            let stats = integrate(&Prothero { lambda }, &[1.0], &grid, &opts, |i, y| {
                worst = worst.max((y[0] - exact(lambda, 1.0, grid[i])).abs());
            })
            .unwrap();
            assert!(worst < 1e-6, "λ {lambda}: max error {worst:e}, {stats:?}");
        }
    }

    /// Robertson's chemical kinetics (Hairer & Wanner 1996, §IV.1), the classic stiff test:
    /// reference values at t = 40 from the same book's test set.
    struct Robertson;
    impl StiffSystem for Robertson {
        fn dim(&self) -> usize {
            3
        }
        fn autonomous(&self) -> bool {
            true
        }
        fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
            dy[0] = -0.04 * y[0] + 1e4 * y[1] * y[2];
            dy[2] = 3e7 * y[1] * y[1];
            dy[1] = -dy[0] - dy[2];
        }
    }

    #[test]
    fn robertson_matches_the_reference_solution() {
        let opts = SolverOptions {
            rtol: 1e-8,
            atol: 1e-14,
            max_steps: 100_000,
        };
        let mut y40 = vec![];
        let stats = integrate(&Robertson, &[1.0, 0.0, 0.0], &[40.0], &opts, |_, y| {
            y40 = y.to_vec();
        })
        .unwrap();
        let reference = [0.7158270687, 9.185534764e-6, 0.2841637457];
        for (y, r) in y40.iter().zip(reference) {
            assert!((y / r - 1.0).abs() < 1e-6, "{y40:?} vs {reference:?}");
        }
        // An explicit method would need millions of steps (stability at h < 1e-3).
        assert!(stats.accepted_steps < 500, "{stats:?}");
    }

    #[test]
    fn step_limit_is_a_typed_error() {
        let opts = SolverOptions {
            max_steps: 3,
            ..SolverOptions::default()
        };
        let r = integrate(&Robertson, &[1.0, 0.0, 0.0], &[1e3], &opts, |_, _| {});
        assert!(matches!(r, Err(SimulationError::StepLimit { .. })));
    }
}
