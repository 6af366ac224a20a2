//! One simulation of an FMU instance onto a time grid.
//!
//! Both start at [`SolverOptions::start_time`], where the FMU is initialised (with the stop
//! time, the last output time); outputs asked for before it hold the values at the start.
//!
//! **Co-Simulation**: initialise (telling the FMU the tolerance), then `doStep` from one output
//! time to the next and read the outputs there. With a communication step `h`
//! ([`SolverOptions::communication_step`]) the steps end on the regular points `start + n·h`
//! and on every output time: several steps between two outputs when `h` is smaller than
//! their interval, and never one past an output time (the last one is shortened to land on
//! it). The FMU's own solver sets the accuracy.
//!
//! **Model Exchange**: initialise, run the event iteration, then integrate the FMU's
//! derivatives with calib's Dormand–Prince ([`crate::ode`]) at the requested tolerance (its
//! clock counts from the start).
//! Event functions are each event indicator `z_k` (an event when it goes from ≥ 0 to < 0)
//! and `−z_k` (from ≤ 0 to > 0), located on the dense output; a time event is the function
//! `t_next − δ − t`, with δ = 1e-10·max(1, t_next): the FMU is told the event's exact time,
//! and an output at that time reports the values after it, as FMI's reference results do. At
//! each event the FMU enters event mode, iterates its discrete states and gives back its
//! continuous states. A model without continuous states (a pure time-event model) is
//! integrated with one dummy state. When the FMU asks to terminate, its outputs are held.
//! Step events are not supported: `fmi*CompletedIntegratorStep` is not called.
//!
//! Any call that returns Discard, Error or Fatal ends the simulation with
//! [`SimulationError::Failed`] carrying the function, the status and the FMU's messages.

use super::description::{Interface, Kind};
use super::ffi::Instance;
use super::FmuError;
use crate::limits;
use crate::model::{SimulationError, SolverOptions, SolverStats, Trajectory};
use crate::ode::{self, HybridSystem};
use std::cell::{Cell, RefCell};

/// Iterations of the discrete states at one event before the FMU is deemed to loop.
const MAX_EVENT_ITERATIONS: usize = 1000;

/// What one simulation needs to know of the FMU.
pub struct Plan<'a> {
    pub interface: Interface,
    pub parameter_vrs: &'a [u32],
    pub parameters: &'a [f64],
    /// The requested outputs, in the order they are returned.
    pub outputs: &'a Outputs,
    pub states: usize,
    pub indicators: usize,
}

/// Output variables grouped by type, each with its place in the returned outputs.
#[derive(Debug, Default)]
pub struct Outputs {
    len: usize,
    real: (Vec<u32>, Vec<usize>),
    integer: (Vec<u32>, Vec<usize>),
    boolean: (Vec<u32>, Vec<usize>),
}

impl Outputs {
    pub fn new(variables: &[(Kind, u32)]) -> Self {
        let mut o = Outputs {
            len: variables.len(),
            ..Default::default()
        };
        for (i, (kind, vr)) in variables.iter().enumerate() {
            let group = match kind {
                Kind::Real => &mut o.real,
                Kind::Integer => &mut o.integer,
                Kind::Boolean => &mut o.boolean,
            };
            group.0.push(*vr);
            group.1.push(i);
        }
        o
    }

    pub fn len(&self) -> usize {
        self.len
    }

    /// Read every output into `values`.
    fn read(&self, fmu: &mut Instance, values: &mut [f64]) -> Result<(), FmuError> {
        if self.real.0.len() == self.len {
            return fmu.get_reals(&self.real.0, values);
        }
        if !self.real.0.is_empty() {
            let mut v = vec![0.0; self.real.0.len()];
            fmu.get_reals(&self.real.0, &mut v)?;
            for (i, x) in self.real.1.iter().zip(v) {
                values[*i] = x;
            }
        }
        if !self.integer.0.is_empty() {
            let mut v = vec![0; self.integer.0.len()];
            fmu.get_integers(&self.integer.0, &mut v)?;
            for (i, x) in self.integer.1.iter().zip(v) {
                values[*i] = f64::from(x);
            }
        }
        if !self.boolean.0.is_empty() {
            let mut v = vec![false; self.boolean.0.len()];
            fmu.get_booleans(&self.boolean.0, &mut v)?;
            for (i, x) in self.boolean.1.iter().zip(v) {
                values[*i] = if x { 1.0 } else { 0.0 };
            }
        }
        Ok(())
    }
}

