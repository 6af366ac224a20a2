//! Runge–Kutta–Chebyshev (RKC): a stabilised explicit method of order 2 for mildly stiff
//! systems whose Jacobian has its eigenvalues near the negative real axis.
//!
//! A step of `s` stages is built from the Chebyshev polynomials `T_j` by their three-term
//! recursion (Sommeijer, Shampine & Verwer 1998):
//!
//! ```text
//! Y_0 = y_n,   Y_1 = y_n + μ̃_1 h F(Y_0),
//! Y_j = (1 − μ_j − ν_j) y_n + μ_j Y_{j−1} + ν_j Y_{j−2} + μ̃_j h F(Y_{j−1}) + γ̃_j h F(Y_0),
//! y_{n+1} = Y_s,
//! ```
//!
//! with damping `ε = 2/13`, `w_0 = 1 + ε/s²`, `w_1 = T_s'(w_0)/T_s''(w_0)`,
//! `b_j = T_j''(w_0)/T_j'(w_0)²` (`b_0 = b_1 = b_2`), `μ_j = 2 b_j w_0/b_{j−1}`,
//! `ν_j = −b_j/b_{j−2}`, `μ̃_j = 2 b_j w_1/b_{j−1}`, `γ̃_j = −(1 − b_{j−1} T_{j−1}(w_0)) μ̃_j`.
//! Its stability region contains the real interval `[−β(s), 0]`, `β(s) ≈ 0.653 s²`: the
//! stage count grows like the square root of `h ρ` (`ρ` the spectral radius of the
//! Jacobian), so a step across a stiffness-limited stretch costs `√(h ρ)` right-hand sides
//! where a classical explicit method needs about `h ρ`. No Jacobian enters the stages, so
//! a right-hand side that is only piecewise smooth in the state costs small steps at its
//! kinks and nothing more, where the stages of a linearly implicit method go wrong.
//!
//! As in the `RKC` code of the paper:
//! - the local error is estimated by `(12 (y_n − y_{n+1}) + 6 h (F_n + F_{n+1}))/15` in
//!   the same mixed norm as [`super::integrate`], and the step controlled by
//!   `0.8 err^(−1/3)` with the predictive (Gustafsson) correction after accepted steps;
//! - `F_{n+1}` is the next step's `F_n` (first same as last), so a step of `s` stages
//!   costs `s` right-hand sides;
//! - the spectral radius is estimated by a nonlinear power iteration on differences of the
//!   right-hand side (in the scaled variables of the error norm, started from the last
//!   dominant direction), at the start, every 25 accepted steps, after an event
//!   and after two rejected steps in a row (a single rejection is usually one of
//!   accuracy), and taken with a margin of 1.2; when the iteration does not settle (a
//!   complex dominant pair), the largest ratio it met is taken. The stage count is
//!   `s = 1 + ⌊√(1 + 1.54 h ρ)⌋`;
//! - the continuous extension is the cubic Hermite interpolant of `y_n, y_{n+1}, F_n,
//!   F_{n+1}`, of third order, on which outputs are read and events located exactly as
//!   in [`super::integrate`].
//!
//! References:
//! - B. P. Sommeijer, L. F. Shampine, J. G. Verwer, "RKC: an explicit solver for parabolic
//!   PDEs", J. Comput. Appl. Math. 88 (1998) 315–326.
//! - J. G. Verwer, W. H. Hundsdorfer, B. P. Sommeijer, "Convergence properties of the
//!   Runge–Kutta–Chebyshev method", Numer. Math. 57 (1990) 157–178.
//! - E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II*, 2nd ed., Springer
//!   1996, §IV.2 (stabilised explicit methods).

use super::{
    first_event, outputs_at_start, outputs_of_step, switch_mode, HybridSystem, Interpolant,
    StepEnd, ZenoGuard,
};
use crate::model::{SimulationError, SolverOptions, SolverStats};

/// Accepted steps between two estimates of the spectral radius.
const SPECTRAL_REFRESH: usize = 25;
/// Iterations allowed to the power method.
const SPECTRAL_ITER: usize = 50;
/// Most stages per step (the stability interval then reaches about 0.65 · 250²).
const MAX_STAGES: usize = 250;

/// The cubic Hermite interpolant of one accepted step.
struct Hermite {
    t0: f64,
    h: f64,
    y0: Vec<f64>,
    y1: Vec<f64>,
    f0: Vec<f64>,
    f1: Vec<f64>,
}

impl Interpolant for Hermite {
    fn eval(&self, t: f64, out: &mut [f64]) {
        let theta = (t - self.t0) / self.h;
        let h = self.h;
        for (i, o) in out.iter_mut().enumerate() {
            let (y0, y1) = (self.y0[i], self.y1[i]);
            let dy = y1 - y0;
            *o = y0
                + theta
                    * (dy
                        + (theta - 1.0)
                            * ((1.0 - 2.0 * theta) * dy
                                + (theta - 1.0) * h * self.f0[i]
                                + theta * h * self.f1[i]));
        }
    }
}

