//! Dormand–Prince 5(4) with dense output and event location, for hybrid systems.
//!
//! An explicit embedded Runge–Kutta pair of order 5 with an error estimate of order 4,
//! local extrapolation, a PI step-size controller and the continuous extension of order 4
//! from Hairer's `DOPRI5`. Outputs are read off the dense output at the requested times, so
//! the step size is set by accuracy alone, never by the output grid.
//!
//! Hybrid systems (mode switches such as stick–slip friction) declare event functions
//! `g_k(t, y)`. An event fires when `g_k` goes from `≥ 0` to `< 0` within an accepted step;
//! its time is located on the dense output by the Illinois variant of regula falsi, the step
//! is cut there, the system switches mode (and may reset the state), and integration restarts
//! from the event with a fresh first stage. The right-hand side is therefore always smooth
//! inside a step, which is what the error control assumes.
//!
//! Events may accumulate: a ball bouncing ever lower, a friction model switching between
//! sliding forward and backward around a speed of zero. Such a Zeno point would cost every
//! step allowed, each with a root search. The [`ZenoGuard`] watches the event times; when
//! [`ZENO_EVENTS`] events fall within a span that is tiny next to the integrated one, the
//! system is asked to take the mode the switching approximates (a ball at rest, a joint held
//! stuck: [`HybridSystem::on_chattering`]); a system that has none, or that chatters again
//! at once, ends the simulation with [`SimulationError::Chattering`] naming the time and the
//! event.
//!
//! For mildly stiff systems whose step size this method's stability would set, the
//! Runge–Kutta–Chebyshev method of [`rkc`] takes the same systems, grids and events.
//!
//! References:
//! - J. R. Dormand, P. J. Prince, "A family of embedded Runge–Kutta formulae",
//!   J. Comp. Appl. Math. 6 (1980) 19–26.
//! - E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*,
//!   2nd ed., Springer 1993, §II.4–II.6 (step control, dense output) and the `DOPRI5` code.
//! - L. F. Shampine, S. Thompson, "Event location for ordinary differential equations",
//!   Computers & Mathematics with Applications 39 (2000) 43–54.

use crate::model::{SimulationError, SolverOptions, SolverStats};

pub mod rkc;

/// A system of first-order ODEs, possibly with discrete modes switched at events.
pub trait HybridSystem {
    /// Dimension of the state.
    fn dim(&self) -> usize;

    /// `dy = f(t, y)` in the current mode.
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]);

    /// Number of event functions (constant for the life of the system).
    fn event_count(&self) -> usize {
        0
    }

    /// Event functions in the current mode; event `k` fires when `g[k]` goes from `≥ 0` to `< 0`.
    fn events(&self, _t: f64, _y: &[f64], _g: &mut [f64]) {}

    /// Called at a located event: switch mode, and adjust the state if the physics demands it.
    fn on_event(&mut self, _t: f64, _y: &mut [f64], _event: usize) {}

    /// What event `k` stands for, for error messages.
    fn event_name(&self, event: usize) -> String {
        format!("event #{event}")
    }

    /// Called when events accumulate at `t` (a Zeno point), `event` being the last to fire:
    /// switch to the mode the switching approximates (a ball at rest, a joint held stuck
    /// while its driving torque stays within the static friction), adjust the state, and
    /// return `true`; return `false` when there is no such mode, which ends the simulation
    /// with [`SimulationError::Chattering`].
    fn on_chattering(&mut self, _t: f64, _y: &mut [f64], _event: usize) -> bool {
        false
    }
}

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

/// Events the [`ZenoGuard`] looks back over.
pub const ZENO_EVENTS: usize = 32;
/// Span of [`ZENO_EVENTS`] events, relative to the integrated span, below which events are
/// taken to accumulate: a millionth of a second over a 1000 s simulation.
const ZENO_RELATIVE_SPAN: f64 = 1e-9;

/// Detects events that accumulate at one time: [`ZENO_EVENTS`] of them within a span tiny
/// next to the integrated one. Located events come strictly one after the other, so a count
/// of events at an identical time would never see them.
struct ZenoGuard {
    /// Times of the last events, oldest first once full.
    times: std::collections::VecDeque<f64>,
    span: f64,
    /// When the system last resolved an accumulation by switching mode.
    resolved_at: Option<f64>,
}

/// What the guard makes of an event.
#[derive(Debug, PartialEq)]
enum Zeno {
    /// Events are not accumulating.
    Clear,
    /// Events accumulate: the system must take the mode the switching approximates.
    Accumulating,
    /// Events accumulate again right after the system switched mode for that: give up.
    Persisting,
}

