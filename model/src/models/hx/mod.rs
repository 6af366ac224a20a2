//! `hx_highfi` / `hx_lowfi`: a microtube (microchannel) evaporator test bench, R134a inside
//! flat multiport tubes, air across louvered fins.
//!
//! # Structure
//!
//! The refrigerant path (four passes of the core, unrolled, see [`geometry`]) is cut into
//! `N` segments of equal length (`hx_highfi`: N = 40, `hx_lowfi`: N = 6). Each segment `i`
//! has one state, its wall temperature `T_w,i` (tubes and fins lumped, heat capacity
//! `C_w/N`):
//!
//! ```text
//! (C_w/N) dT_w,i/dt = Q_air,i − Q_ref,i − (G_amb/N)(T_w,i − T_amb)
//! ```
//!
//! **Air side** (ε-NTU, cross flow against a wall at uniform temperature, `C_min/C_max = 0`):
//! each segment sees the share `ṁ_a/N` of the air, entering at `T_a,in`;
//! `Q_air,i = ε (ṁ_a c_p/N)(T_a,in − T_w,i)`, `ε = 1 − exp(−NTU)`,
//! `NTU = η_o h_a A_a/(ṁ_a c_p)`, `η_o = 1 − (A_f/A_a)(1 − η_f)`, with
//! `h_a = CF_AirHT · j G_c c_p Pr^(−2/3)` and the Colburn factor `j` of Chang & Wang
//! (1997) for louvered fins ([`correlations`]).
//!
//! **Refrigerant side**, marched from the inlet quasi-steadily (the refrigerant's own heat
//! capacity and mass storage are neglected next to the wall's): in segment `i`, at inlet
//! pressure `p_i` and enthalpy `h_i`,
//! - two-phase (`h_i < h_v(p_i)`): `Q = α_tp A_r,i (T_w,i − T_sat(p_i))` with
//!   `α_tp = CF_RefHT · (F h_l + S h_FZ)` of Chen (1966) at the inlet quality. If the
//!   segment reaches the dew point, the fraction `f = ṁ (h_v − h_i)/Q` of its area boils
//!   the rest of the liquid and the remainder superheats the vapour as below;
//! - superheated vapour: `Q = ṁ c_p (T_w,i − T_i)(1 − exp(−α_v A/(ṁ c_p)))` with
//!   `α_v = CF_RefHT · Nu k/D_h`, `Nu` Gnielinski (1976) blended with the laminar value;
//! - `h_{i+1} = h_i + Q/ṁ`; the outlet enthalpy and temperature come out of the march.
//!
//! **Pressure**: the outlet pressure is the boundary condition; the inlet pressure
//! `p_in` is a state. The march starts from `p_in` and yields a residual `r` of the
//! outlet condition:
//! - `hx_highfi`: `p_{i+1} = p_i − Δp_i`, `Δp_i = CF_Refdp · Δp_friction + Δp_momentum`;
//!   two-phase friction by Friedel (1979) at the segment's mean quality, vapour friction
//!   by Churchill (1977), the momentum term `G² (v_out − v_in)` of homogeneous flow
//!   ([`pressure_drop`]); `r = p_N − p_out`;
//! - `hx_lowfi`: the density-profile model
//!   `Δp = CF_Refdp · Δp0 · (ṁ/ṁ0)² · (ρ0/ρ̄)`, where `ρ̄` is the path-mean density of the
//!   current state (harmonic mean of the segments' homogeneous densities, since
//!   homogeneous friction scales with specific volume) and `ρ0` the same density at the
//!   nominal point: `ρ̄` of this model's own steady state with inlet `(p0, h0)`, flow
//!   `ṁ0`, outlet pressure `p0 − Δp0`, the nominal air and every factor 1. So at every
//!   factor 1 the model gives `Δp0` at its nominal point and, with [`LOWFI_NOMINAL`],
//!   `hx_highfi`'s nominal steady state (pressure drop within 0.1 %, heat flow within
//!   1.5 %). The pressure falls linearly along the path; `r = p_in − p_out − Δp`.
//!
//! and `τ_p dp_in/dt = −r` with `τ_p` = [`PRESSURE_LAG`] = 1 s, a lumped stand-in for the
//! refrigerant inventory that the quasi-steady march neglects. Without it the inlet
//! pressure would be the root of `r(p_in) = 0` at frozen wall temperatures, and that root
//! is not unique: a lower inlet pressure raises every wall superheat, moves the dry-out
//! point upstream, and shortens the high-quality two-phase region, whose Friedel gradient
//! exceeds the vapour's, so `r` is V-shaped around the steady state and the explicit
//! integrator chattered between roots (measured: 24 000 steps and non-flat outputs at
//! constant inputs). With the lag, the walls settle the superheat before the pressure
//! moves, and the steady state is unchanged.
//!
//! The air-side pressure drop `Δp_air = CF_Airdp · f (A_a/A_c) G_c²/(2ρ)` (with `f = 4 j`)
//! only feeds the `dp_air` output.
//!
//! **Ambient loss** (effect `ambient_loss`, conductance `G_amb` in W/K, 0 = absent): heat
//! flows from the wall to the room at `T_amb`; for an evaporator colder than the room it is
//! a heat gain.
//!
//! # Time integration
//!
//! States: `N` wall temperatures and the inlet pressure. The fastest wall mode (wall to
//! boiling refrigerant, whose heat flux grows like the square of the wall superheat in
//! Chen's nucleate term, over the wall capacity) has a time constant of about 0.1–0.3 s
//! (spectral radius 8–10 s⁻¹ at the defaults). It holds the crate's Dormand–Prince 5(4)
//! ([`crate::ode`]) to its stability bound, steps of about 0.4 s, almost whatever the
//! tolerance, so the integrator depends on the tolerance:
//! - at rtol ≥ 10⁻⁶ ([`RKC_MAX_ACCURACY`], the models' own tolerance and looser): the
//!   Runge–Kutta–Chebyshev method of [`crate::ode::rkc`] (Sommeijer, Shampine & Verwer
//!   1998), explicit and of second order, whose stability interval grows with the square
//!   of its stage count, with the spectral radius from a power iteration on the
//!   right-hand side. Where the solution is smooth it takes steps of seconds; where the
//!   dry-out front crosses a segment boundary (the right-hand side bends within a few
//!   millikelvin of wall temperature) it shortens its steps and nothing more. It runs at
//!   [`RKC_TOLERANCE_SCALE`] times the requested tolerances: a second-order method uses up
//!   its tolerance where Dormand–Prince, held back by stability, stays well inside it, and
//!   at the full tolerance the outputs left the bounds of
//!   `outputs_at_the_model_tolerance_stay_near_the_reference`;
//! - at tighter tolerances: Dormand–Prince, as its fifth order gains on the second order
//!   of RKC, whose steps grow like `rtol^(−1/3)`.
//!
//! Both locate the event of a state leaving the property tables (below) on their
//! continuous extension, and a simulation that leaves them fails the same way with either.
//! Rosenbrock methods (linearly implicit) were measured and fail across that bend: the
//! dry-out front makes the right-hand side only piecewise smooth, and their stages are
//! wrong at any useful step, where an explicit method only sees a kink in time.
//!
//! The initial state is the steady state at the inputs of t = 0, solved directly: for a
//! given inlet pressure, each segment's wall balance is a scalar equation in `T_w,i`
//! (strictly decreasing), solved in flow order by regula falsi; a secant iteration on the
//! inlet pressure meets the outlet condition (to 10⁻¹⁰ of the pressure drop). Outputs are
//! therefore flat until the first ramp, and the integration starts there. Either solve
//! that does not converge fails the simulation with its reason (`SimulationError::Failed`
//! at t = 0).
//!
//! **Property range**: R134a properties are tabulated for 0.6–20 bar, two-phase and
//! vapour up to 160 kJ/kg of superheat (no subcooled liquid). A state outside them is a
//! failed simulation, never a clamped property: at t = 0 when the steady state (or the
//! low-fidelity nominal point) lies outside, else at the first accepted instant where a
//! state of the march leaves them, located by the solver's event search; trial stages of
//! the solver are not counted.
//!
//! **Cost**: the march is one chain of dependent operations (each segment's saturation
//! lookup waits for the previous segment's pressure drop), so a right-hand side costs
//! mostly the latency of its logarithms, exponentials and divisions. Hence the property
//! groups that depend on pressure alone come interpolated from the saturation table
//! ([`refrigerant::Groups`]), powers are exponentials of shared logarithms, the quantities
//! that depend on the mass flux alone are computed once per march ([`pressure_drop::Flow`]),
//! the air side is recomputed only when the air inputs move, and the flat first minute is
//! not integrated. The measurements behind these choices, the integrator's, and the ways to
//! a faster `hx_highfi` that were measured and not kept are in `docs/hx.md`.
//!
//! # Boundary conditions
//!
//! Ramps of refrigerant mass flow, inlet enthalpy, outlet pressure, air inlet temperature
//! and air mass flow, in turn between 60 s and 230 s ([`boundary`]); their start and end
//! values are parameters. Each is also a model input (`mdot_ref` kg/s, `h_in` J/kg,
//! `p_out` Pa, `T_air_in` K, `mdot_air` kg/s): a measured signal that drives it replaces
//! its ramp, and inputs left undriven keep their ramps, to the bit. The steady initial
//! state is then that of the inputs at t = 0, and the integration starts where the first
//! input moves (for a bench record with noise on its signals: at once).
//!
//! # Nominal operating point
//!
//! At the start values ([`NOMINAL`]: 0.021 kg/s of R134a at 250 kJ/kg, quality 0.25 at the
//! inlet; 2.7 bar at the outlet; 0.15 kg/s of air at 25 °C) `hx_highfi` gives 3.27 kW,
//! a refrigerant pressure drop of 38.2 kPa (inlet 3.08 bar) and 9.7 K of outlet superheat
//! (measured; `nominal_point_is_the_documented_one` holds them to ranges).
//! The refrigerant flow is a little below the 0.025 kg/s of the bench specification: with
//! dry air (no condensate on the fins), 0.15 kg/s at 25 °C can give at most about
//! `ṁ_a c_p (25 − T_sat) ≈ 3.9 kW` at infinite NTU, less than the 3.9 kW that 0.025 kg/s
//! needs to leave superheated from quality 0.25.
//!
//! # Sources
//!
//! See [`correlations`], [`pressure_drop`] and [`refrigerant`] for the papers behind each
//! correlation and the property data.