/// Error weights `atol + rtol · max(|y|, |y_new|)`.
fn weight(options: &SolverOptions, y: f64, y_new: f64) -> f64 {
    options.atol + options.rtol * y.abs().max(y_new.abs())
}

/// Root mean square of `v`.
fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt()
}

/// Spectral radius of the Jacobian at `(t, y)` (`f0 = F(t, y)`), with a margin of 1.2, by
/// the nonlinear power method in the variables scaled by the error weights; `dir` holds
/// the starting direction and receives the dominant one. When the ratio does not settle
/// to 1 % within [`SPECTRAL_ITER`] iterations, the largest one met; `None` when the
/// right-hand side is not finite.
#[allow(clippy::too_many_arguments)]
fn spectral_radius<S: HybridSystem>(
    system: &S,
    t: f64,
    y: &[f64],
    f0: &[f64],
    dir: &mut [f64],
    options: &SolverOptions,
    work: &mut [Vec<f64>; 2],
    stats: &mut SolverStats,
) -> Option<f64> {
    let n = y.len();
    // A perturbation of about √ε relative to the state.
    let delta = f64::EPSILON.sqrt() / options.rtol;
    let [yp, fp] = work;
    let mut norm = rms(dir);
    if !(norm > 0.0 && norm.is_finite()) {
        dir.copy_from_slice(f0);
        for i in 0..n {
            dir[i] /= weight(options, y[i], y[i]);
        }
        norm = rms(dir);
        if !(norm > 0.0 && norm.is_finite()) {
            dir.fill(1.0);
            norm = 1.0;
        }
    }
    let mut sigma = f64::NAN;
    let mut largest: f64 = 0.0;
    for iteration in 0..SPECTRAL_ITER {
        for i in 0..n {
            yp[i] = y[i] + delta * weight(options, y[i], y[i]) * dir[i] / norm;
        }
        system.rhs(t, yp, fp);
        stats.rhs_evaluations += 1;
        for i in 0..n {
            dir[i] = (fp[i] - f0[i]) / (delta * weight(options, y[i], y[i]));
        }
        norm = rms(dir);
        if !norm.is_finite() {
            return None;
        }
        let previous = sigma;
        sigma = norm;
        largest = largest.max(sigma);
        if iteration > 0 && (sigma - previous).abs() <= 0.01 * sigma.max(1e-12) {
            return Some(1.2 * sigma);
        }
        if norm == 0.0 {
            dir.fill(1.0);
            norm = 1.0;
        }
    }
    Some(1.2 * largest)
}