impl ZenoGuard {
    fn new(t_end: f64) -> Self {
        Self {
            times: std::collections::VecDeque::with_capacity(ZENO_EVENTS),
            span: ZENO_RELATIVE_SPAN * t_end.abs().max(1.0),
            resolved_at: None,
        }
    }

    fn record(&mut self, t: f64) -> Zeno {
        if self.times.len() == ZENO_EVENTS {
            self.times.pop_front();
        }
        self.times.push_back(t);
        let oldest = self.times[0];
        if self.times.len() < ZENO_EVENTS || t - oldest > self.span {
            return Zeno::Clear;
        }
        self.times.clear();
        match self.resolved_at {
            Some(resolved) if oldest - resolved <= self.span => Zeno::Persisting,
            _ => {
                self.resolved_at = Some(t);
                Zeno::Accumulating
            }
        }
    }
}

/// The continuous extension of one accepted step.
struct Dense {
    t0: f64,
    h: f64,
    r: [Vec<f64>; 5],
}

impl Dense {
    fn new(n: usize) -> Self {
        Self {
            t0: 0.0,
            h: 0.0,
            r: std::array::from_fn(|_| vec![0.0; n]),
        }
    }
}

/// A continuous extension of one accepted step, on which events are located.
trait Interpolant {
    /// The state at time `t` inside the step.
    fn eval(&self, t: f64, out: &mut [f64]);
}

impl Interpolant for Dense {
    fn eval(&self, t: f64, out: &mut [f64]) {
        let theta = (t - self.t0) / self.h;
        let theta1 = 1.0 - theta;
        let [r1, r2, r3, r4, r5] = &self.r;
        for i in 0..out.len() {
            out[i] = r1[i] + theta * (r2[i] + theta1 * (r3[i] + theta * (r4[i] + theta1 * r5[i])));
        }
    }
}