pub mod boundary;
pub mod correlations;
pub mod evaporator;
pub mod geometry;
pub mod pressure_drop;
pub mod refrigerant;

#[cfg(test)]
mod tests;

use crate::model::{
    check_request, EffectSpec, InputSpec, Model, ModelInfo, OutputSpec, ParameterSpec,
    SimulationError, SolverOptions, SolverStats, Trajectory,
};
use crate::ode::{integrate, rkc, HybridSystem};
use crate::Run;
use boundary::{Driven, Inputs, Ramps};
use evaporator::{describe_out_of_range, Evaporator, Fidelity, NominalPoint, Settings};
use geometry::Geometry;
use std::cell::RefCell;

const T0: f64 = 273.15;

/// Segments of each model.
pub const HIGHFI_SEGMENTS: usize = 40;
pub const LOWFI_SEGMENTS: usize = 6;

/// The nominal operating point (start values of the ramps).
pub const NOMINAL: Inputs = Inputs {
    mdot_ref: 0.021,
    h_in: 250e3,
    p_out: 2.7e5,
    t_air_in: T0 + 25.0,
    mdot_air: 0.15,
};

/// Nominal point of the low-fidelity pressure-drop model: the high-fidelity model's
/// steady state at [`NOMINAL`] (inlet pressure, inlet enthalpy, flow, pressure drop; the
/// test `lowfi_nominal_matches_highfi_steady_state` computes it), rounded so that
/// `p0 − dp0` is [`NOMINAL`]'s outlet pressure.
pub const LOWFI_NOMINAL: NominalPoint = NominalPoint {
    p0: 3.082e5,
    h0: 250e3,
    mdot0: 0.021,
    dp0: 38.2e3,
};

