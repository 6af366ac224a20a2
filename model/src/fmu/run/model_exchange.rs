//! Model Exchange: the FMU's derivatives integrated by calib's solver, in the order of the
//! standard's simulation algorithm (see the [parent module](super) for the order and why).

use super::*;

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
    fn check_step(&self, t: f64, y: &[f64]) -> Result<(), SimulationError> {
        self.inner.check_step(t + self.start, y)
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

fn event_iteration(fmu: &mut Instance) -> Result<crate::fmu::ffi::EventUpdate, FmuError> {
    let mut result = crate::fmu::ffi::EventUpdate::default();
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
pub(super) fn integrate(
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
