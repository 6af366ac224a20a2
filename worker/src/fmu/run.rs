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
//! clock counts from the start), in the order of the standard's simulation algorithm (and of FMPy's):
//! - after setting time and states, the FMU computes its derivatives there
//!   (`fmi*GetDerivatives`) before anything else is read, and the time and states are set
//!   again before event indicators or outputs are read: some FMUs compute their other
//!   variables only in `GetDerivatives`, others (OpenModelica's) compute only the
//!   derivatives there and the rest when a variable is read after a change;
//! - event functions are each event indicator `z_k` (an event when it goes from ≥ 0 to < 0)
//!   and `−z_k` (from ≤ 0 to > 0), located on the dense output; a time event is the
//!   function `t_next − δ − t`, with δ = 1e-10·max(1, t_next): the FMU is told the event's
//!   exact time, and an output at that time reports the values after it, as FMI's reference
//!   results do;
//! - at an event the FMU computes at the event's time and states (derivatives and event
//!   indicators) before it enters event mode: FMUs such as MapleSim's decide there on what
//!   they computed last, not on the time and states set since; then the discrete states are
//!   iterated until the FMU needs no more, the continuous states read back, and the
//!   integration restarts from them;
//! - after every accepted step `fmi*CompletedIntegratorStep` is called at the step's end
//!   (when the FMU has it), and an event is handled there when it asks (a step event);
//! - when the FMU asks to terminate (at an event or a completed step) its outputs then are
//!   held to the end.
//!
//! A model without continuous states (a pure time-event model) is integrated with one dummy
//! state.
//!
//! **Inputs** ([`Driven`]): every driven input gets its start-time value in initialisation
//! mode. Model Exchange sets the continuous ones wherever it sets time and states (so before
//! every derivative, event-indicator and output read), and every one in event mode; where
//! what the FMU is given jumps (a held input's new sample, a linear input's repeated sample
//! time, a discrete input's change) is a time event, the only place discrete inputs change.
//! Co-Simulation sets every input at each step's start, held over the step, and ends a step
//! where an input jumps.
//!
//! Any call that returns Discard, Error or Fatal ends the simulation with
//! [`SimulationError::Failed`] carrying the function, the status and the FMU's messages.

use super::description::{Interface, Kind};
use super::ffi::Instance;
use super::FmuError;
use crate::inputs::{InputSignal, Inputs};
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
    /// The signals that drive the FMU's inputs.
    pub inputs: &'a Driven<'a>,
}

/// An input variable of the FMU and how calib sets it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InputRef {
    pub kind: Kind,
    pub vr: u32,
    /// It changes only at events (Integer, Boolean, a Real of variability `discrete`): it is
    /// given the value of the last sample at or before the time (rounded when it is an
    /// Integer, true when that is non-zero for a Boolean), whatever the signal's
    /// interpolation, and it changes at time events.
    pub discrete: bool,
}

/// The signals that drive one simulation, each with the FMU input it sets, and the times at
/// which what the FMU is given jumps.
#[derive(Debug, Default)]
pub struct Driven<'a> {
    signals: Vec<(InputRef, &'a InputSignal)>,
    /// Sorted, without repeats: each sample of a discrete or held input where its value
    /// changes, each repeated sample time of a linear one where it steps.
    events: Vec<f64>,
}

/// The value of the last sample at or before `t` (the first before the first sample).
fn held(s: &InputSignal, t: f64) -> f64 {
    let k = s.times.partition_point(|&u| u <= t);
    s.values[k.saturating_sub(1)]
}

impl<'a> Driven<'a> {
    /// `inputs` (checked against the model) onto the FMU's inputs `refs` (in the order of
    /// the model's inputs).
    pub fn new(refs: &[InputRef], inputs: &'a Inputs) -> Self {
        let signals: Vec<(InputRef, &InputSignal)> =
            inputs.signals.iter().map(|s| (refs[s.input], s)).collect();
        let mut events = Vec::new();
        for (r, s) in &signals {
            let value = |v: f64| Self::value_of(r, v);
            for k in 1..s.times.len() {
                let jumps = value(s.values[k]) != value(s.values[k - 1])
                    && (r.discrete
                        || s.interpolation == crate::inputs::Interpolation::Hold
                        || s.times[k] == s.times[k - 1]);
                if jumps {
                    events.push(s.times[k]);
                }
            }
        }
        events.sort_by(f64::total_cmp);
        events.dedup();
        Driven { signals, events }
    }