/// Outputs, in order.
pub const OUTPUTS: [(&str, &str, &str); 10] = [
    (
        "dp_ref",
        "Pa",
        "refrigerant pressure drop, inlet minus outlet",
    ),
    ("Qdot_refTotal", "W", "heat flow into the refrigerant"),
    ("Qdot_airTotal", "W", "heat flow out of the air"),
    (
        "superheat_out",
        "K",
        "refrigerant outlet superheat (0 while the outlet is two-phase)",
    ),
    ("T_ref_out", "degC", "refrigerant outlet temperature"),
    ("T_air_out", "degC", "mixed air outlet temperature"),
    ("T_wall_mean", "degC", "mean wall temperature"),
    ("p_ref_in", "bar", "refrigerant inlet pressure"),
    ("h_ref_out", "kJ/kg", "refrigerant outlet enthalpy"),
    ("dp_air", "Pa", "air-side pressure drop"),
];

struct Param {
    name: &'static str,
    unit: &'static str,
    default: f64,
    min: f64,
    max: f64,
    description: &'static str,
}

const fn param(
    name: &'static str,
    unit: &'static str,
    default: f64,
    min: f64,
    max: f64,
    description: &'static str,
) -> Param {
    Param {
        name,
        unit,
        default,
        min,
        max,
        description,
    }
}

