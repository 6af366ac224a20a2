//! ODE solvers for hybrid systems: Dormand–Prince 5(4) and Runge–Kutta–Chebyshev, with
//! dense output and event location.
//!
//! A model hands its equations over as a [`HybridSystem`]: a right-hand side, and for
//! hybrid systems (mode switches such as stick–slip friction) event functions, the mode
//! switch at an event and the mode that events accumulating at one time approximate.
//!
//! Two one-step methods integrate them. Each is a `Stepper` (in `driver.rs`): an attempted
//! step with its error estimate, a continuous extension of the last step, and its own
//! step-size controller:
//! - [`integrate`], Dormand–Prince 5(4) (`dopri.rs`), for non-stiff systems and tight
//!   tolerances;
//! - [`rkc::integrate`], the Runge–Kutta–Chebyshev method ([`rkc`]), for mildly stiff systems
//!   whose step size Dormand–Prince's stability would set.
//!
//! Both run in the one loop of `drive` (in `driver.rs`), which owns what they share: outputs
//! read off the continuous extension at the requested times (so the step size is set by
//! accuracy alone, never by the output grid), the step limit, the clamp of the last step,
//! rejected steps, and the events (`events.rs`): located on the continuous extension, the
//! step cut there, the mode switched and the integration restarted from the event. A new
//! method is a new `Stepper`, and gets outputs, events and limits as they are.
//!
//! References: with each method, and
//! - E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*,
//!   2nd ed., Springer 1993, §II.4–II.6;
//! - L. F. Shampine, S. Thompson, "Event location for ordinary differential equations",
//!   Computers & Mathematics with Applications 39 (2000) 43–54.

mod dopri;
mod driver;
mod events;
pub mod rkc;

pub use dopri::integrate;
pub use events::ZENO_EVENTS;

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
    /// with [`crate::model::SimulationError::Chattering`].
    fn on_chattering(&mut self, _t: f64, _y: &mut [f64], _event: usize) -> bool {
        false
    }

    /// Called at the end `t` (state `y`) of every accepted step that ends without an event,
    /// once its outputs are recorded: whether the system asks for an event there (a step
    /// event, as an FMU's `fmi*CompletedIntegratorStep` may). If so the driver calls
    /// [`HybridSystem::on_event`] at `t` with the event number `event_count()` and restarts
    /// from there, as after a located event.
    fn step_completed(&mut self, _t: f64, _y: &[f64]) -> bool {
        false
    }

    /// Checked at the end `t` (state `y`) of every accepted step that ends without an
    /// event: an error ends the simulation there. A system whose right-hand side may stop
    /// being a number (a user's formula) says so here, where a step that was kept reached
    /// it, rather than at a trial stage the step-size control throws away.
    fn check_step(&self, _t: f64, _y: &[f64]) -> Result<(), crate::model::SimulationError> {
        Ok(())
    }
}
