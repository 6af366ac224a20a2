//! One simulation of an FMU instance onto a time grid.
//!
//! **Co-Simulation**: initialise, then `doStep` from one output time to the next and read the
//! outputs after each step (the FMU's own solver sets the accuracy).
//!
//! **Model Exchange**: initialise, run the event iteration, then integrate the FMU's
//! derivatives with calib's Dormand–Prince ([`crate::ode`]) at the requested tolerance.
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

/// Initialise `instance` (reset first unless `fresh`) and simulate it onto `grid`.
pub fn simulate(
    instance: &mut Instance,
    fresh: bool,
    plan: &Plan,
    grid: &[f64],
    options: &SolverOptions,
) -> Result<Trajectory, SimulationError> {
    if !fresh {
        instance.reset().map_err(|e| failed(0.0, e))?;
    }
    let stop = grid.last().copied().unwrap_or(0.0);
    let init = |instance: &mut Instance| -> Result<(), FmuError> {
        instance.set_reals(plan.parameter_vrs, plan.parameters)?;
        let tolerance = (plan.interface == Interface::CoSimulation).then_some(options.rtol);
        instance.enter_initialization(tolerance, Some(stop))?;
        instance.exit_initialization()
    };
    init(instance).map_err(|e| failed(0.0, e))?;
    match plan.interface {
        Interface::CoSimulation => co_simulate(instance, plan, grid),
        Interface::ModelExchange => integrate(instance, plan, grid, options),
    }
}

fn co_simulate(
    instance: &mut Instance,
    plan: &Plan,
    grid: &[f64],
) -> Result<Trajectory, SimulationError> {
    let n_out = plan.outputs.len();
    let mut values = vec![Vec::with_capacity(grid.len()); n_out];
    let mut sample = vec![0.0; n_out];
    let mut t = 0.0;
    let mut terminated = false;
    let mut stats = SolverStats::default();
    for &target in grid {
        if target > t && !terminated {
            terminated = instance.do_step(t, target - t).map_err(|e| failed(t, e))?;
            stats.accepted_steps += 1;
            t = target;
            plan.outputs
                .read(instance, &mut sample)
                .map_err(|e| failed(t, e))?;
        } else if stats.accepted_steps == 0 && values.first().is_none_or(|v| v.is_empty()) {
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

fn integrate(
    instance: &mut Instance,
    plan: &Plan,
    grid: &[f64],
    options: &SolverOptions,
) -> Result<Trajectory, SimulationError> {
    let nx = plan.states;
    let update = event_iteration(instance).map_err(|e| failed(0.0, e))?;
    instance
        .enter_continuous_time_mode()
        .map_err(|e| failed(0.0, e))?;
    let mut y0 = vec![0.0; nx.max(1)];
    if nx > 0 {
        instance
            .get_states(&mut y0[..nx])
            .map_err(|e| failed(0.0, e))?;
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
                let t = grid[i];
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