/// Integrate `system` by RKC from `t = 0`, state `y0`, and call `out(i, y)` with the
/// state at each `grid[i]` (non-decreasing, ≥ 0); events as in [`super::integrate`].
pub fn integrate<S, F>(
    system: &mut S,
    y0: &[f64],
    grid: &[f64],
    options: &SolverOptions,
    mut out: F,
) -> Result<SolverStats, SimulationError>
where
    S: HybridSystem,
    F: FnMut(usize, &[f64]),
{
    let n = system.dim();
    assert_eq!(y0.len(), n, "state dimension");
    let mut stats = SolverStats::default();
    let Some(&t_end) = grid.last() else {
        return Ok(stats);
    };

    let mut t = 0.0;
    let mut next_out = outputs_at_start(grid, y0, &mut out);
    if next_out == grid.len() {
        return Ok(stats);
    }

    let ne = system.event_count();
    let mut g_old = vec![0.0; ne];
    let mut g_new = vec![0.0; ne];
    let mut g_tmp = vec![0.0; ne];

    // The step's ends live in the interpolant: `y0`/`f0` at `t`, `y1`/`f1` at `t + h`.
    let mut step = Hermite {
        t0: 0.0,
        h: 0.0,
        y0: y0.to_vec(),
        y1: vec![0.0; n],
        f0: vec![0.0; n],
        f1: vec![0.0; n],
    };
    let mut yjm1 = vec![0.0; n];
    let mut yjm2 = vec![0.0; n];
    let mut ytmp = vec![0.0; n];
    let mut work: [Vec<f64>; 2] = std::array::from_fn(|_| vec![0.0; n]);
    let mut dir = vec![0.0; n];

    let restart = |system: &mut S,
                   t: f64,
                   step: &mut Hermite,
                   g_old: &mut [f64],
                   stats: &mut SolverStats|
     -> Result<(), SimulationError> {
        system.rhs(t, &step.y0, &mut step.f0);
        stats.rhs_evaluations += 1;
        if step.f0.iter().any(|v| !v.is_finite()) {
            return Err(SimulationError::Diverged { time: t });
        }
        system.events(t, &step.y0, g_old);
        Ok(())
    };
    restart(system, t, &mut step, &mut g_old, &mut stats)?;

    let mut rho = f64::NAN;
    let mut since_estimate = 0;
    let mut h = f64::NAN;
    let mut h_old = f64::NAN;
    let mut err_old = f64::NAN;
    let mut last_rejected = false;
    let mut zeno = ZenoGuard::new(t_end);

    loop {
        if stats.accepted_steps + stats.rejected_steps >= options.max_steps {
            return Err(SimulationError::StepLimit {
                limit: options.max_steps,
                time: t,
            });
        }
        if !rho.is_finite() || since_estimate >= SPECTRAL_REFRESH {
            rho = spectral_radius(
                &*system, t, &step.y0, &step.f0, &mut dir, options, &mut work, &mut stats,
            )
            .ok_or(SimulationError::Diverged { time: t })?;
            since_estimate = 0;
        }
        if !h.is_finite() {
            h = initial_step(
                &*system,
                t,
                &step,
                rho,
                t_end - t,
                options,
                &mut ytmp,
                &mut work[0],
            );
            stats.rhs_evaluations += 1;
        }
        let remaining = t_end - t;
        let mut last_step = false;
        if h >= remaining * (1.0 - 1e-12) {
            h = remaining;
            last_step = true;
        }
        // Stages for stability, `h` shortened when even the most are not enough.
        let mut stages = 1 + (1.0 + 1.54 * h * rho).sqrt() as usize;
        if stages > MAX_STAGES {
            stages = MAX_STAGES;
            h = ((stages - 1).pow(2) - 1) as f64 / (1.54 * rho);
            last_step = false;
        }
        let stages = stages.max(2);
        if h <= 1e-14 * t.abs().max(1.0) {
            return Err(SimulationError::StepTooSmall { time: t });
        }

        chebyshev_step(
            &*system,
            t,
            h,
            stages,
            &step.y0,
            &step.f0,
            &mut yjm1,
            &mut yjm2,
            &mut step.y1,
        );
        stats.rhs_evaluations += stages - 1;
        system.rhs(t + h, &step.y1, &mut step.f1);
        stats.rhs_evaluations += 1;

        let mut err = 0.0;
        for i in 0..n {
            let e = (12.0 * (step.y0[i] - step.y1[i]) + 6.0 * h * (step.f0[i] + step.f1[i]))
                / 15.0
                / weight(options, step.y0[i], step.y1[i]);
            err += e * e;
        }
        let err = (err / n as f64).sqrt();
        if !err.is_finite() {
            if h < 1e-10 {
                return Err(SimulationError::Diverged { time: t });
            }
            stats.rejected_steps += 1;
            h *= 0.1;
            last_rejected = true;
            rho = f64::NAN;
            continue;
        }
        if err > 1.0 {
            stats.rejected_steps += 1;
            h *= 0.8 / err.cbrt();
            if last_rejected {
                // Rejected twice in a row: the state may have turned stiffer.
                rho = f64::NAN;
            }
            last_rejected = true;
            continue;
        }

        stats.accepted_steps += 1;
        since_estimate += 1;
        step.t0 = t;
        step.h = h;
        let t_new = if last_step { t_end } else { t + h };
        let event = first_event(
            &*system, &step, t, t_new, &step.y1, &g_old, &mut g_new, &mut ytmp, &mut g_tmp,
        );
        let end = match event {
            None => StepEnd::Reached(t_new, &step.y1),
            Some((_, te)) => StepEnd::Event(te),
        };
        outputs_of_step(grid, &mut next_out, end, &step, &mut ytmp, &mut out);

        match event {
            None => {
                t = t_new;
                std::mem::swap(&mut step.y0, &mut step.y1);
                std::mem::swap(&mut step.f0, &mut step.f1);
                std::mem::swap(&mut g_old, &mut g_new);
                if next_out == grid.len() {
                    return Ok(stats);
                }
                // 0.8 err^(−1/3), with the predictive correction of the RKC code.
                let cbrt = err.max(1e-10).cbrt();
                let mut fac: f64 = 10.0;
                if err_old.is_finite() {
                    fac = fac.min(0.8 * (h / h_old) * err_old.cbrt() / (cbrt * cbrt));
                }
                fac = fac.min(0.8 / cbrt).max(0.1);
                if last_rejected {
                    fac = fac.min(1.0);
                }
                h_old = h;
                err_old = err.max(1e-10);
                h *= fac;
                last_rejected = false;
            }
            Some((e, te)) => {
                stats.events += 1;
                let mut y = vec![0.0; n];
                step.eval(te, &mut y);
                t = te;
                switch_mode(system, &mut zeno, t, &mut y, e)?;
                if next_out == grid.len() {
                    return Ok(stats);
                }
                step.y0.copy_from_slice(&y);
                restart(system, t, &mut step, &mut g_old, &mut stats)?;
                h = (te - step.t0).max(0.1 * h).max(1e-6);
                h_old = f64::NAN;
                err_old = f64::NAN;
                rho = f64::NAN;
                last_rejected = false;
            }
        }
    }
}