/// Integrate `system` from `t = 0`, state `y0`, and call `out(i, y)` with the state at each
/// `grid[i]` (non-decreasing, ≥ 0).
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
    let mut y = y0.to_vec();
    let mut next_out = outputs_at_start(grid, &y, &mut out);
    if next_out == grid.len() {
        return Ok(stats);
    }

    let ne = system.event_count();
    let mut g_old = vec![0.0; ne];
    let mut g_new = vec![0.0; ne];
    let mut g_tmp = vec![0.0; ne];

    let mut k: [Vec<f64>; 7] = std::array::from_fn(|_| vec![0.0; n]);
    let mut ytmp = vec![0.0; n];
    let mut ynew = vec![0.0; n];
    let mut yerr = vec![0.0; n];
    let mut dense = Dense::new(n);

    system.rhs(t, &y, &mut k[0]);
    stats.rhs_evaluations += 1;
    system.events(t, &y, &mut g_old);

    let mut h = initial_step(system, t, &y, &k[0], t_end - t, options, &mut stats);
    let mut fac_old: f64 = 1e-4;
    let mut last_rejected = false;
    let mut zeno = ZenoGuard::new(t_end);

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

        // Stages 2..7 (stage 1 is k[0], first-same-as-last).
        {
            let (k1, rest) = k.split_first_mut().expect("seven stages");
            let [k2, k3, k4, k5, k6, k7] = rest else {
                unreachable!()
            };
            for i in 0..n {
                ytmp[i] = y[i] + h * A21 * k1[i];
            }
            system.rhs(t + C2 * h, &ytmp, k2);
            for i in 0..n {
                ytmp[i] = y[i] + h * (A31 * k1[i] + A32 * k2[i]);
            }
            system.rhs(t + C3 * h, &ytmp, k3);
            for i in 0..n {
                ytmp[i] = y[i] + h * (A41 * k1[i] + A42 * k2[i] + A43 * k3[i]);
            }
            system.rhs(t + C4 * h, &ytmp, k4);
            for i in 0..n {
                ytmp[i] = y[i] + h * (A51 * k1[i] + A52 * k2[i] + A53 * k3[i] + A54 * k4[i]);
            }
            system.rhs(t + C5 * h, &ytmp, k5);
            for i in 0..n {
                ytmp[i] = y[i]
                    + h * (A61 * k1[i] + A62 * k2[i] + A63 * k3[i] + A64 * k4[i] + A65 * k5[i]);
            }
            system.rhs(t + h, &ytmp, k6);
            for i in 0..n {
                ynew[i] = y[i]
                    + h * (A71 * k1[i] + A73 * k3[i] + A74 * k4[i] + A75 * k5[i] + A76 * k6[i]);
            }
            system.rhs(t + h, &ynew, k7);
            stats.rhs_evaluations += 6;
            for i in 0..n {
                yerr[i] = h
                    * (E1 * k1[i] + E3 * k3[i] + E4 * k4[i] + E5 * k5[i] + E6 * k6[i] + E7 * k7[i]);
            }
        }

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
            stats.rejected_steps += 1;
            h *= FAC_MIN;
            last_rejected = true;
            continue;
        }

        let fac11 = err.powf(EXPO1);
        if err > 1.0 {
            stats.rejected_steps += 1;
            h /= (fac11 / SAFETY).min(1.0 / FAC_MIN);
            last_rejected = true;
            continue;
        }

        // Accepted: build the dense output of [t, t + h].
        stats.accepted_steps += 1;
        dense.t0 = t;
        dense.h = h;
        for i in 0..n {
            let ydiff = ynew[i] - y[i];
            let bspl = h * k[0][i] - ydiff;
            dense.r[0][i] = y[i];
            dense.r[1][i] = ydiff;
            dense.r[2][i] = bspl;
            dense.r[3][i] = ydiff - h * k[6][i] - bspl;
            dense.r[4][i] = h
                * (D1 * k[0][i]
                    + D3 * k[2][i]
                    + D4 * k[3][i]
                    + D5 * k[4][i]
                    + D6 * k[5][i]
                    + D7 * k[6][i]);
        }
        let t_new = if last_step { t_end } else { t + h };

        let event = first_event(
            system, &dense, t, t_new, &ynew, &g_old, &mut g_new, &mut ytmp, &mut g_tmp,
        );

        let end = match event {
            None => StepEnd::Reached(t_new, &ynew),
            Some((_, te)) => StepEnd::Event(te),
        };
        outputs_of_step(grid, &mut next_out, end, &dense, &mut ytmp, &mut out);

        match event {
            None => {
                t = t_new;
                std::mem::swap(&mut y, &mut ynew);
                k.swap(0, 6);
                std::mem::swap(&mut g_old, &mut g_new);
                if next_out == grid.len() {
                    return Ok(stats);
                }
                let mut fac = fac11 / fac_old.powf(BETA);
                fac = (fac / SAFETY).clamp(1.0 / FAC_MAX, 1.0 / FAC_MIN);
                let mut h_new = h / fac;
                if last_rejected {
                    h_new = h_new.min(h);
                }
                fac_old = err.max(1e-4);
                h = h_new;
                last_rejected = false;
            }
            Some((e, te)) => {
                stats.events += 1;
                dense.eval(te, &mut y);
                t = te;
                switch_mode(system, &mut zeno, t, &mut y, e)?;
                if next_out == grid.len() {
                    return Ok(stats);
                }
                system.rhs(t, &y, &mut k[0]);
                stats.rhs_evaluations += 1;
                system.events(t, &y, &mut g_old);
                // Restart with the step that reached the event, at least a fraction of the
                // accepted one so the controller does not crawl after every switch.
                h = (te - dense.t0).max(0.1 * h).max(1e-6);
                fac_old = 1e-4;
                last_rejected = false;
            }
        }
    }
}

/// Record the outputs at the grid times up to the start (`t = 0`, state `y0`); the index of
/// the first grid time after it.
fn outputs_at_start<F: FnMut(usize, &[f64])>(grid: &[f64], y0: &[f64], out: &mut F) -> usize {
    let mut next_out = 0;
    while next_out < grid.len() && grid[next_out] <= 0.0 {
        out(next_out, y0);
        next_out += 1;
    }
    next_out
}

/// Where an accepted step's outputs stop.
enum StepEnd<'a> {
    /// At the step's end `t_new`, whose state is known exactly.
    Reached(f64, &'a [f64]),
    /// At an event inside the step.
    Event(f64),
}

