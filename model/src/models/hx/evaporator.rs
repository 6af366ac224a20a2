//! The segmented evaporator: quasi-steady refrigerant march, ε-NTU air side, dynamic
//! wall temperatures.
//!
//! See the module documentation of [`super`] for the equations. This file holds the
//! march along the refrigerant path for given wall temperatures (used by the
//! time integration) and the direct steady-state solve (used for the initial state and
//! for the reference density of the low-fidelity pressure drop).
//!
//! Every march measures how far its states lie inside the property tables
//! ([`March::margin`], negative outside): a steady state outside them is an error, and the
//! time integration stops with a failure at the first accepted instant where the margin
//! turns negative (see [`super`]). Neither solve returns an unconverged result.

use std::cell::Cell;

use super::boundary::{Driven, Inputs, Ramps};
use super::correlations::{colburn_j, fin_efficiency, louver_group, Air};
use super::geometry::Geometry;
use super::pressure_drop::{self, Flow};
use super::refrigerant::{self, saturation, Saturation};
use super::NOMINAL;

mod refrigerant_side;
use refrigerant_side::Inlet;

/// Which pressure-drop model, and how fine the segmentation.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fidelity {
    /// Friedel two-phase friction, Churchill single-phase friction and the homogeneous
    /// momentum term, marched segment by segment.
    High,
    /// The density-profile model around a nominal point; linear pressure profile.
    Low,
}

/// The nominal point of the low-fidelity pressure-drop model (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NominalPoint {
    pub p0: f64,
    pub h0: f64,
    pub mdot0: f64,
    pub dp0: f64,
}

/// Everything that defines one simulation, in SI units.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Settings {
    pub fidelity: Fidelity,
    pub segments: usize,
    pub geometry: Geometry,
    pub cf_ref_ht: f64,
    pub cf_air_ht: f64,
    pub cf_ref_dp: f64,
    pub cf_air_dp: f64,
    pub ramps: Ramps,
    /// Heat capacity of tubes and fins (J/K).
    pub wall_capacity: f64,
    /// Ambient temperature (K) and wall-to-ambient conductance (W/K, 0 = no loss).
    pub t_ambient: f64,
    pub ambient_conductance: f64,
    /// Used by [`Fidelity::Low`] only.
    pub nominal: NominalPoint,
}

/// Air side at one instant: per-segment capacity rate and effectiveness.
#[derive(Debug, Clone, Copy)]
pub struct AirSide {
    pub t_in: f64,
    /// `ṁ_a c_p / N` (W/K).
    pub c_seg: f64,
    pub effectiveness: f64,
    /// Core pressure drop (Pa).
    pub dp: f64,
}

/// One segment's result.
#[derive(Debug, Clone, Copy)]
struct Segment {
    q_ref: f64,
    h_out: f64,
    /// Pressure drop over the segment (high fidelity only, else 0).
    dp: f64,
    /// Specific volume at the segment's mean enthalpy (low fidelity only, else 0).
    v_mid: f64,
    /// [`enthalpy_margin`] of the segment's inlet state.
    margin: f64,
}

/// Totals of one march along the path.
#[derive(Debug, Clone, Copy, Default)]
pub struct March {
    pub p_in: f64,
    pub p_end: f64,
    pub h_out: f64,
    pub q_ref: f64,
    pub q_air: f64,
    pub q_ambient: f64,
    pub wall_mean: f64,
    /// Low fidelity: the path-mean density ρ̄ (harmonic mean of the segments' homogeneous
    /// densities) and the model's pressure drop for this march.
    pub rho_mean: f64,
    pub dp_model: f64,
    /// How far the states of the march lie inside the property tables: the smallest
    /// [`table_margin`] along the path, negative when one lies outside; `worst` is the
    /// state `(p, h)` where it is smallest.
    pub margin: f64,
    pub worst: (f64, f64),
}

impl March {
    /// Keep the smaller margin and its state; a NaN margin counts as outside.
    fn note_margin(&mut self, margin: f64, p: f64, h: f64) {
        let margin = if margin.is_nan() {
            f64::NEG_INFINITY
        } else {
            margin
        };
        if margin < self.margin {
            self.margin = margin;
            self.worst = (p, h);
        }
    }
}