/// Parameters shared by both models, in order.
const COMMON: [Param; 16] = [
    param(
        "CF_RefHT",
        "1",
        1.0,
        0.1,
        5.0,
        "calibration factor on the refrigerant-side heat-transfer coefficients",
    ),
    param(
        "CF_AirHT",
        "1",
        1.0,
        0.1,
        5.0,
        "calibration factor on the air-side heat-transfer coefficient",
    ),
    param(
        "CF_Refdp",
        "1",
        1.0,
        0.1,
        5.0,
        "calibration factor on the refrigerant frictional pressure drop",
    ),
    param(
        "CF_Airdp",
        "1",
        1.0,
        0.1,
        5.0,
        "calibration factor on the air-side pressure drop",
    ),
    param(
        "mdot_ref_start",
        "kg/s",
        NOMINAL.mdot_ref,
        0.005,
        0.05,
        "refrigerant mass flow before its ramp (60-90 s)",
    ),
    param(
        "mdot_ref_end",
        "kg/s",
        0.0252,
        0.005,
        0.05,
        "refrigerant mass flow after its ramp",
    ),
    param(
        "h_in_start",
        "kJ/kg",
        250.0,
        180.0,
        450.0,
        "refrigerant inlet enthalpy before its ramp (95-125 s)",
    ),
    param(
        "h_in_end",
        "kJ/kg",
        260.0,
        180.0,
        450.0,
        "refrigerant inlet enthalpy after its ramp",
    ),
    param(
        "p_out_start",
        "bar",
        2.7,
        1.5,
        6.0,
        "refrigerant outlet pressure before its ramp (130-160 s)",
    ),
    param(
        "p_out_end",
        "bar",
        3.0,
        1.5,
        6.0,
        "refrigerant outlet pressure after its ramp",
    ),
    param(
        "T_air_in_start",
        "degC",
        25.0,
        0.0,
        50.0,
        "air inlet temperature before its ramp (165-195 s)",
    ),
    param(
        "T_air_in_end",
        "degC",
        35.0,
        0.0,
        50.0,
        "air inlet temperature after its ramp",
    ),
    param(
        "mdot_air_start",
        "kg/s",
        NOMINAL.mdot_air,
        0.05,
        0.4,
        "air mass flow before its ramp (200-230 s)",
    ),
    param(
        "mdot_air_end",
        "kg/s",
        0.195,
        0.05,
        0.4,
        "air mass flow after its ramp",
    ),
    param(
        "C_wall",
        "J/K",
        1430.0,
        100.0,
        10000.0,
        "heat capacity of tubes and fins",
    ),
    param(
        "T_amb",
        "degC",
        25.0,
        -10.0,
        50.0,
        "room temperature (for the ambient_loss effect)",
    ),
];