fn failed(time: f64, e: FmuError) -> SimulationError {
    SimulationError::Failed {
        time,
        reason: e.to_string(),
    }
}

/// Initialise `instance` (reset first unless `fresh`) at `options.start_time` and simulate
/// it onto `grid`; outputs asked for before the start hold the values at the start.
pub fn simulate(
    instance: &mut Instance,
    fresh: bool,
    plan: &Plan,
    grid: &[f64],
    options: &SolverOptions,
) -> Result<Trajectory, SimulationError> {
    let start = options.start_time;
    if !fresh {
        instance.reset().map_err(|e| failed(start, e))?;
    }
    let stop = grid.last().copied().unwrap_or(start).max(start);
    if let Some(h) = options.communication_step {
        if !(h > 0.0 && (stop - start) / h <= limits::MAX_COMMUNICATION_STEPS) {
            return Err(SimulationError::InvalidInput(format!(
                "a communication step of {h} s over {} s is more than {:e} steps",
                stop - start,
                limits::MAX_COMMUNICATION_STEPS
            )));
        }
    }
    let init = |instance: &mut Instance| -> Result<(), FmuError> {
        instance.set_reals(plan.parameter_vrs, plan.parameters)?;
        let tolerance = (plan.interface == Interface::CoSimulation).then_some(options.rtol);
        instance.enter_initialization(tolerance, start, Some(stop))?;
        instance.exit_initialization()
    };
    init(instance).map_err(|e| failed(start, e))?;
    match plan.interface {
        Interface::CoSimulation => co_simulate(instance, plan, grid, start, options),
        Interface::ModelExchange => {
            // calib's integrator starts at 0: it sees the FMU's time less the start.
            let shifted: Vec<f64> = grid.iter().map(|t| (t - start).max(0.0)).collect();
            let mut trajectory =
                integrate(instance, plan, &shifted, start, options).map_err(|e| later(e, start))?;
            trajectory.time = grid.to_vec();
            Ok(trajectory)
        }
    }
}

/// `e`, which happened `start` earlier by the integrator's clock, at the FMU's time.
fn later(e: SimulationError, start: f64) -> SimulationError {
    use SimulationError::*;
    match e {
        StepLimit { limit, time } => StepLimit {
            limit,
            time: time + start,
        },
        StepTooSmall { time } => StepTooSmall { time: time + start },
        Chattering {
            time,
            event,
            events,
            span,
        } => Chattering {
            time: time + start,
            event,
            events,
            span,
        },
        Diverged { time } => Diverged { time: time + start },
        // Failures carry the FMU's time already.
        other => other,
    }
}

/// The next communication point after `t` towards the output time `target`: the next point
/// of the regular grid `start + n·h` (none with no `step`), or `target` when that is no
/// earlier (or within a billionth of a step of it).
fn next_communication_point(t: f64, target: f64, start: f64, step: Option<f64>) -> f64 {
    let Some(h) = step else {
        return target;
    };
    let n = ((t - start) / h + 1e-9).floor() + 1.0;
    let regular = start + n * h;
    if regular >= target - 1e-9 * h {
        target
    } else {
        regular
    }
}

fn co_simulate(
    instance: &mut Instance,
    plan: &Plan,
    grid: &[f64],
    start: f64,
    options: &SolverOptions,
) -> Result<Trajectory, SimulationError> {
    let n_out = plan.outputs.len();
    let mut values = vec![Vec::with_capacity(grid.len()); n_out];
    let mut sample = vec![0.0; n_out];
    let mut t = start;
    plan.outputs
        .read(instance, &mut sample)
        .map_err(|e| failed(t, e))?;
    let mut terminated = false;
    let mut stats = SolverStats::default();
    for &target in grid {
        let mut stepped = false;
        while target > t && !terminated {
            let next = next_communication_point(t, target, start, options.communication_step);
            terminated = instance.do_step(t, next - t).map_err(|e| failed(t, e))?;
            stats.accepted_steps += 1;
            t = next;
            stepped = true;
        }
        if stepped {
            plan.outputs
                .read(instance, &mut sample)
                .map_err(|e| failed(t, e))?;
        }
        for (series, v) in values.iter_mut().zip(&sample) {
            series.push(*v);
        }
    }
    Ok(Trajectory {
        time: grid.to_vec(),
        values,
        stats,
    })
}