/// Record the outputs at the grid times of an accepted step from `grid[*next_out]` up to
/// its end: read off the continuous extension, except a grid time at the step's very end,
/// which takes the step's state.
fn outputs_of_step<D: Interpolant, F: FnMut(usize, &[f64])>(
    grid: &[f64],
    next_out: &mut usize,
    end: StepEnd,
    dense: &D,
    ytmp: &mut [f64],
    out: &mut F,
) {
    let t_stop = match end {
        StepEnd::Reached(t_new, _) | StepEnd::Event(t_new) => t_new,
    };
    while *next_out < grid.len() && grid[*next_out] <= t_stop {
        match end {
            StepEnd::Reached(t_new, y_new) if grid[*next_out] == t_new => out(*next_out, y_new),
            _ => {
                dense.eval(grid[*next_out], ytmp);
                out(*next_out, ytmp);
            }
        }
        *next_out += 1;
    }
}

/// The earliest event of the accepted step `[t, t_new]` (state `ynew` at its end, event
/// functions `g_old` at its start): the first event function to change sign from `≥ 0` to
/// `< 0`, located on the step's continuous extension. Leaves the event functions at
/// `t_new` in `g_new`.
#[allow(clippy::too_many_arguments)]
fn first_event<S: HybridSystem, D: Interpolant>(
    system: &S,
    dense: &D,
    t: f64,
    t_new: f64,
    ynew: &[f64],
    g_old: &[f64],
    g_new: &mut [f64],
    ytmp: &mut [f64],
    g_tmp: &mut [f64],
) -> Option<(usize, f64)> {
    let mut event: Option<(usize, f64)> = None;
    if !g_old.is_empty() {
        system.events(t_new, ynew, g_new);
        for e in 0..g_old.len() {
            if g_old[e] >= 0.0 && g_new[e] < 0.0 {
                let te = locate_event(system, dense, e, t, t_new, g_old[e], g_new[e], ytmp, g_tmp);
                if event.is_none_or(|(_, best)| te < best) {
                    event = Some((e, te));
                }
            }
        }
    }
    event
}

/// Let the system switch mode at the located event `e` (time `t`, state `y`), or take the
/// mode that accumulating events approximate; fails when they accumulate and it has none.
fn switch_mode<S: HybridSystem>(
    system: &mut S,
    zeno: &mut ZenoGuard,
    t: f64,
    y: &mut [f64],
    e: usize,
) -> Result<(), SimulationError> {
    system.on_event(t, y, e);
    let resolved = match zeno.record(t) {
        Zeno::Clear => true,
        Zeno::Accumulating => system.on_chattering(t, y, e),
        Zeno::Persisting => false,
    };
    if resolved {
        Ok(())
    } else {
        Err(SimulationError::Chattering {
            time: t,
            event: system.event_name(e),
            events: ZENO_EVENTS,
            span: zeno.span,
        })
    }
}