/// Parameters of the low-fidelity pressure-drop model.
const LOWFI_EXTRA: [Param; 4] = [
    param(
        "p0",
        "bar",
        LOWFI_NOMINAL.p0 / 1e5,
        1.5,
        8.0,
        "nominal inlet pressure of the density-profile pressure drop",
    ),
    param(
        "h0",
        "kJ/kg",
        LOWFI_NOMINAL.h0 / 1e3,
        180.0,
        450.0,
        "nominal inlet enthalpy of the density-profile pressure drop",
    ),
    param(
        "mdot0",
        "kg/s",
        LOWFI_NOMINAL.mdot0,
        0.005,
        0.05,
        "nominal mass flow of the density-profile pressure drop",
    ),
    param(
        "dp0",
        "Pa",
        LOWFI_NOMINAL.dp0,
        1e3,
        2e5,
        "nominal pressure drop of the density-profile model",
    ),
];

/// A hosted heat-exchanger model of either fidelity.
pub struct HxModel {
    info: ModelInfo,
    fidelity: Fidelity,
    segments: usize,
}

/// `hx_highfi`.
pub fn highfi() -> HxModel {
    HxModel::new(Fidelity::High, HIGHFI_SEGMENTS)
}

/// `hx_lowfi`.
pub fn lowfi() -> HxModel {
    HxModel::new(Fidelity::Low, LOWFI_SEGMENTS)
}

impl HxModel {
    /// A model of the given fidelity and segmentation (other segment counts are for tests).
    pub fn new(fidelity: Fidelity, segments: usize) -> Self {
        let (name, description, extra): (&str, &str, &[Param]) = match fidelity {
            Fidelity::High => (
                "hx_highfi",
                "microtube evaporator test bench (R134a / air): 40 segments with dynamic wall \
                 temperatures, Chen boiling, Gnielinski vapour, Chang-Wang louvered fins, \
                 Friedel two-phase pressure drop",
                &[],
            ),
            Fidelity::Low => (
                "hx_lowfi",
                "microtube evaporator test bench (R134a / air): 6 segments with dynamic wall \
                 temperatures, same heat transfer as hx_highfi, density-profile pressure drop \
                 around a nominal point",
                &LOWFI_EXTRA,
            ),
        };
        let parameters = COMMON
            .iter()
            .chain(extra)
            .map(|p| ParameterSpec {
                name: p.name.into(),
                unit: p.unit.into(),
                default: p.default,
                min: p.min,
                max: p.max,
                description: p.description.into(),
            })
            .collect();
        let outputs = OUTPUTS
            .iter()
            .map(|(n, u, d)| OutputSpec {
                name: (*n).into(),
                unit: (*u).into(),
                description: (*d).into(),
            })
            .collect();
        let effects = vec![EffectSpec {
            name: "ambient_loss".into(),
            unit: "W/K".into(),
            min: 0.0,
            max: 100.0,
            description: "heat flow from the wall to the room, G (T_wall - T_amb)".into(),
            parameter: None,
        }];
        Self {
            info: ModelInfo {
                name: name.into(),
                version: 5,
                description: description.into(),
                parameters,
                outputs,
                effects,
                inputs: boundary::INPUTS
                    .iter()
                    .enumerate()
                    .map(|(k, (name, unit, ..))| InputSpec {
                        name: (*name).into(),
                        unit: (*unit).into(),
                        description: boundary::input_description(k),
                    })
                    .collect(),
            },
            fidelity,
            segments,
        }
    }

