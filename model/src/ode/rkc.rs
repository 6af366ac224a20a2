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
//!   F_{n+1}`, of third order, on which the shared driver reads the outputs and
//!   locates the events exactly as for Dormand–Prince.
//!
//! References:
//! - B. P. Sommeijer, L. F. Shampine, J. G. Verwer, "RKC: an explicit solver for parabolic
//!   PDEs", J. Comput. Appl. Math. 88 (1998) 315–326.
//! - J. G. Verwer, W. H. Hundsdorfer, B. P. Sommeijer, "Convergence properties of the
//!   Runge–Kutta–Chebyshev method", Numer. Math. 57 (1990) 157–178.
//! - E. Hairer, G. Wanner, *Solving Ordinary Differential Equations II*, 2nd ed., Springer
//!   1996, §IV.2 (stabilised explicit methods).

use super::driver::{drive, Interpolant, Stepper, Trial};
use super::HybridSystem;
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
    out: F,
) -> Result<SolverStats, SimulationError>
where
    S: HybridSystem,
    F: FnMut(usize, &[f64]),
{
    drive(system, &mut Rkc::new(y0.len()), y0, grid, options, out)
}

/// The method's state: the last step's ends (in its interpolant), the stages' scratch, and
/// what it carries from step to step.
struct Rkc {
    /// `y0`/`f0` at the current time, `y1`/`f1` at the end of the last attempt.
    step: Hermite,
    yjm1: Vec<f64>,
    yjm2: Vec<f64>,
    ytmp: Vec<f64>,
    work: [Vec<f64>; 2],
    /// The dominant direction of the last spectral radius estimate.
    dir: Vec<f64>,
    /// The spectral radius estimate, NaN when it is to be renewed.
    rho: f64,
    /// Accepted steps since `rho` was estimated.
    since_estimate: usize,
    /// Stages of the next attempt.
    stages: usize,
    /// The last accepted step and its error, for the predictive controller.
    h_old: f64,
    err_old: f64,
}

impl Rkc {
    fn new(n: usize) -> Self {
        let vector = || vec![0.0; n];
        Self {
            step: Hermite {
                t0: 0.0,
                h: 0.0,
                y0: vector(),
                y1: vector(),
                f0: vector(),
                f1: vector(),
            },
            yjm1: vector(),
            yjm2: vector(),
            ytmp: vector(),
            work: std::array::from_fn(|_| vector()),
            dir: vector(),
            rho: f64::NAN,
            since_estimate: 0,
            stages: 2,
            h_old: f64::NAN,
            err_old: f64::NAN,
        }
    }
}

impl Interpolant for Rkc {
    fn eval(&self, t: f64, out: &mut [f64]) {
        self.step.eval(t, out);
    }
}

impl Stepper for Rkc {
    fn state(&self) -> &[f64] {
        &self.step.y0
    }

    fn proposed(&self) -> &[f64] {
        &self.step.y1
    }