    /// A sample's value as the input's type takes it.
    fn value_of(r: &InputRef, v: f64) -> f64 {
        match r.kind {
            Kind::Real => v,
            Kind::Integer => v.round().clamp(f64::from(i32::MIN), f64::from(i32::MAX)),
            Kind::Boolean => f64::from(u8::from(v.round() != 0.0)),
        }
    }

    /// The value input `r` driven by `s` has at `t` (after an event at `t`).
    fn at(r: &InputRef, s: &InputSignal, t: f64) -> f64 {
        if r.discrete {
            Self::value_of(r, held(s, t))
        } else {
            s.at(t)
        }
    }

    /// Set the inputs to their values at `t`: the continuous ones only (as Model Exchange
    /// may in continuous-time mode), or every one (at initialisation, at an event, before
    /// a Co-Simulation step).
    fn apply(&self, fmu: &mut Instance, t: f64, discrete_too: bool) -> Result<(), FmuError> {
        if self.signals.is_empty() {
            return Ok(());
        }
        let mut reals = (Vec::new(), Vec::new());
        let mut integers = (Vec::new(), Vec::new());
        let mut booleans = (Vec::new(), Vec::new());
        for (r, s) in &self.signals {
            if r.discrete && !discrete_too {
                continue;
            }
            let v = Self::at(r, s, t);
            match r.kind {
                Kind::Real => {
                    reals.0.push(r.vr);
                    reals.1.push(v);
                }
                Kind::Integer => {
                    integers.0.push(r.vr);
                    integers.1.push(v as i32);
                }
                Kind::Boolean => {
                    booleans.0.push(r.vr);
                    booleans.1.push(v != 0.0);
                }
            }
        }
        if !reals.0.is_empty() {
            fmu.set_reals(&reals.0, &reals.1)?;
        }
        if !integers.0.is_empty() {
            fmu.set_integers(&integers.0, &integers.1)?;
        }
        if !booleans.0.is_empty() {
            fmu.set_booleans(&booleans.0, &booleans.1)?;
        }
        Ok(())
    }

    /// The first time after `t` at which an input jumps.
    fn next_event(&self, t: f64) -> Option<f64> {
        let k = self.events.partition_point(|&e| e <= t);
        self.events.get(k).copied()
    }
}

/// The earlier of two optional times.
fn earliest(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, None) => a,
        (None, b) => b,
    }
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
        // Inputs have their start-time values during initialisation.
        plan.inputs.apply(instance, start, true)?;
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
            let mut next = next_communication_point(t, target, start, options.communication_step);
            // A step ends where an input jumps, so that the FMU gets its new value there.
            if let Some(e) = plan.inputs.next_event(t).filter(|&e| e < next) {
                next = e;
            }
            // The inputs at the step's start, held over the step.
            plan.inputs
                .apply(instance, t, true)
                .map_err(|e| failed(t, e))?;
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
    fn step_completed(&mut self, t: f64, y: &[f64]) -> bool {
        self.inner.step_completed(t + self.start, y)
    }
}

/// Where the FMU's continuous-time variables stand: the time and states set last, and
/// whether it has computed its derivatives there since.
#[derive(Default)]
struct Point {
    t: f64,
    x: Vec<f64>,
    set: bool,
    evaluated: bool,
}

/// A Model Exchange FMU instance and what calib knows of where it stands; shared by the
/// hybrid system and the reading of the outputs.
struct Host<'a> {
    fmu: RefCell<&'a mut Instance>,
    outputs: &'a Outputs,
    inputs: &'a Driven<'a>,
    states: usize,
    indicators: usize,
    completed_step: bool,
    point: RefCell<Point>,
    dx: RefCell<Vec<f64>>,
    z: RefCell<Vec<f64>>,
    /// Once the FMU asks to terminate: its outputs then, held to the end.
    held: RefCell<Option<Vec<f64>>>,
    /// The first failure; the integration runs on with NaN derivatives and is then discarded.
    error: RefCell<Option<(f64, FmuError)>>,
}

/// A Model Exchange FMU seen as a hybrid system.
struct Exchange<'a> {
    host: &'a Host<'a>,
    next_event: Cell<Option<f64>>,
}