    /// Simulation settings from a full parameter vector (already checked for length).
    pub fn settings(&self, p: &[f64]) -> Result<Settings, SimulationError> {
        for (i, v) in p.iter().enumerate() {
            let (lo, hi) = self.info.bounds_at(i);
            if *v < lo || *v > hi {
                return Err(SimulationError::InvalidInput(format!(
                    "parameter `{}` = {v} is outside [{lo}, {hi}]",
                    self.info.name_at(i)
                )));
            }
        }
        let inputs = |k: usize| Inputs {
            mdot_ref: p[4 + k],
            h_in: p[6 + k] * 1e3,
            p_out: p[8 + k] * 1e5,
            t_air_in: p[10 + k] + T0,
            mdot_air: p[12 + k],
        };
        let nominal = match self.fidelity {
            Fidelity::High => LOWFI_NOMINAL,
            Fidelity::Low => NominalPoint {
                p0: p[16] * 1e5,
                h0: p[17] * 1e3,
                mdot0: p[18],
                dp0: p[19],
            },
        };
        Ok(Settings {
            fidelity: self.fidelity,
            segments: self.segments,
            geometry: Geometry::BENCH,
            cf_ref_ht: p[0],
            cf_air_ht: p[1],
            cf_ref_dp: p[2],
            cf_air_dp: p[3],
            ramps: Ramps {
                start: inputs(0),
                end: inputs(1),
            },
            wall_capacity: p[14],
            t_ambient: p[15] + T0,
            ambient_conductance: p[self.info.parameters.len()],
            nominal,
        })
    }
}

/// The tightest relative tolerance integrated by RKC ([`rkc`]); tighter ones go to
/// Dormand–Prince, which takes fewer steps there. See the module documentation.
pub const RKC_MAX_ACCURACY: f64 = 1e-6;
/// RKC runs at this fraction of the requested tolerances: being of second order, it uses up
/// the tolerance where Dormand–Prince, held back by its stability, stays well inside it, so
/// at the same tolerance its wall temperatures (and with them the air-side heat flow) would
/// be about three times further from the exact solution. See the module documentation.
pub const RKC_TOLERANCE_SCALE: f64 = 0.3;

/// Time constant (s) of the inlet-pressure lag; see the module documentation.
pub const PRESSURE_LAG: f64 = 1.0;

/// The ODE: wall temperatures of the segments, then the inlet pressure. Its clock starts
/// at `t0` of the simulation's.
///
/// Its one event function is the property-table margin of the march ([`evaporator::March::margin`]):
/// it is evaluated on accepted steps only, so a trial stage outside the tables (rejected, or
/// a stage of a step that ends inside) never counts, and the event is located in time.
/// Once it fires the simulation has failed: the right-hand side turns NaN, the solver
/// stops, and [`HxModel::simulate`] reports the recorded time and state.
struct Dynamics<'a> {
    evap: &'a Evaporator,
    inv_capacity: f64,
    t0: f64,
    /// The last march's table margin: the event function of an accepted step is
    /// evaluated where the step's last stage was.
    last: RefCell<LastMarch>,
    /// The first accepted instant (simulation time) outside the tables, and the state.
    left: Option<(f64, (f64, f64))>,
}

/// Table margin and worst state `(p, h)` of the march at time `t`, state `y`.
struct LastMarch {
    t: f64,
    y: Vec<f64>,
    margin: f64,
    worst: (f64, f64),
}