    fn restart<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        y: &[f64],
        stats: &mut SolverStats,
    ) -> Result<(), SimulationError> {
        let step = &mut self.step;
        step.y0.copy_from_slice(y);
        system.rhs(t, &step.y0, &mut step.f0);
        stats.rhs_evaluations += 1;
        if step.f0.iter().any(|v| !v.is_finite()) {
            return Err(SimulationError::Diverged { time: t });
        }
        self.h_old = f64::NAN;
        self.err_old = f64::NAN;
        self.rho = f64::NAN;
        Ok(())
    }

    /// Chosen in [`Stepper::prepare`], once the spectral radius is known.
    fn initial_step<S: HybridSystem>(
        &mut self,
        _system: &S,
        _t: f64,
        _span: f64,
        _options: &SolverOptions,
        _stats: &mut SolverStats,
    ) -> f64 {
        f64::NAN
    }

    fn prepare<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        span: f64,
        h: &mut f64,
        options: &SolverOptions,
        stats: &mut SolverStats,
    ) -> Result<(), SimulationError> {
        if !self.rho.is_finite() || self.since_estimate >= SPECTRAL_REFRESH {
            let step = &self.step;
            self.rho = spectral_radius(
                system,
                t,
                &step.y0,
                &step.f0,
                &mut self.dir,
                options,
                &mut self.work,
                stats,
            )
            .ok_or(SimulationError::Diverged { time: t })?;
            self.since_estimate = 0;
        }
        if !h.is_finite() {
            *h = initial_step(
                system,
                t,
                &self.step,
                self.rho,
                span,
                options,
                &mut self.ytmp,
                &mut self.work[0],
            );
            stats.rhs_evaluations += 1;
        }
        Ok(())
    }

    /// Stages for stability, `h` shortened when even the most are not enough.
    fn fit(&mut self, h: &mut f64, last: &mut bool) {
        let mut stages = 1 + (1.0 + 1.54 * *h * self.rho).sqrt() as usize;
        if stages > MAX_STAGES {
            stages = MAX_STAGES;
            *h = ((stages - 1).pow(2) - 1) as f64 / (1.54 * self.rho);
            *last = false;
        }
        self.stages = stages.max(2);
    }

    fn attempt<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        h: f64,
        options: &SolverOptions,
        stats: &mut SolverStats,
    ) -> Result<Trial, SimulationError> {
        let step = &mut self.step;
        chebyshev_step(
            system,
            t,
            h,
            self.stages,
            &step.y0,
            &step.f0,
            &mut self.yjm1,
            &mut self.yjm2,
            &mut step.y1,
        );
        stats.rhs_evaluations += self.stages - 1;
        system.rhs(t + h, &step.y1, &mut step.f1);
        stats.rhs_evaluations += 1;

        let (y0, y1, f0, f1): (&[f64], &[f64], &[f64], &[f64]) =
            (&step.y0, &step.y1, &step.f0, &step.f1);
        let n = y0.len();
        let mut err = 0.0;
        for i in 0..n {
            let e = (12.0 * (y0[i] - y1[i]) + 6.0 * h * (f0[i] + f1[i]))
                / 15.0
                / weight(options, y0[i], y1[i]);
            err += e * e;
        }
        let err = (err / n as f64).sqrt();
        if !err.is_finite() {
            if h < 1e-10 {
                return Err(SimulationError::Diverged { time: t });
            }
            return Ok(Trial::NonFinite);
        }
        Ok(Trial::Error(err))
    }

    fn after_non_finite(&mut self, h: f64) -> f64 {
        self.rho = f64::NAN;
        h * 0.1
    }

    fn after_rejected(&mut self, h: f64, err: f64, again: bool) -> f64 {
        if again {
            // Rejected twice in a row: the state may have turned stiffer.
            self.rho = f64::NAN;
        }
        h * (0.8 / err.cbrt())
    }

    fn accept(&mut self, t: f64, h: f64) {
        self.since_estimate += 1;
        self.step.t0 = t;
        self.step.h = h;
    }

    fn advance(&mut self) {
        let step = &mut self.step;
        std::mem::swap(&mut step.y0, &mut step.y1);
        std::mem::swap(&mut step.f0, &mut step.f1);
    }

    /// `0.8 err^(−1/3)`, with the predictive correction of the RKC code.
    fn next_step(&mut self, h: f64, err: f64, after_rejection: bool) -> f64 {
        let cbrt = err.max(1e-10).cbrt();
        let mut fac: f64 = 10.0;
        if self.err_old.is_finite() {
            fac = fac.min(0.8 * (h / self.h_old) * self.err_old.cbrt() / (cbrt * cbrt));
        }
        fac = fac.min(0.8 / cbrt).max(0.1);
        if after_rejection {
            fac = fac.min(1.0);
        }
        self.h_old = h;
        self.err_old = err.max(1e-10);
        h * fac
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
mod tests;
