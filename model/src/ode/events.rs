//! Events of hybrid systems: their location on a step's continuous extension, the mode
//! switch, and the guard against events that accumulate.
//!
//! An event fires when an event function `g_k` goes from `≥ 0` to `< 0` within an accepted
//! step; its time is located on the step's continuous extension by the Illinois variant of
//! regula falsi, on the side where the event condition holds. The driver cuts the step
//! there, lets the system switch mode (and reset its state), and restarts from the event, so
//! the right-hand side is always smooth inside a step, which is what the error control
//! assumes.
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
//! References:
//! - L. F. Shampine, S. Thompson, "Event location for ordinary differential equations",
//!   Computers & Mathematics with Applications 39 (2000) 43–54.
//! - M. Dowell, P. Jarratt, "A modified regula falsi method for computing the root of an
//!   equation", BIT 11 (1971) 168–174 (the Illinois method).

use super::driver::Interpolant;
use super::HybridSystem;
use crate::model::SimulationError;

/// Events the guard against accumulating events looks back over.
pub const ZENO_EVENTS: usize = 32;
/// Span of [`ZENO_EVENTS`] events, relative to the integrated span, below which events are
/// taken to accumulate: a millionth of a second over a 1000 s simulation.
const ZENO_RELATIVE_SPAN: f64 = 1e-9;

/// Detects events that accumulate at one time: [`ZENO_EVENTS`] of them within a span tiny
/// next to the integrated one. Located events come strictly one after the other, so a count
/// of events at an identical time would never see them.
pub(super) struct ZenoGuard {
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
    pub(super) fn new(t_end: f64) -> Self {
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

/// The earliest event of the accepted step `[t, t_new]` (state `ynew` at its end, event
/// functions `g_old` at its start): the first event function to change sign from `≥ 0` to
/// `< 0`, located on the step's continuous extension. Leaves the event functions at
/// `t_new` in `g_new`.
#[allow(clippy::too_many_arguments)]
pub(super) fn first_event<S: HybridSystem, D: Interpolant>(
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
pub(super) fn switch_mode<S: HybridSystem>(
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::SolverOptions;
    use crate::ode::integrate;
    use std::cell::Cell;

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
}