impl<'a> Dynamics<'a> {
    /// The dynamics of `evap` from `t0` on: no march remembered yet, and no state outside the
    /// tables.
    fn new(evap: &'a Evaporator, t0: f64) -> Self {
        Dynamics {
            evap,
            inv_capacity: 1.0 / evap.segment_capacity(),
            t0,
            last: RefCell::new(LastMarch {
                t: f64::NAN,
                y: Vec::new(),
                margin: f64::NAN,
                worst: (f64::NAN, f64::NAN),
            }),
            left: None,
        }
    }

    /// Margin and worst state of the march at `(t, y)`, from the last right-hand side when
    /// it was evaluated there.
    fn margin_at(&self, t: f64, y: &[f64]) -> (f64, (f64, f64)) {
        {
            let last = self.last.borrow();
            if last.t == t && last.y == y {
                return (last.margin, last.worst);
            }
        }
        let n = self.evap.segments();
        let mut net = vec![0.0; n];
        let (_, _, m, _) = self.evap.evaluate(self.t0 + t, &y[..n], y[n], &mut net);
        (m.margin, m.worst)
    }
}

impl HybridSystem for Dynamics<'_> {
    fn dim(&self) -> usize {
        self.evap.segments() + 1
    }

    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        if self.left.is_some() {
            dy.fill(f64::NAN);
            return;
        }
        let n = self.evap.segments();
        let (_, _, m, r) = self.evap.evaluate(self.t0 + t, &y[..n], y[n], &mut dy[..n]);
        for v in dy[..n].iter_mut() {
            *v *= self.inv_capacity;
        }
        dy[n] = -r / PRESSURE_LAG;
        let mut last = self.last.borrow_mut();
        last.t = t;
        last.y.clear();
        last.y.extend_from_slice(y);
        last.margin = m.margin;
        last.worst = m.worst;
    }

    fn event_count(&self) -> usize {
        1
    }

    fn events(&self, t: f64, y: &[f64], g: &mut [f64]) {
        g[0] = self.margin_at(t, y).0;
    }

    fn on_event(&mut self, t: f64, y: &mut [f64], _event: usize) {
        let (_, worst) = self.margin_at(t, y);
        self.left.get_or_insert((self.t0 + t, worst));
    }
}

/// Where the integration of `evap` over `grid` starts. The inputs hold their values of t = 0
/// until the first ramp (undriven) or the last sample before a signal moves (driven), and
/// `y0` is the steady state there, so the exact solution is `y0` up to then: the integration
/// starts there (a driven run whose inputs never move: at its last time).
fn integration_start(evap: &Evaporator, grid: &[f64]) -> f64 {
    if evap.is_driven() {
        evap.steady_until().min(grid[grid.len() - 1])
    } else {
        boundary::FIRST_RAMP
    }
}

/// Integrate `system` from `y0` over the times `rest` after its start: by RKC at rtol ≥
/// [`RKC_MAX_ACCURACY`] (at [`RKC_TOLERANCE_SCALE`] times the tolerances), else by
/// Dormand–Prince, as the module documentation explains.
fn integrate_dynamics(
    system: &mut Dynamics<'_>,
    y0: &[f64],
    rest: &[f64],
    options: &SolverOptions,
    out: impl FnMut(usize, &[f64]),
) -> Result<SolverStats, SimulationError> {
    if options.rtol >= RKC_MAX_ACCURACY {
        let options = SolverOptions {
            rtol: RKC_TOLERANCE_SCALE * options.rtol,
            atol: RKC_TOLERANCE_SCALE * options.atol,
            ..*options
        };
        rkc::integrate(system, y0, rest, &options, out)
    } else {
        integrate(system, y0, rest, options, out)
    }
}

