//! The one integration loop, shared by the one-step methods of [`super`].
//!
//! A method is a [`Stepper`]: it attempts a step `(t, y, h) → (y_new, error)`, keeps the
//! continuous extension of the last accepted step, and owns its step-size controller and
//! whatever state it carries from step to step (Dormand–Prince the previous error of its PI
//! controller, RKC its spectral radius estimate and its stage count). [`drive`] owns
//! everything the methods share: the outputs at the requested times (read off the continuous
//! extension, so the output grid never sets the step size), the step limit, the clamp of the
//! last step to the end time, the retries after rejected steps, the event location on the
//! continuous extension, the mode switch and the restart from the event (or from the end of a
//! step where the system asks for a step event), and the guard against events that accumulate.
//!
//! The split follows the one of Hairer's codes (`DOPRI5`, and Sommeijer's `RKC` built the same
//! way): the method proposes, the driver decides what becomes of the proposal. The order of
//! every call into the system (right-hand sides and event functions) is part of the contract:
//! systems may cache what the last call computed (the heat exchanger's event function reads
//! the march of the last right-hand side), so a method evaluates its right-hand sides in
//! [`Stepper::restart`], [`Stepper::initial_step`], [`Stepper::prepare`] and
//! [`Stepper::attempt`] only, and the driver the event functions after them.
//!
//! References:
//! - E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*,
//!   2nd ed., Springer 1993, §II.4 (step control) and §II.6 (dense output).
//! - L. F. Shampine, S. Thompson, "Event location for ordinary differential equations",
//!   Computers & Mathematics with Applications 39 (2000) 43–54.

use super::events::{first_event, switch_mode, ZenoGuard};
use super::HybridSystem;
use crate::model::{SimulationError, SolverOptions, SolverStats};

/// What an attempted step made of its local error.
pub(super) enum Trial {
    /// The error in the mixed norm of the tolerances: the step is accepted when it is ≤ 1.
    Error(f64),
    /// No finite error estimate (or state): the step is retried much shorter.
    NonFinite,
}

/// A continuous extension of one accepted step, on which outputs are read and events located.
pub(super) trait Interpolant {
    /// The state at time `t` inside the step.
    fn eval(&self, t: f64, out: &mut [f64]);
}

/// A one-step method with an error estimate and a continuous extension; see the module
/// documentation for what it owns and in which order [`drive`] calls it.
pub(super) trait Stepper: Interpolant {
    /// The state at the current time, where the next step starts.
    fn state(&self) -> &[f64];

    /// The state at the end of the last attempted step.
    fn proposed(&self) -> &[f64];

    /// Start from state `y` at `t` (the start, or the restart after an event): evaluate what
    /// the first step needs there and forget the controller's history.
    fn restart<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        y: &[f64],
        stats: &mut SolverStats,
    ) -> Result<(), SimulationError>;

    /// The first step from the start `t` over `span`, or NaN to choose it in
    /// [`Stepper::prepare`]. Called once, after [`Stepper::restart`] and the event functions
    /// at the start.
    fn initial_step<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        span: f64,
        options: &SolverOptions,
        stats: &mut SolverStats,
    ) -> f64;

    /// Before each attempt from `t`, with `span` to the end: refresh the per-step state (a
    /// spectral radius estimate) and choose `h` if it is NaN.
    fn prepare<S: HybridSystem>(
        &mut self,
        _system: &S,
        _t: f64,
        _span: f64,
        _h: &mut f64,
        _options: &SolverOptions,
        _stats: &mut SolverStats,
    ) -> Result<(), SimulationError> {
        Ok(())
    }

    /// Shorten `h`, already clamped to the end when `last` is set, where the method's
    /// stability asks for it (and clear `last` then).
    fn fit(&mut self, _h: &mut f64, _last: &mut bool) {}

    /// Attempt the step `[t, t + h]` from [`Stepper::state`] into [`Stepper::proposed`].
    fn attempt<S: HybridSystem>(
        &mut self,
        system: &S,
        t: f64,
        h: f64,
        options: &SolverOptions,
        stats: &mut SolverStats,
    ) -> Result<Trial, SimulationError>;

    /// The step to retry with after an attempt of `h` without a finite error.
    fn after_non_finite(&mut self, h: f64) -> f64;

    /// The step to retry with after an attempt of `h` rejected with error `err > 1`; `again`
    /// when the attempt before was rejected too.
    fn after_rejected(&mut self, h: f64, err: f64, again: bool) -> f64;

    /// The attempt `[t, t + h]` is accepted: build its continuous extension.
    fn accept(&mut self, t: f64, h: f64);

    /// Move to the accepted step's end: the proposed state becomes the state.
    fn advance(&mut self);

    /// The next step after the accepted `h` of error `err`; `after_rejection` when the
    /// attempt before it was rejected.
    fn next_step(&mut self, h: f64, err: f64, after_rejection: bool) -> f64;
}