/// A system whose time runs `start` ahead of the integrator's.
struct Shifted<'a, S> {
    inner: &'a mut S,
    start: f64,
}

impl<S: HybridSystem> HybridSystem for Shifted<'_, S> {
    fn dim(&self) -> usize {
        self.inner.dim()
    }
    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        self.inner.rhs(t + self.start, y, dy)
    }
    fn event_count(&self) -> usize {
        self.inner.event_count()
    }
    fn events(&self, t: f64, y: &[f64], g: &mut [f64]) {
        self.inner.events(t + self.start, y, g)
    }
    fn on_event(&mut self, t: f64, y: &mut [f64], event: usize) {
        self.inner.on_event(t + self.start, y, event)
    }
    fn event_name(&self, event: usize) -> String {
        self.inner.event_name(event)
    }
    fn on_chattering(&mut self, t: f64, y: &mut [f64], event: usize) -> bool {
        self.inner.on_chattering(t + self.start, y, event)
    }
}

/// A Model Exchange FMU seen as a hybrid system.
struct Exchange<'a> {
    fmu: &'a RefCell<&'a mut Instance>,
    states: usize,
    indicators: usize,
    z: RefCell<Vec<f64>>,
    next_event: Cell<Option<f64>>,
    terminated: &'a Cell<bool>,
    /// The first failure; the integration runs on with NaN derivatives and is then discarded.
    error: &'a RefCell<Option<(f64, FmuError)>>,
}

impl Exchange<'_> {
    fn fail(&self, t: f64, e: FmuError) {
        let mut slot = self.error.borrow_mut();
        if slot.is_none() {
            *slot = Some((t, e));
        }
    }

    fn failed(&self) -> bool {
        self.error.borrow().is_some()
    }

    fn set_point(&self, fmu: &mut Instance, t: f64, y: &[f64]) -> Result<(), FmuError> {
        fmu.set_time(t)?;
        if self.states > 0 {
            fmu.set_states(&y[..self.states])?;
        }
        Ok(())
    }

    /// The event iteration at `t`: discrete states, then back to continuous time.
    fn handle_event(&self, t: f64, y: &mut [f64]) -> Result<(), FmuError> {
        let mut fmu = self.fmu.borrow_mut();
        self.set_point(&mut fmu, t, y)?;
        fmu.enter_event_mode()?;
        let update = event_iteration(&mut fmu)?;
        fmu.enter_continuous_time_mode()?;
        if update.values_changed && self.states > 0 {
            fmu.get_states(&mut y[..self.states])?;
        }
        self.next_event.set(update.next_event_time);
        if update.terminate {
            self.terminated.set(true);
        }
        Ok(())
    }
}

fn event_iteration(fmu: &mut Instance) -> Result<super::ffi::EventUpdate, FmuError> {
    let mut result = super::ffi::EventUpdate::default();
    for _ in 0..MAX_EVENT_ITERATIONS {
        let update = fmu.update_discrete_states()?;
        result.values_changed |= update.values_changed;
        result.terminate |= update.terminate;
        result.next_event_time = update.next_event_time;
        if !update.again || update.terminate {
            return Ok(result);
        }
    }
    Err(FmuError::Loop(MAX_EVENT_ITERATIONS))
}

fn time_event_lead(t_next: f64) -> f64 {
    1e-10 * t_next.abs().max(1.0)
}