/// All outputs at one instant, in the order of [`OUTPUTS`].
fn outputs_at(evap: &Evaporator, t: f64, y: &[f64], scratch: &mut [f64]) -> [f64; 10] {
    let n = evap.segments();
    let (inp, air, m, _) = evap.evaluate(t, &y[..n], y[n], scratch);
    let (t_out, superheat) = Evaporator::outlet_state(inp.p_out, m.h_out);
    let c_air = air.c_seg * n as f64;
    [
        m.p_in - inp.p_out,
        m.q_ref,
        m.q_air,
        superheat,
        t_out - T0,
        inp.t_air_in - m.q_air / c_air - T0,
        m.wall_mean - T0,
        m.p_in / 1e5,
        m.h_out / 1e3,
        air.dp,
    ]
}

impl Model for HxModel {
    fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// The 300 s bench cycle.
    fn default_stop_time(&self) -> f64 {
        300.0
    }

    /// rtol 1e-6: over the 300 s bench cycle its outputs stay within 3.5 Pa and 0.75 W of a
    /// run at 1e-8 (`hx_highfi`), far below what pressure and heat-flow sensors resolve,
    /// at half the steps. Integrated by RKC since (see the module documentation): within
    /// 0.61 Pa and 0.34 W of a run at rtol 1e-9, with 45 % of the right-hand sides of a run
    /// at 1e-8.
    fn default_options(&self) -> SolverOptions {
        SolverOptions {
            rtol: 1e-6,
            atol: 1e-8,
            ..SolverOptions::default()
        }
    }

    fn simulate(&self, run: &Run) -> Result<Trajectory, SimulationError> {
        run.refuse_forces(self.info())?;
        let Run {
            params,
            grid,
            outputs,
            options,
            inputs,
            ..
        } = *run;
        check_request(&self.info, params, grid, outputs)?;
        inputs
            .check(&self.info, 0.0, grid[grid.len() - 1])
            .map_err(SimulationError::InvalidInput)?;
        let settings = self.settings(params)?;
        let failed = |time: f64| move |reason: String| SimulationError::Failed { time, reason };
        let evap = Evaporator::new(settings)
            .map_err(failed(0.0))?
            .driven_by(Driven::new(inputs));
        let y0 = evap.steady_state(0.0).map_err(failed(0.0))?;
        let t0 = integration_start(&evap, grid);
        let mut system = Dynamics::new(&evap, t0);
        let mut values = vec![Vec::with_capacity(grid.len()); outputs.len()];
        let mut scratch = vec![0.0; evap.segments()];
        // Up to `t0` the inputs hold their values of t = 0 exactly and the state is `y0`: one
        // evaluation of the outputs serves every time there.
        let flat = grid.partition_point(|&t| t <= t0);
        if flat > 0 {
            let all = outputs_at(&evap, grid[0], &y0, &mut scratch);
            for (v, &o) in values.iter_mut().zip(outputs) {
                v.resize(flat, all[o]);
            }
        }
        let mut record = |t: f64, y: &[f64]| {
            let all = outputs_at(&evap, t, y, &mut scratch);
            for (v, &o) in values.iter_mut().zip(outputs) {
                v.push(all[o]);
            }
        };
        let rest: Vec<f64> = grid[flat..].iter().map(|t| t - t0).collect();
        let result = integrate_dynamics(&mut system, &y0, &rest, options, |i, y| {
            record(grid[flat + i], y)
        });
        if let Some((time, (p, h))) = system.left {
            return Err(failed(time)(describe_out_of_range(p, h)));
        }
        let stats = result?;
        let recorded = values.iter().map(Vec::len).min().unwrap_or(0);
        if let Some(k) = (0..recorded).find(|&k| values.iter().any(|v| !v[k].is_finite())) {
            return Err(SimulationError::Diverged { time: grid[k] });
        }
        Ok(Trajectory {
            time: grid.to_vec(),
            values,
            stats,
        })
    }
}