/// Integrate `system` by `stepper` from `t = 0`, state `y0`, and call `out(i, y)` with the
/// state at each `grid[i]` (non-decreasing, ≥ 0).
pub(super) fn drive<S, M, F>(
    system: &mut S,
    stepper: &mut M,
    y0: &[f64],
    grid: &[f64],
    options: &SolverOptions,
    out: F,
) -> Result<SolverStats, SimulationError>
where
    S: HybridSystem,
    M: Stepper,
    F: FnMut(usize, &[f64]),
{
    let mut stats = SolverStats::default();
    let Some((t_end, mut run)) = Run::start(&*system, y0, grid, out) else {
        return Ok(stats);
    };

    let mut t = 0.0;
    restart(&*system, stepper, t, y0, &mut run.g_old, &mut stats)?;
    let mut h = stepper.initial_step(&*system, t, t_end - t, options, &mut stats);
    let mut last_rejected = false;
    loop {
        let last_step = step_size(&*system, stepper, t, t_end, &mut h, options, &mut stats)?;
        let trial = stepper.attempt(&*system, t, h, options, &mut stats)?;
        let Some(err) = judge(stepper, trial, &mut h, last_rejected, &mut stats) else {
            last_rejected = true;
            continue;
        };

        stats.accepted_steps += 1;
        stepper.accept(t, h);
        let t_new = if last_step { t_end } else { t + h };
        let event = run.accepted(&*system, stepper, t, t_new);
        let t_step = t;
        let switched = match event {
            None => {
                t = t_new;
                stepper.advance();
                std::mem::swap(&mut run.g_old, &mut run.g_new);
                system.check_step(t, stepper.state())?;
                if run.done() {
                    return Ok(stats);
                }
                let switched = run.step_event(system, stepper, t, &mut stats)?;
                if !switched {
                    h = stepper.next_step(h, err, last_rejected);
                }
                switched
            }
            Some((e, te)) => {
                stats.events += 1;
                t = te;
                if run.switch(system, stepper, te, e)? {
                    return Ok(stats);
                }
                true
            }
        };
        if switched {
            restart(&*system, stepper, t, &run.ytmp, &mut run.g_old, &mut stats)?;
            // Restart with the step that reached the event, at least a fraction of the
            // accepted one so the controller does not crawl after every switch.
            h = (t - t_step).max(0.1 * h).max(1e-6);
        }
        last_rejected = false;
    }
}

/// Start `stepper` from state `y` at `t` (the start, or the restart after a switch) and
/// evaluate the event functions there into `g`, after the method's right-hand sides.
fn restart<S: HybridSystem, M: Stepper>(
    system: &S,
    stepper: &mut M,
    t: f64,
    y: &[f64],
    g: &mut [f64],
    stats: &mut SolverStats,
) -> Result<(), SimulationError> {
    stepper.restart(system, t, y, stats)?;
    system.events(t, stepper.state(), g);
    Ok(())
}

/// The error of an accepted attempt `trial` of `h`, or `None` for a rejected one: then it is
/// counted and the step to retry with is in `h` (`again`: the attempt before was rejected too).
fn judge<M: Stepper>(
    stepper: &mut M,
    trial: Trial,
    h: &mut f64,
    again: bool,
    stats: &mut SolverStats,
) -> Option<f64> {
    match trial {
        Trial::NonFinite => {
            stats.rejected_steps += 1;
            *h = stepper.after_non_finite(*h);
            None
        }
        Trial::Error(err) if err > 1.0 => {
            stats.rejected_steps += 1;
            *h = stepper.after_rejected(*h, err, again);
            None
        }
        Trial::Error(err) => Some(err),
    }
}

/// What a run carries besides the method: the outputs still to record, the event functions
/// at the start and the end of the step, scratch, and the guard against accumulating events.
struct Run<'g, F> {
    grid: &'g [f64],
    next_out: usize,
    out: F,
    g_old: Vec<f64>,
    g_new: Vec<f64>,
    g_tmp: Vec<f64>,
    ytmp: Vec<f64>,
    zeno: ZenoGuard,
}