impl Host<'_> {
    fn fail(&self, t: f64, e: FmuError) {
        let mut slot = self.error.borrow_mut();
        if slot.is_none() {
            *slot = Some((t, e));
        }
    }

    fn failed(&self) -> bool {
        self.error.borrow().is_some()
    }

    fn terminated(&self) -> bool {
        self.held.borrow().is_some()
    }

    /// Set time `t` and states `y` (unless they are set already).
    fn set_point(&self, fmu: &mut Instance, t: f64, y: &[f64]) -> Result<(), FmuError> {
        let x = &y[..self.states];
        let mut point = self.point.borrow_mut();
        if point.set && point.t == t && point.x == x {
            return Ok(());
        }
        point.set = false;
        point.evaluated = false;
        fmu.set_time(t)?;
        if self.states > 0 {
            fmu.set_states(x)?;
        }
        self.inputs.apply(fmu, t, false)?;
        point.t = t;
        point.x.clear();
        point.x.extend_from_slice(x);
        point.set = true;
        Ok(())
    }

    /// Set time `t` and states `y` and have the FMU compute its derivatives there, as FMI's
    /// simulation algorithm does before anything else is read: many FMUs compute their
    /// other continuous-time variables only in `fmi*GetDerivatives`.
    fn evaluate(&self, fmu: &mut Instance, t: f64, y: &[f64]) -> Result<(), FmuError> {
        self.set_point(fmu, t, y)?;
        if self.point.borrow().evaluated {
            return Ok(());
        }
        fmu.get_derivatives(&mut self.dx.borrow_mut())?;
        self.point.borrow_mut().evaluated = true;
        Ok(())
    }

    /// Make the FMU's variables at `t`, `y` readable, whichever way it computes them: its
    /// derivatives there first (some FMUs compute their other variables only in
    /// `fmi*GetDerivatives`), then the time and states set again (others compute only the
    /// derivatives there and the rest when a variable is read after a change; OpenModelica's
    /// do, and then take `fmi*GetDerivatives` to have computed everything).
    fn prepare_read(&self, fmu: &mut Instance, t: f64, y: &[f64]) -> Result<(), FmuError> {
        self.evaluate(fmu, t, y)?;
        fmu.set_time(t)?;
        if self.states > 0 {
            fmu.set_states(&y[..self.states])?;
        }
        self.inputs.apply(fmu, t, false)
    }

    /// The event indicators at `t`, `y` into `self.z`.
    fn indicators_at(&self, fmu: &mut Instance, t: f64, y: &[f64]) -> Result<(), FmuError> {
        self.prepare_read(fmu, t, y)?;
        if self.indicators > 0 {
            fmu.get_event_indicators(&mut self.z.borrow_mut())?;
        }
        Ok(())
    }

    /// Every output at `t`, `y` into `values`: the held ones once the FMU asked to stop.
    fn read(&self, t: f64, y: &[f64], values: &mut [f64]) -> Result<(), FmuError> {
        if let Some(held) = &*self.held.borrow() {
            values.copy_from_slice(held);
            return Ok(());
        }
        let mut fmu = self.fmu.borrow_mut();
        self.prepare_read(&mut fmu, t, y)?;
        self.outputs.read(&mut fmu, values)
    }

    /// The FMU asked to terminate at `t`: hold its outputs as they are.
    fn terminate(&self, fmu: &mut Instance) -> Result<(), FmuError> {
        let mut values = vec![0.0; self.outputs.len()];
        self.outputs.read(fmu, &mut values)?;
        *self.held.borrow_mut() = Some(values);
        Ok(())
    }

    /// The FMU's integrator step is complete at `t`, `y`: whether it asks for an event.
    fn complete_step(&self, t: f64, y: &[f64]) -> Result<bool, FmuError> {
        if !self.completed_step {
            return Ok(false);
        }
        let mut fmu = self.fmu.borrow_mut();
        self.evaluate(&mut fmu, t, y)?;
        let (event, terminate) = fmu.completed_integrator_step()?;
        if terminate {
            self.terminate(&mut fmu)?;
            return Ok(false);
        }
        Ok(event)
    }

    /// The event iteration at `t`: discrete states, then back to continuous time with the
    /// states the FMU gives back; the time of the next time event.
    fn handle_event(&self, t: f64, y: &mut [f64]) -> Result<Option<f64>, FmuError> {
        let mut fmu = self.fmu.borrow_mut();
        // The FMU sees the event's time and states as after a step to it (derivatives and
        // event indicators there), then switches.
        self.indicators_at(&mut fmu, t, y)?;
        fmu.enter_event_mode()?;
        // Every input at its value after the event (discrete ones change only here).
        self.inputs.apply(&mut fmu, t, true)?;
        let update = event_iteration(&mut fmu)?;
        if update.terminate {
            self.terminate(&mut fmu)?;
            return Ok(None);
        }
        fmu.enter_continuous_time_mode()?;
        if self.states > 0 {
            fmu.get_states(&mut y[..self.states])?;
        }
        // A new mode: what the FMU computed before the event is stale.
        self.point.borrow_mut().set = false;
        Ok(earliest(update.next_event_time, self.inputs.next_event(t)))
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
        self.host.states.max(1)
    }

    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        let host = self.host;
        dy.fill(0.0);
        if host.failed() {
            dy.fill(f64::NAN);
            return;
        }
        if host.terminated() {
            return;
        }
        let mut fmu = host.fmu.borrow_mut();
        if let Err(e) = host.evaluate(&mut fmu, t, y) {
            drop(fmu);
            host.fail(t, e);
            dy.fill(f64::NAN);
            return;
        }
        let nx = host.states;
        dy[..nx].copy_from_slice(&host.dx.borrow());
    }

    fn event_count(&self) -> usize {
        2 * self.host.indicators + 1
    }

    fn events(&self, t: f64, y: &[f64], g: &mut [f64]) {
        let host = self.host;
        g.fill(1.0);
        if host.failed() || host.terminated() {
            return;
        }
        let nz = host.indicators;
        if nz > 0 {
            let mut fmu = host.fmu.borrow_mut();
            if let Err(e) = host.indicators_at(&mut fmu, t, y) {
                drop(fmu);
                host.fail(t, e);
                return;
            }
            let z = host.z.borrow();
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
        let host = self.host;
        if host.failed() || host.terminated() {
            return;
        }
        // A time event happens at its own time, which the lead puts just after `t`.
        let at = match self.next_event.get() {
            Some(t_next) if event == 2 * host.indicators => t_next,
            _ => t,
        };
        match host.handle_event(at, y) {
            Ok(next) => self.next_event.set(next),
            Err(e) => host.fail(at, e),
        }
    }

    fn step_completed(&mut self, t: f64, y: &[f64]) -> bool {
        let host = self.host;
        if host.failed() || host.terminated() {
            return false;
        }
        match host.complete_step(t, y) {
            Ok(event) => event,
            Err(e) => {
                host.fail(t, e);
                false
            }
        }
    }

    fn event_name(&self, event: usize) -> String {
        let nz = self.host.indicators;
        if event == 2 * nz {
            "time event".into()
        } else if event > 2 * nz {
            "step event".into()
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
    let n_out = plan.outputs.len();
    let update = event_iteration(instance).map_err(|e| failed(start, e))?;
    let held = RefCell::new(None);
    let mut y0 = vec![0.0; nx.max(1)];
    if update.terminate {
        // Asked to stop at the start: the outputs after initialisation, throughout.
        let mut values = vec![0.0; n_out];
        plan.outputs
            .read(instance, &mut values)
            .map_err(|e| failed(start, e))?;
        *held.borrow_mut() = Some(values);
    } else {
        instance
            .enter_continuous_time_mode()
            .map_err(|e| failed(start, e))?;
        if nx > 0 {
            instance
                .get_states(&mut y0[..nx])
                .map_err(|e| failed(start, e))?;
        }
    }
    let completed_step = instance.has_completed_integrator_step();
    let host = Host {
        fmu: RefCell::new(instance),
        outputs: plan.outputs,
        inputs: plan.inputs,
        states: nx,
        indicators: plan.indicators,
        completed_step,
        point: RefCell::new(Point::default()),
        dx: RefCell::new(vec![0.0; nx]),
        z: RefCell::new(vec![0.0; plan.indicators]),
        held,
        error: RefCell::new(None),
    };
    let mut system = Exchange {
        host: &host,
        next_event: Cell::new(earliest(
            update.next_event_time,
            plan.inputs.next_event(start),
        )),
    };
    let mut values = vec![vec![0.0; grid.len()]; n_out];
    let mut sample = vec![0.0; n_out];
    let mut system = Shifted {
        inner: &mut system,
        start,
    };
    let stats = ode::integrate(&mut system, &y0, grid, options, |i, y| {
        if host.failed() {
            return;
        }
        let t = grid[i] + start;
        if let Err(e) = host.read(t, y, &mut sample) {
            host.fail(t, e);
            return;
        }
        for (series, v) in values.iter_mut().zip(&sample) {
            series[i] = *v;
        }
    });
    if let Some((t, e)) = host.error.take() {
        return Err(failed(t, e));
    }
    let stats = stats?;
    Ok(Trajectory {
        time: grid.to_vec(),
        values,
        stats,
    })
}