/// One RKC step of `stages` stages from `(t, y)`, `f0 = F(t, y)`, into `y_new`.
#[allow(clippy::too_many_arguments)]
fn chebyshev_step<S: HybridSystem>(
    system: &S,
    t: f64,
    h: f64,
    stages: usize,
    y: &[f64],
    f0: &[f64],
    yjm1: &mut Vec<f64>,
    yjm2: &mut Vec<f64>,
    y_new: &mut Vec<f64>,
) {
    let n = y.len();
    let s = stages as f64;
    let w0 = 1.0 + 2.0 / (13.0 * s * s);
    let temp1 = w0 * w0 - 1.0;
    let temp2 = temp1.sqrt();
    let arg = s * (w0 + temp2).ln();
    // w1 = T_s'(w0) / T_s''(w0).
    let w1 = arg.sinh() * temp1 / (arg.cosh() * s * temp2 - w0 * arg.sinh());
    let mut bjm1 = 1.0 / (4.0 * w0 * w0);
    let mut bjm2 = bjm1;
    // Stage 1.
    let mus = w1 * bjm1;
    yjm2.copy_from_slice(y);
    for i in 0..n {
        yjm1[i] = y[i] + h * mus * f0[i];
    }
    let mut thjm2 = 0.0;
    let mut thjm1 = mus;
    // T_j(w0), T_j'(w0), T_j''(w0) for j − 1 and j − 2.
    let (mut zjm1, mut zjm2) = (w0, 1.0);
    let (mut dzjm1, mut dzjm2) = (1.0, 0.0);
    let (mut d2zjm1, mut d2zjm2) = (0.0, 0.0);
    for _ in 2..=stages {
        let zj = 2.0 * w0 * zjm1 - zjm2;
        let dzj = 2.0 * w0 * dzjm1 - dzjm2 + 2.0 * zjm1;
        let d2zj = 2.0 * w0 * d2zjm1 - d2zjm2 + 4.0 * dzjm1;
        let bj = d2zj / (dzj * dzj);
        let ajm1 = 1.0 - zjm1 * bjm1;
        let mu = 2.0 * w0 * bj / bjm1;
        let nu = -bj / bjm2;
        let mus = mu * w1 / w0;
        // The new stage is built in `y_new`, starting from F(Y_{j−1}).
        system.rhs(t + h * thjm1, yjm1, y_new);
        for i in 0..n {
            y_new[i] = mu * yjm1[i]
                + nu * yjm2[i]
                + (1.0 - mu - nu) * y[i]
                + h * mus * (y_new[i] - ajm1 * f0[i]);
        }
        let thj = mu * thjm1 + nu * thjm2 + mus * (1.0 - ajm1);
        thjm2 = thjm1;
        thjm1 = thj;
        std::mem::swap(yjm2, yjm1);
        std::mem::swap(yjm1, y_new);
        (zjm2, zjm1) = (zjm1, zj);
        (dzjm2, dzjm1) = (dzjm1, dzj);
        (d2zjm2, d2zjm1) = (d2zjm1, d2zj);
        bjm2 = bjm1;
        bjm1 = bj;
    }
    // The last stage is in `yjm1`.
    std::mem::swap(yjm1, y_new);
}

/// Starting step of the RKC code: `1/ρ` at most, shortened until a forward difference of
/// the right-hand side says its error would be well inside the tolerance. Costs one
/// right-hand side.
#[allow(clippy::too_many_arguments)]
fn initial_step<S: HybridSystem>(
    system: &S,
    t: f64,
    step: &Hermite,
    rho: f64,
    span: f64,
    options: &SolverOptions,
    ytmp: &mut [f64],
    ftmp: &mut [f64],
) -> f64 {
    let n = ytmp.len();
    let mut h = span;
    if rho * h > 1.0 {
        h = 1.0 / rho;
    }
    for (i, y) in ytmp.iter_mut().enumerate() {
        *y = step.y0[i] + h * step.f0[i];
    }
    system.rhs(t + h, ytmp, ftmp);
    let mut est = 0.0;
    for (i, f) in ftmp.iter().enumerate() {
        let e = (f - step.f0[i]) / weight(options, step.y0[i], step.y0[i]);
        est += e * e;
    }
    let est = h * (est / n as f64).sqrt();
    if 0.1 * h < span * est.sqrt() {
        0.1 * h / est.sqrt()
    } else {
        span
    }
}

#[cfg(test)]
mod tests {
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
}