impl<'g, F: FnMut(usize, &[f64])> Run<'g, F> {
    fn new(events: usize, n: usize, grid: &'g [f64], next_out: usize, out: F) -> Self {
        Self {
            grid,
            next_out,
            out,
            g_old: vec![0.0; events],
            g_new: vec![0.0; events],
            g_tmp: vec![0.0; events],
            ytmp: vec![0.0; n],
            zeno: ZenoGuard::new(grid[grid.len() - 1]),
        }
    }

    /// Check the initial state `y0` against `system`, record the outputs at the grid times
    /// up to the start; the end time and the run, or `None` when nothing is left to integrate.
    fn start<S: HybridSystem>(
        system: &S,
        y0: &[f64],
        grid: &'g [f64],
        mut out: F,
    ) -> Option<(f64, Self)> {
        let n = system.dim();
        assert_eq!(y0.len(), n, "state dimension");
        let &t_end = grid.last()?;
        let next_out = outputs_at_start(grid, y0, &mut out);
        if next_out == grid.len() {
            return None;
        }
        Some((
            t_end,
            Self::new(system.event_count(), n, grid, next_out, out),
        ))
    }

    /// Whether every output is recorded.
    fn done(&self) -> bool {
        self.next_out == self.grid.len()
    }

    /// The accepted step `[t, t_new]` of `stepper`: its first event, and the outputs up to
    /// that event or the step's end.
    fn accepted<S: HybridSystem, M: Stepper>(
        &mut self,
        system: &S,
        stepper: &M,
        t: f64,
        t_new: f64,
    ) -> Option<(usize, f64)> {
        let y_new = stepper.proposed();
        let event = first_event(
            system,
            stepper,
            t,
            t_new,
            y_new,
            &self.g_old,
            &mut self.g_new,
            &mut self.ytmp,
            &mut self.g_tmp,
        );
        let end = match event {
            None => StepEnd::Reached(t_new, y_new),
            Some((_, te)) => StepEnd::Event(te),
        };
        // A local index, which the loop keeps in a register.
        let mut next_out = self.next_out;
        outputs_of_step(
            self.grid,
            &mut next_out,
            end,
            stepper,
            &mut self.ytmp,
            &mut self.out,
        );
        self.next_out = next_out;
        event
    }

    /// At the end `t` of an accepted step without an event: whether the system asks for a
    /// step event there, and then the state switched by the system into `ytmp`.
    fn step_event<S: HybridSystem, M: Stepper>(
        &mut self,
        system: &mut S,
        stepper: &M,
        t: f64,
        stats: &mut SolverStats,
    ) -> Result<bool, SimulationError> {
        if !system.step_completed(t, stepper.state()) {
            return Ok(false);
        }
        // A step event: the system switches mode at the step's end.
        stats.events += 1;
        self.ytmp.copy_from_slice(stepper.state());
        let e = system.event_count();
        switch_mode(system, &mut self.zeno, t, &mut self.ytmp, e)?;
        Ok(true)
    }

    /// At event `e` at `te` of the last accepted step: the state there into `ytmp`, switched
    /// by the system; whether every output is recorded.
    fn switch<S: HybridSystem, M: Stepper>(
        &mut self,
        system: &mut S,
        stepper: &M,
        te: f64,
        e: usize,
    ) -> Result<bool, SimulationError> {
        stepper.eval(te, &mut self.ytmp);
        switch_mode(system, &mut self.zeno, te, &mut self.ytmp, e)?;
        Ok(self.done())
    }
}

/// The size of the next attempt from `t` into `h`, and whether it reaches `t_end`: within the
/// step limit, clamped to the end, fitted to the method, and not vanishingly small.
fn step_size<S: HybridSystem, M: Stepper>(
    system: &S,
    stepper: &mut M,
    t: f64,
    t_end: f64,
    h: &mut f64,
    options: &SolverOptions,
    stats: &mut SolverStats,
) -> Result<bool, SimulationError> {
    if stats.accepted_steps + stats.rejected_steps >= options.max_steps {
        return Err(SimulationError::StepLimit {
            limit: options.max_steps,
            time: t,
        });
    }
    stepper.prepare(system, t, t_end - t, h, options, stats)?;
    let remaining = t_end - t;
    let mut last_step = false;
    if *h >= remaining * (1.0 - 1e-12) {
        *h = remaining;
        last_step = true;
    }
    stepper.fit(h, &mut last_step);
    if *h <= 1e-14 * t.abs().max(1.0) {
        return Err(SimulationError::StepTooSmall { time: t });
    }
    Ok(last_step)
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
