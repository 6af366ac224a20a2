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

mod model_exchange;

use model_exchange::integrate;

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