impl HybridSystem for Exchange<'_> {
    fn dim(&self) -> usize {
        self.states.max(1)
    }

    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        dy.fill(0.0);
        if self.failed() {
            dy.fill(f64::NAN);
            return;
        }
        if self.states == 0 || self.terminated.get() {
            return;
        }
        let mut fmu = self.fmu.borrow_mut();
        let result = self
            .set_point(&mut fmu, t, y)
            .and_then(|()| fmu.get_derivatives(dy));
        if let Err(e) = result {
            drop(fmu);
            self.fail(t, e);
            dy.fill(f64::NAN);
        }
    }

    fn event_count(&self) -> usize {
        2 * self.indicators + 1
    }

    fn events(&self, t: f64, y: &[f64], g: &mut [f64]) {
        g.fill(1.0);
        if self.failed() || self.terminated.get() {
            return;
        }
        let nz = self.indicators;
        if nz > 0 {
            let mut z = self.z.borrow_mut();
            let mut fmu = self.fmu.borrow_mut();
            let result = self
                .set_point(&mut fmu, t, y)
                .and_then(|()| fmu.get_event_indicators(&mut z));
            if let Err(e) = result {
                drop(fmu);
                self.fail(t, e);
                return;
            }
            for k in 0..nz {
                g[k] = z[k];
                g[nz + k] = -z[k];
            }
        }
        if let Some(t_next) = self.next_event.get() {
            g[2 * nz] = t_next - time_event_lead(t_next) - t;
        }
    }

    fn on_event(&mut self, t: f64, y: &mut [f64], event: usize) {
        if self.failed() {
            return;
        }
        // A time event happens at its own time, which the lead puts just after `t`.
        let at = match self.next_event.get() {
            Some(t_next) if event == 2 * self.indicators => t_next,
            _ => t,
        };
        if let Err(e) = self.handle_event(at, y) {
            self.fail(at, e);
        }
    }

    fn event_name(&self, event: usize) -> String {
        let nz = self.indicators;
        if event == 2 * nz {
            "time event".into()
        } else {
            format!("event indicator #{}", event % nz.max(1))
        }
    }
}

/// Integrate from `start` onto `grid`, whose times are counted from `start`.
fn integrate(
    instance: &mut Instance,
    plan: &Plan,
    grid: &[f64],
    start: f64,
    options: &SolverOptions,
) -> Result<Trajectory, SimulationError> {
    let nx = plan.states;
    let update = event_iteration(instance).map_err(|e| failed(start, e))?;
    instance
        .enter_continuous_time_mode()
        .map_err(|e| failed(start, e))?;
    let mut y0 = vec![0.0; nx.max(1)];
    if nx > 0 {
        instance
            .get_states(&mut y0[..nx])
            .map_err(|e| failed(start, e))?;
    }
    let n_out = plan.outputs.len();
    let error = RefCell::new(None);
    let terminated = Cell::new(update.terminate);
    let fmu = RefCell::new(instance);
    let mut system = Exchange {
        fmu: &fmu,
        states: nx,
        indicators: plan.indicators,
        z: RefCell::new(vec![0.0; plan.indicators]),
        next_event: Cell::new(update.next_event_time),
        terminated: &terminated,
        error: &error,
    };
    let mut values = vec![vec![0.0; grid.len()]; n_out];
    let mut sample = vec![0.0; n_out];
    let mut held = false;
    let stats = {
        // The output closure reads the FMU through the same cell as the system.
        let fmu = &fmu;
        let error = &error;
        let values = &mut values;
        let sample = &mut sample;
        let mut read = move |i: usize, y: &[f64], stop: bool| {
            if error.borrow().is_some() {
                return;
            }
            if !held {
                let mut f = fmu.borrow_mut();
                let t = grid[i] + start;
                let result = (|| {
                    f.set_time(t)?;
                    if nx > 0 {
                        f.set_states(&y[..nx])?;
                    }
                    plan.outputs.read(&mut f, sample)
                })();
                if let Err(e) = result {
                    *error.borrow_mut() = Some((t, e));
                    return;
                }
                held = stop;
            }
            for (series, v) in values.iter_mut().zip(sample.iter()) {
                series[i] = *v;
            }
        };
        let terminated = &terminated;
        let mut system = Shifted {
            inner: &mut system,
            start,
        };
        ode::integrate(&mut system, &y0, grid, options, |i, y| {
            read(i, y, terminated.get())
        })
    };
    if let Some((t, e)) = error.into_inner() {
        return Err(failed(t, e));
    }
    let stats = stats?;
    Ok(Trajectory {
        time: grid.to_vec(),
        values,
        stats,
    })
}