/// Wall temperatures: given (time integration) or solved segment by segment (steady state).
enum Walls<'a> {
    Given(&'a [f64]),
    Steady(&'a mut [f64]),
}

/// Pre-computed constants of one simulation.
pub struct Evaporator {
    pub settings: Settings,
    n: usize,
    seg_len: f64,
    seg_area_ref: f64,
    d: f64,
    flow_area: f64,
    louver_group: f64,
    /// `ρ0` of the low-fidelity model: the path-mean density of its steady state at the
    /// nominal point (see [`Evaporator::nominal_density`]); NaN for the high fidelity.
    rho0: f64,
    /// The last air side computed, with its air inlet temperature and mass flow: undriven,
    /// the air inputs only move during their own ramps.
    air_cache: Cell<Option<(f64, f64, AirSide)>>,
    /// Measured signals in place of ramps (none: every input follows its ramp).
    driven: Driven,
}

/// Quality of dry-out inception: above it the boiling coefficient falls linearly to the
/// vapour coefficient at x = 1 (Wojtan, Ursenbacher & Thome 2005).
pub const X_DRYOUT: f64 = 0.9;

/// Relative tolerance of the inlet-pressure iteration, on the pressure drop.
const PRESSURE_TOL: f64 = 1e-10;
const PRESSURE_ITER: usize = 60;
/// Tolerance (W) and iteration limit of a segment's steady wall balance.
const WALL_TOL: f64 = 1e-9;
const WALL_ITER: usize = 200;

/// Specific volume (homogeneous in the two-phase region) at enthalpy `h` and the pressure of
/// the saturation state `s`.
fn specific_volume_at(s: &refrigerant::Saturation, h: f64) -> f64 {
    if h < s.h_v {
        let x = s.quality(h).clamp(0.0, 1.0);
        x / s.rho_v + (1.0 - x) / s.rho_l
    } else {
        1.0 / s.vapour(h).rho
    }
}

/// Relative distance of enthalpy `h` at pressure `p` (saturation state `s`) from the edges
/// of the property data: the quality while two-phase (the subcooled liquid is not
/// tabulated), `1 − (h − h_v)/u_max` in the vapour (the vapour table ends at a superheat
/// of `u_max`). Continuous across the dew line, negative outside.
fn enthalpy_margin(s: &Saturation, h: f64) -> f64 {
    if h < s.h_v {
        s.quality(h)
    } else {
        1.0 - (h - s.h_v) / refrigerant::superheat_limit()
    }
}

/// Relative distance of pressure `p` from the ends of the tables, negative outside.
fn pressure_margin(p: f64) -> f64 {
    let (p_min, p_max) = refrigerant::pressure_range();
    (p / p_min - 1.0).min(1.0 - p / p_max)
}

/// The smaller of [`pressure_margin`] and [`enthalpy_margin`] at `(p, h)`.
pub fn table_margin(p: f64, h: f64) -> f64 {
    let (p_min, p_max) = refrigerant::pressure_range();
    let s = saturation(p.clamp(p_min, p_max));
    pressure_margin(p).min(enthalpy_margin(&s, h))
}

/// What is wrong with a state `(p, h)` outside the property tables.
pub fn describe_out_of_range(p: f64, h: f64) -> String {
    let (p_min, p_max) = refrigerant::pressure_range();
    if pressure_margin(p) < 0.0 {
        return format!(
            "refrigerant pressure {:.4} bar is outside the property tables ({:.2}–{:.2} bar)",
            p / 1e5,
            p_min / 1e5,
            p_max / 1e5
        );
    }
    let s = saturation(p);
    if h < s.h_l {
        format!(
            "refrigerant enthalpy {:.2} kJ/kg at {:.4} bar is subcooled liquid (saturated \
             liquid {:.2} kJ/kg), which the property tables do not cover",
            h / 1e3,
            p / 1e5,
            s.h_l / 1e3
        )
    } else {
        format!(
            "refrigerant superheat {:.2} kJ/kg at {:.4} bar is past the vapour table's \
             {:.0} kJ/kg",
            (h - s.h_v) / 1e3,
            p / 1e5,
            refrigerant::superheat_limit() / 1e3
        )
    }
}

impl Evaporator {
    /// The evaporator of `settings`; for the low fidelity this solves its nominal steady
    /// state for `ρ0`, and fails when that has none inside the property tables.
    pub fn new(settings: Settings) -> Result<Self, String> {
        let mut evap = Self::without_reference(settings);
        if settings.fidelity == Fidelity::Low {
            evap.rho0 = evap.nominal_density()?;
        }
        Ok(evap)
    }

    fn without_reference(settings: Settings) -> Self {
        let g = settings.geometry;
        let n = settings.segments.max(1);
        Self {
            settings,
            n,
            seg_len: g.path_length() / n as f64,
            seg_area_ref: g.refrigerant_area() / n as f64,
            d: g.hydraulic_diameter(),
            flow_area: g.flow_area(),
            louver_group: louver_group(
                g.louver_angle,
                g.fin_pitch,
                g.fin_height,
                g.tube_depth,
                g.louver_length,
                g.fin_height + g.tube_thickness,
                g.fin_thickness,
                g.louver_pitch,
            ),
            rho0: f64::NAN,
            air_cache: Cell::new(None),
            driven: Driven::default(),
        }
    }

    /// The same evaporator with the inputs of `driven` following their signals instead of
    /// their ramps.
    pub fn driven_by(self, driven: Driven) -> Self {
        Self { driven, ..self }
    }

    /// The inputs at time `t`: the ramps, where a signal drives an input its value.
    #[inline]
    pub fn inputs_at(&self, t: f64) -> Inputs {
        let mut inp = self.settings.ramps.at(t);
        self.driven.apply(t, &mut inp);
        inp
    }

    /// A time up to which every input keeps its value of t = 0 (see
    /// [`Driven::steady_until`]).
    pub fn steady_until(&self) -> f64 {
        self.driven.steady_until()
    }

    /// Whether a signal drives any input.
    pub fn is_driven(&self) -> bool {
        !self.driven.is_empty()
    }

    /// `ρ0` of the density-profile pressure drop: the path-mean density `ρ̄` of this
    /// model's steady march at its nominal point — flow `ṁ0`, inlet enthalpy `h0`, inlet
    /// pressure `p0`, outlet pressure `p0 − Δp0`, the nominal air ([`NOMINAL`]), every
    /// calibration factor 1 and no ambient loss. At that point `ρ̄ = ρ0`, so the model
    /// gives `Δp0` whatever the factors; without it (`ρ0` at the inlet state) the nominal
    /// pressure drop came out 2.3 times `Δp0`.
    fn nominal_density(&self) -> Result<f64, String> {
        let nom = self.settings.nominal;
        let reference = Self::without_reference(Settings {
            cf_ref_ht: 1.0,
            cf_air_ht: 1.0,
            cf_ref_dp: 1.0,
            ambient_conductance: 0.0,
            ..self.settings
        });
        let inp = Inputs {
            mdot_ref: nom.mdot0,
            h_in: nom.h0,
            p_out: nom.p0 - nom.dp0,
            ..NOMINAL
        };
        let air = reference.air_side(&inp);
        let mut tw = vec![0.0; self.n];
        let mut net = vec![0.0; self.n];
        let m = reference
            .march(&inp, &air, nom.p0, Walls::Steady(&mut tw), &mut net)
            .map_err(|e| format!("nominal point of the pressure drop: {e}"))?;
        if m.margin < 0.0 {
            let (p, h) = m.worst;
            return Err(format!(
                "nominal point of the pressure drop (p0 {:.4} bar, h0 {:.2} kJ/kg, dp0 {:.0} \
                 Pa): {}",
                nom.p0 / 1e5,
                nom.h0 / 1e3,
                nom.dp0,
                describe_out_of_range(p, h)
            ));
        }
        Ok(m.rho_mean)
    }

    pub fn segments(&self) -> usize {
        self.n
    }

    /// ε-NTU of the finned air side against a wall at uniform temperature, per segment.
    pub fn air_side(&self, inp: &Inputs) -> AirSide {
        if let Some((t, m, air)) = self.air_cache.get() {
            if t == inp.t_air_in && m == inp.mdot_air {
                return air;
            }
        }
        let air = self.compute_air_side(inp);
        self.air_cache.set(Some((inp.t_air_in, inp.mdot_air, air)));
        air
    }

    fn compute_air_side(&self, inp: &Inputs) -> AirSide {
        let g = &self.settings.geometry;
        let air = Air::at(inp.t_air_in);
        let a_min = g.air_min_flow_area();
        let g_c = inp.mdot_air.max(1e-9) / a_min;
        let re_lp = g_c * g.louver_pitch / air.mu;
        let j = colburn_j(re_lp, self.louver_group);
        let h = self.settings.cf_air_ht * j * g_c * air.cp / air.prandtl().powf(2.0 / 3.0);
        let eta_f = fin_efficiency(h, g.fin_conductivity, g.fin_thickness, 0.5 * g.fin_height);
        let area = g.air_area();
        let eta_o = 1.0 - g.fin_area() / area * (1.0 - eta_f);
        let c = inp.mdot_air.max(1e-9) * air.cp;
        let ntu = eta_o * h * area / c;
        AirSide {
            t_in: inp.t_air_in,
            c_seg: c / self.n as f64,
            effectiveness: 1.0 - (-ntu).exp(),
            dp: self.settings.cf_air_dp * pressure_drop::air_core(j, area / a_min, g_c, air.rho),
        }
    }

    /// Refrigerant side of one segment at inlet pressure `p`, enthalpy `h`, wall `tw`, for
    /// the flow `flow` (mass flux `mdot / flow_area`, see [`Evaporator::flow`]).
    fn segment(&self, p: f64, h: f64, tw: f64, mdot: f64, flow: &Flow) -> Segment {
        let high = self.settings.fidelity == Fidelity::High;
        let s = saturation(p);
        let inlet = Inlet {
            evap: self,
            s: &s,
            flow,
            h,
            tw,
            mdot,
            high,
        };
        let (q_ref, h_out, dp) = if h < s.h_v {
            inlet.boiling()
        } else {
            inlet.superheated()
        };
        let v_mid = if high {
            0.0
        } else {
            specific_volume_at(&s, 0.5 * (h + h_out))
        };
        Segment {
            q_ref,
            h_out,
            dp,
            v_mid,
            margin: enthalpy_margin(&s, h),
        }
    }

    /// The flow-only quantities of the friction correlations at refrigerant flow `mdot`.
    fn flow(&self, mdot: f64) -> Flow {
        Flow::new(mdot / self.flow_area, self.d)
    }

    /// Heat flows into the wall of a segment from air, and out of it to ambient.
    #[inline]
    fn air_and_ambient(&self, air: &AirSide, tw: f64) -> (f64, f64) {
        let q_air = air.effectiveness * air.c_seg * (air.t_in - tw);
        let q_amb =
            self.settings.ambient_conductance / self.n as f64 * (tw - self.settings.t_ambient);
        (q_air, q_amb)
    }

    /// Steady wall temperature of one segment: `q_air(T_w) = q_ref(T_w) + q_amb(T_w)`, the
    /// balance being strictly decreasing in `T_w`, solved by [`falsi`] on a bracket between
    /// the coldest and the warmest temperature around. `flow` is [`Evaporator::flow`] of
    /// `mdot`.
    fn steady_wall(
        &self,
        air: &AirSide,
        p: f64,
        h: f64,
        mdot: f64,
        flow: &Flow,
    ) -> Result<(f64, Segment), String> {
        let s = saturation(p);
        let t_ref = if h < s.h_v { s.t } else { s.vapour(h).t };
        let t_amb = self.settings.t_ambient;
        let lo = t_ref.min(air.t_in).min(t_amb) - 0.01;
        let hi = t_ref.max(air.t_in).max(t_amb) + 0.01;
        let balance = |tw: f64| {
            let (q_air, q_amb) = self.air_and_ambient(air, tw);
            q_air - self.segment(p, h, tw, mdot, flow).q_ref - q_amb
        };
        let tw = falsi(balance, lo, hi, WALL_TOL, WALL_ITER).map_err(|e| {
            format!(
                "steady wall temperature at {:.4} bar, {:.2} kJ/kg: {e}",
                p / 1e5,
                h / 1e3
            )
        })?;
        Ok((tw, self.segment(p, h, tw, mdot, flow)))
    }

    /// March from the inlet at pressure `p_in`, writing the net heat flow into each wall
    /// (W) into `net`, and return the totals. Fails only when a steady wall temperature
    /// cannot be found.
    fn march(
        &self,
        inp: &Inputs,
        air: &AirSide,
        p_in: f64,
        mut walls: Walls,
        net: &mut [f64],
    ) -> Result<March, String> {
        let n = self.n;
        let high = self.settings.fidelity == Fidelity::High;
        // Low fidelity: linear pressure profile between the inlet and the outlet boundary.
        let dp_lin = (p_in - inp.p_out) / n as f64;
        let mut p = p_in;
        let mut h = inp.h_in;
        let mut m = March {
            p_in,
            margin: f64::INFINITY,
            ..March::default()
        };
        let mut v_sum = 0.0;
        let (p_min, p_max) = refrigerant::pressure_range();
        let flow = self.flow(inp.mdot_ref);
        for i in 0..n {
            // Outside the tables the march goes on at the nearest tabulated pressure, so
            // that trial states stay finite; the margin reports it.
            let p_margin = pressure_margin(p);
            let p_seg = p.clamp(p_min, p_max);
            let (tw, seg) = match &mut walls {
                Walls::Given(tw) => (tw[i], self.segment(p_seg, h, tw[i], inp.mdot_ref, &flow)),
                Walls::Steady(tw) => {
                    let (t, seg) = self.steady_wall(air, p_seg, h, inp.mdot_ref, &flow)?;
                    tw[i] = t;
                    (t, seg)
                }
            };
            m.note_margin(p_margin.min(seg.margin), p, h);
            let (q_air, q_amb) = self.air_and_ambient(air, tw);
            net[i] = q_air - seg.q_ref - q_amb;
            m.q_ref += seg.q_ref;
            m.q_air += q_air;
            m.q_ambient += q_amb;
            m.wall_mean += tw / n as f64;
            v_sum += seg.v_mid;
            h = seg.h_out;
            p -= if high { seg.dp } else { dp_lin };
        }
        m.note_margin(table_margin(p, h), p, h);
        m.p_end = p;
        m.h_out = h;
        if !high {
            let nom = &self.settings.nominal;
            m.rho_mean = n as f64 / v_sum;
            m.dp_model = pressure_drop::density_profile(
                self.settings.cf_ref_dp,
                nom.dp0,
                inp.mdot_ref,
                nom.mdot0,
                self.rho0,
                m.rho_mean,
            );
        }
        Ok(m)
    }

    /// Residual of the outlet condition: zero when the march ends at the outlet pressure.
    fn residual(&self, inp: &Inputs, m: &March) -> f64 {
        match self.settings.fidelity {
            Fidelity::High => m.p_end - inp.p_out,
            Fidelity::Low => m.p_in - inp.p_out - m.dp_model,
        }
    }

    /// Steady state for the inputs `inp`: the inlet pressure that meets the outlet
    /// boundary condition, by a secant iteration on `p_in` (kept between the outlet
    /// pressure and the top of the tables) around the segment-by-segment steady wall
    /// solve. Writes the wall temperatures into `tw`. Fails when the iteration does not
    /// meet the outlet condition or its state leaves the property tables.
    fn solve_steady(
        &self,
        inp: &Inputs,
        air: &AirSide,
        tw: &mut [f64],
        net: &mut [f64],
    ) -> Result<March, String> {
        let p_max = refrigerant::pressure_range().1;
        let mut run = |p_in: f64, net: &mut [f64]| -> Result<(f64, March), String> {
            let m = self.march(inp, air, p_in, Walls::Steady(&mut *tw), net)?;
            Ok((self.residual(inp, &m), m))
        };
        let scale = |x: f64| PRESSURE_TOL * (x - inp.p_out).abs().max(100.0);
        let mut x0 = (inp.p_out + 3e4).min(p_max);
        let (mut r0, mut m) = run(x0, net)?;
        let mut converged = r0.abs() <= scale(x0);
        let mut slope = 1.0;
        let mut x1 = (x0 - r0 / slope).clamp(inp.p_out, p_max);
        let mut iterations = 0;
        while !converged && iterations < PRESSURE_ITER {
            iterations += 1;
            let (r1, m1) = run(x1, net)?;
            m = m1;
            converged = r1.abs() <= scale(x1);
            if converged || x1 == x0 {
                r0 = r1;
                break;
            }
            let s = (r1 - r0) / (x1 - x0);
            if s.is_finite() && s > 0.05 {
                slope = s;
            }
            let x2 = (x1 - r1 / slope).clamp(inp.p_out, p_max);
            x0 = x1;
            r0 = r1;
            x1 = x2;
        }
        if !converged {
            return Err(format!(
                "no steady inlet pressure between the outlet's {:.4} bar and {:.2} bar meets \
                 the outlet condition: residual {:.4e} Pa at {:.4} bar after {iterations} \
                 iterations",
                inp.p_out / 1e5,
                p_max / 1e5,
                r0,
                m.p_in / 1e5
            ));
        }
        if m.margin < 0.0 {
            let (p, h) = m.worst;
            return Err(format!("steady state: {}", describe_out_of_range(p, h)));
        }
        Ok(m)
    }

    /// Net heat flow into each wall (W), the outlet-condition residual (Pa) and the march
    /// totals at time-`t` inputs, for wall temperatures `tw` and inlet pressure `p_in`.
    pub fn evaluate(
        &self,
        t: f64,
        tw: &[f64],
        p_in: f64,
        net: &mut [f64],
    ) -> (Inputs, AirSide, March, f64) {
        let inp = self.inputs_at(t);
        let air = self.air_side(&inp);
        let m = match self.march(&inp, &air, p_in, Walls::Given(tw), net) {
            Ok(m) => m,
            // Given walls: nothing is solved, so the march cannot fail.
            Err(_) => unreachable!("a march on given walls solves nothing"),
        };
        let r = self.residual(&inp, &m);
        (inp, air, m, r)
    }

    /// Steady state at the inputs of time `t`: wall temperatures, then the inlet pressure.
    pub fn steady_state(&self, t: f64) -> Result<Vec<f64>, String> {
        let inp = self.inputs_at(t);
        let air = self.air_side(&inp);
        let mut tw = vec![inp.t_air_in; self.n];
        let mut net = vec![0.0; self.n];
        let m = self.solve_steady(&inp, &air, &mut tw, &mut net)?;
        tw.push(m.p_in);
        Ok(tw)
    }

    /// Heat capacity of one segment's wall (J/K).
    pub fn segment_capacity(&self) -> f64 {
        self.settings.wall_capacity / self.n as f64
    }

    /// Outlet temperature (K) and superheat (K, 0 while two-phase) at `(p, h)`.
    pub fn outlet_state(p: f64, h: f64) -> (f64, f64) {
        let s = saturation(p);
        if h < s.h_v {
            (s.t, 0.0)
        } else {
            let t = s.vapour(h).t;
            (t, t - s.t)
        }
    }
}

/// Root of a strictly decreasing `f` on `[lo, hi]` by the Illinois variant of regula falsi:
/// the `x` where `|f(x)| < tol`, or where the bracket has shrunk below 10⁻¹¹. Fails when
/// `[lo, hi]` does not bracket a root (or `f` is not finite there) or the iterations run out.
pub fn falsi(
    f: impl Fn(f64) -> f64,
    mut lo: f64,
    mut hi: f64,
    tol: f64,
    max_iter: usize,
) -> Result<f64, String> {
    let (mut f_lo, mut f_hi) = (f(lo), f(hi));
    if !(f_lo >= 0.0 && f_hi <= 0.0) {
        return Err(format!(
            "no root in [{lo:.6}, {hi:.6}]: the balance is {f_lo:.6e} and {f_hi:.6e} at its ends"
        ));
    }
    let mut side = 0i8;
    let mut last = (f64::NAN, f64::NAN);
    for _ in 0..max_iter {
        let mut x = (lo * f_hi - hi * f_lo) / (f_hi - f_lo);
        if !(x > lo && x < hi) {
            x = 0.5 * (lo + hi);
        }
        let fx = f(x);
        if !fx.is_finite() {
            return Err(format!("the balance is not finite at {x:.6}"));
        }
        last = (x, fx);
        if fx.abs() < tol || hi - lo < 1e-11 {
            return Ok(x);
        }
        if fx > 0.0 {
            lo = x;
            f_lo = fx;
            if side == 1 {
                f_hi *= 0.5;
            }
            side = 1;
        } else {
            hi = x;
            f_hi = fx;
            if side == -1 {
                f_lo *= 0.5;
            }
            side = -1;
        }
    }
    Err(format!(
        "not converged after {max_iter} iterations: balance {:.3e} at {:.6}, bracket width \
         {:.3e}",
        last.1,
        last.0,
        hi - lo
    ))
}