/// Time of the zero of event `e` in `[ta, tb]`, where `g(ta) ≥ 0 > g(tb)`: the returned time
/// is on the negative side, so the event condition holds there.
#[allow(clippy::too_many_arguments)]
fn locate_event<S: HybridSystem, D: Interpolant>(
    system: &S,
    dense: &D,
    e: usize,
    mut ta: f64,
    mut tb: f64,
    mut ga: f64,
    mut gb: f64,
    y: &mut [f64],
    g: &mut [f64],
) -> f64 {
    let tol = 1e-13 * tb.abs().max(1.0);
    let mut side = 0i8;
    for _ in 0..100 {
        if tb - ta <= tol {
            break;
        }
        let mut tc = (ta * gb - tb * ga) / (gb - ga);
        if !(tc > ta && tc < tb) {
            tc = 0.5 * (ta + tb);
        }
        dense.eval(tc, y);
        system.events(tc, y, g);
        let gc = g[e];
        if gc < 0.0 {
            tb = tc;
            gb = gc;
            if side == -1 {
                ga *= 0.5;
            }
            side = -1;
        } else {
            ta = tc;
            ga = gc;
            if side == 1 {
                gb *= 0.5;
            }
            side = 1;
        }
    }
    tb
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
    use std::cell::Cell;

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

    /// A ball dropped from 1 m bouncing with restitution 0.5: event times in closed form.
    /// The bounces accumulate at 3·t1 ≈ 1.355 s (t1 the first contact); from there the ball
    /// rests on the floor, if it may.
    struct Ball {
        bounces: Vec<f64>,
        may_rest: bool,
        rests_since: Option<f64>,
        probes: Cell<usize>,
    }
    impl Ball {
        fn new(may_rest: bool) -> Self {
            Self {
                bounces: vec![],
                may_rest,
                rests_since: None,
                probes: Cell::new(0),
            }
        }
    }
    impl HybridSystem for Ball {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
            dy[0] = y[1];
            dy[1] = if self.rests_since.is_some() {
                0.0
            } else {
                -9.81
            };
        }
        fn event_count(&self) -> usize {
            1
        }
        fn events(&self, _t: f64, y: &[f64], g: &mut [f64]) {
            self.probes.set(self.probes.get() + 1);
            // Fires when the ball, falling, reaches the floor.
            g[0] = if y[1] < 0.0 { y[0] } else { 1.0 };
        }
        fn on_event(&mut self, t: f64, y: &mut [f64], _event: usize) {
            self.bounces.push(t);
            y[0] = 0.0;
            y[1] *= -0.5;
        }
        fn event_name(&self, _event: usize) -> String {
            "floor contact".into()
        }
        fn on_chattering(&mut self, t: f64, y: &mut [f64], _event: usize) -> bool {
            if self.may_rest {
                self.rests_since = Some(t);
                y.fill(0.0);
            }
            self.may_rest
        }
    }

    fn first_contact() -> f64 {
        (2.0f64 / 9.81).sqrt()
    }

    #[test]
    fn events_are_located_on_the_dense_output() {
        let mut ball = Ball::new(false);
        let opts = SolverOptions::default();
        integrate(&mut ball, &[1.0, 0.0], &[1.2], &opts, |_, _| {}).unwrap();
        let t1 = first_contact();
        let v1 = 9.81 * t1;
        let t2 = t1 + 2.0 * 0.5 * v1 / 9.81;
        assert!((ball.bounces[0] - t1).abs() < 1e-9, "{:?}", ball.bounces);
        assert!((ball.bounces[1] - t2).abs() < 1e-9, "{:?}", ball.bounces);
    }

    #[test]
    fn bounces_that_accumulate_end_at_rest_on_the_floor() {
        let mut ball = Ball::new(true);
        let grid = [1.0, 2.0, 3.0];
        let mut heights = vec![f64::NAN; grid.len()];
        let stats = integrate(
            &mut ball,
            &[1.0, 0.0],
            &grid,
            &SolverOptions::default(),
            |i, y| {
                heights[i] = y[0];
            },
        )
        .unwrap();
        let rest = ball.rests_since.expect("the ball comes to rest");
        assert!(
            (rest - 3.0 * first_contact()).abs() < 1e-6,
            "rests at {rest}"
        );
        assert!(heights[0] > 0.0);
        assert_eq!(&heights[1..], &[0.0, 0.0]);
        // A bounded amount of work: the bounces down to the guard's span, and no more.
        assert!(stats.events < 2 * ZENO_EVENTS + 40, "{stats:?}");
        assert!(
            stats.accepted_steps + stats.rejected_steps < 1_000,
            "{stats:?}"
        );
        assert!(
            ball.probes.get() < 10_000,
            "{} event probes",
            ball.probes.get()
        );
    }

    #[test]
    fn bounces_that_accumulate_without_a_resting_mode_are_a_typed_error() {
        let mut ball = Ball::new(false);
        let r = integrate(
            &mut ball,
            &[1.0, 0.0],
            &[3.0],
            &SolverOptions::default(),
            |_, _| {},
        );
        let Err(SimulationError::Chattering { time, event, .. }) = r else {
            panic!("{r:?}");
        };
        assert!((time - 3.0 * first_contact()).abs() < 1e-6, "at {time}");
        assert_eq!(event, "floor contact");
        assert!(
            ball.bounces.len() < 2 * ZENO_EVENTS + 40,
            "{}",
            ball.bounces.len()
        );
        assert!(
            ball.probes.get() < 10_000,
            "{} event probes",
            ball.probes.get()
        );
    }

    /// A block of unit mass under the force u(t) = 1.5·sin t with Coulomb friction 1, state
    /// (x, v), started forward at v = 0.2. Its friction is written as a relay, sliding
    /// forward or backward, with the sticking mode only as the mode its chattering
    /// approximates: held at v = 0 until |u| exceeds the friction.
    struct Block {
        sliding: Option<f64>,
        may_stick: bool,
        probes: Cell<usize>,
        rhs_calls: Cell<usize>,
    }
    const BLOCK_FRICTION: f64 = 1.0;
    fn block_force(t: f64) -> f64 {
        1.5 * t.sin()
    }
    impl Block {
        fn new(may_stick: bool) -> Self {
            Self {
                sliding: Some(1.0),
                may_stick,
                probes: Cell::new(0),
                rhs_calls: Cell::new(0),
            }
        }
    }
    impl HybridSystem for Block {
        fn dim(&self) -> usize {
            2
        }
        fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
            self.rhs_calls.set(self.rhs_calls.get() + 1);
            dy[0] = y[1];
            dy[1] = match self.sliding {
                Some(direction) => block_force(t) - BLOCK_FRICTION * direction,
                None => 0.0,
            };
        }
        fn event_count(&self) -> usize {
            1
        }
        fn events(&self, t: f64, y: &[f64], g: &mut [f64]) {
            self.probes.set(self.probes.get() + 1);
            g[0] = match self.sliding {
                Some(direction) => direction * y[1],
                None => BLOCK_FRICTION - block_force(t).abs(),
            };
        }
        fn on_event(&mut self, t: f64, y: &mut [f64], _event: usize) {
            self.sliding = Some(match self.sliding {
                // The speed crossed zero: the relay turns the friction round.
                Some(direction) => {
                    y[1] = 0.0;
                    -direction
                }
                // Breakaway, the way the force pushes.
                None => block_force(t).signum(),
            });
        }
        fn event_name(&self, _event: usize) -> String {
            "block friction".into()
        }
        fn on_chattering(&mut self, _t: f64, y: &mut [f64], _event: usize) -> bool {
            if self.may_stick {
                self.sliding = None;
                y[1] = 0.0;
            }
            self.may_stick
        }
    }

    /// When the block, sliding forward from v = 0.2, first stops: v(t) = 0.2 + 1.5·(1 − cos t) − t.
    fn block_stops() -> f64 {
        let mut t: f64 = 0.2;
        for _ in 0..50 {
            t -= (0.2 + 1.5 * (1.0 - t.cos()) - t) / (1.5 * t.sin() - 1.0);
        }
        t
    }

    #[test]
    fn chattering_friction_sticks_until_the_force_breaks_it_away() {
        let stop = block_stops();
        let breakaway = (BLOCK_FRICTION / 1.5).asin();
        assert!(
            stop < 0.3 && breakaway > 0.7,
            "stop {stop}, breakaway {breakaway}"
        );
        let x_stop = 0.2 * stop + 1.5 * (stop - stop.sin()) - 0.5 * stop * stop;
        let grid: Vec<f64> = (0..=15).map(|i| i as f64 * 0.1).collect();
        let mut states = vec![[f64::NAN; 2]; grid.len()];
        let mut block = Block::new(true);
        let stats = integrate(
            &mut block,
            &[0.0, 0.2],
            &grid,
            &SolverOptions::default(),
            |i, y| {
                states[i] = [y[0], y[1]];
            },
        )
        .unwrap();
        for (t, [x, v]) in grid.iter().zip(&states) {
            if *t > stop + 1e-3 && *t < breakaway - 1e-3 {
                assert_eq!(*v, 0.0, "speed at {t}");
                assert!((x - x_stop).abs() < 1e-9, "x({t}) = {x}, stuck at {x_stop}");
            }
        }
        // Sliding forward again after the breakaway, as the closed form says.
        let v_end = 1.5 * (breakaway.cos() - 1.5f64.cos()) - (1.5 - breakaway);
        assert!(
            (states[15][1] - v_end).abs() < 1e-7,
            "{:?} vs {v_end}",
            states[15]
        );
        assert!(stats.events < ZENO_EVENTS + 8, "{stats:?}");
        assert!(
            block.probes.get() < 10_000,
            "{} event probes",
            block.probes.get()
        );
        assert!(
            block.rhs_calls.get() < 5_000,
            "{} rhs calls",
            block.rhs_calls.get()
        );
    }

    #[test]
    fn chattering_without_a_sticking_mode_stops_early_with_a_typed_error() {
        let mut block = Block::new(false);
        let r = integrate(
            &mut block,
            &[0.0, 0.2],
            &[10.0],
            &SolverOptions::default(),
            |_, _| {},
        );
        let Err(SimulationError::Chattering {
            time, ref event, ..
        }) = r
        else {
            panic!("{r:?}");
        };
        assert!((time - block_stops()).abs() < 1e-9, "at {time}");
        assert_eq!(event, "block friction");
        let message = r.unwrap_err().to_string();
        assert!(message.contains("block friction") && message.contains(&format!("{time}")));
        // Without the guard the relay would take every allowed step, each with a root search.
        assert!(
            block.probes.get() < 10_000,
            "{} event probes",
            block.probes.get()
        );
        assert!(
            block.rhs_calls.get() < 5_000,
            "{} rhs calls",
            block.rhs_calls.get()
        );
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
