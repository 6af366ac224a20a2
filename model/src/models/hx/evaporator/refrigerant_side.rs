//! The refrigerant side of one segment of the [evaporator](super): the heat it takes from
//! the wall and its pressure drop, for a two-phase inlet (Chen boiling, blended towards the
//! vapour coefficient past dry-out inception, with dry-out inside the segment) or a
//! superheated one (Gnielinski, ε-NTU).

use super::super::correlations::{chen, nusselt_gnielinski, nusselt_gnielinski_with};
use super::super::pressure_drop::{self, Flow};
use super::super::refrigerant::Saturation;
use super::{Evaporator, X_DRYOUT};

/// The inlet of one segment's refrigerant side, shared by the physical steps of
/// [`Evaporator::segment`]: each returns the segment's `(q_ref, h_out, dp)`.
pub(super) struct Inlet<'a> {
    pub(super) evap: &'a Evaporator,
    /// Saturation state at the inlet pressure.
    pub(super) s: &'a Saturation,
    pub(super) flow: &'a Flow,
    pub(super) h: f64,
    pub(super) tw: f64,
    pub(super) mdot: f64,
    /// High fidelity: the pressure drop is marched (else it is 0).
    pub(super) high: bool,
}

impl Inlet<'_> {
    /// Two-phase inlet: boil with the Chen coefficient (blended towards the vapour one past
    /// dry-out inception), up to the dew point if the wall gives that much.
    #[inline]
    pub(super) fn boiling(&self) -> (f64, f64, f64) {
        let s = self.s;
        let x_in = s.quality(self.h);
        let dt = self.tw - s.t;
        let inv_rho = (1.0 / s.rho_l, 1.0 / s.rho_v);
        let alpha = self.boiling_coefficient(x_in, dt);
        let q_full = alpha * self.evap.seg_area_ref * dt;
        let to_dew = self.mdot * (s.h_v - self.h);
        if q_full <= to_dew {
            self.boiling_only(x_in, inv_rho, q_full)
        } else {
            self.dry_out(x_in, inv_rho, q_full, to_dew)
        }
    }

    /// Heat transfer coefficient of flow boiling at quality `x_in`, wall superheat `dt`:
    /// Chen's, falling linearly in quality to the vapour value at x = 1 in the dry-out region.
    #[inline]
    fn boiling_coefficient(&self, x_in: f64, dt: f64) -> f64 {
        let st = &self.evap.settings;
        let c = chen(self.s, x_in, self.flow.g, self.evap.d, dt);
        let mut alpha = st.cf_ref_ht * (c.convective + c.nucleate);
        if x_in > X_DRYOUT {
            // Dry-out region: linear in quality down to the vapour value at x = 1.
            let w = (1.0 - x_in) / (1.0 - X_DRYOUT);
            alpha = w * alpha + (1.0 - w) * self.vapour_coefficient();
        }
        alpha
    }

    /// Saturated-vapour coefficient (Gnielinski), needed in the dry-out region only.
    #[inline]
    fn vapour_coefficient(&self) -> f64 {
        let s = self.s;
        let (g, d) = (self.flow.g, self.evap.d);
        let pr_v = s.cp_v * s.mu_v / s.k_v;
        let nu = nusselt_gnielinski_with(g * d / s.mu_v, pr_v, s.groups.pr_v_23);
        self.evap.settings.cf_ref_ht * nu * s.k_v / d
    }

    /// The whole segment boils below the dew point: it takes the full heat flow `q_full`.
    #[inline]
    fn boiling_only(&self, x_in: f64, inv_rho: (f64, f64), q_full: f64) -> (f64, f64, f64) {
        let s = self.s;
        let st = &self.evap.settings;
        let g = self.flow.g;
        // The reciprocals do not depend on the heat flow, so the divisions stay off
        // the path from the wall balance to the pressure drop.
        let inv_mdot = 1.0 / self.mdot;
        let h_out = self.h + q_full * inv_mdot;
        let dp = if self.high {
            // The quality of `h_out`, as `x_in + Q/(ṁ h_lv)`.
            let x_out = x_in + q_full * (inv_mdot / s.h_lv());
            let x_m = 0.5 * (x_in + x_out).max(0.0);
            st.cf_ref_dp * pressure_drop::friedel_at(s, inv_rho, x_m, self.flow, self.evap.seg_len)
                + pressure_drop::acceleration(
                    g,
                    homogeneous_volume(inv_rho, x_in),
                    homogeneous_volume(inv_rho, x_out),
                )
        } else {
            0.0
        };
        (q_full, h_out, dp)
    }

    /// Dry-out inside the segment: boiling up to the dew point (`to_dew` of the full heat flow
    /// `q_full`) on the fraction `f` of the area, superheating the vapour on the rest.
    #[inline]
    fn dry_out(&self, x_in: f64, inv_rho: (f64, f64), q_full: f64, to_dew: f64) -> (f64, f64, f64) {
        let s = self.s;
        let st = &self.evap.settings;
        let (g, d, a, len) = (
            self.flow.g,
            self.evap.d,
            self.evap.seg_area_ref,
            self.evap.seg_len,
        );
        let mdot = self.mdot;
        let f = to_dew / q_full;
        let c_ref = mdot * s.cp_v;
        let q_v = c_ref
            * (self.tw - s.t)
            * (1.0 - (-self.vapour_coefficient() * a * (1.0 - f) / c_ref).exp());
        let h_out = s.h_v + q_v / mdot;
        let dp = if self.high {
            let v_in = homogeneous_volume(inv_rho, x_in);
            let v_out = 1.0 / s.vapour(h_out).rho;
            st.cf_ref_dp
                * (pressure_drop::friedel_at(
                    s,
                    inv_rho,
                    0.5 * (x_in.max(0.0) + 1.0),
                    self.flow,
                    f * len,
                ) + pressure_drop::single_phase(s.rho_v, s.mu_v, g, d, (1.0 - f) * len))
                + pressure_drop::acceleration(g, v_in, v_out)
        } else {
            0.0
        };
        (to_dew + q_v, h_out, dp)
    }

    /// Superheated inlet: single-phase vapour (Gnielinski) against the wall, ε-NTU.
    #[inline]
    pub(super) fn superheated(&self) -> (f64, f64, f64) {
        let (s, st) = (self.s, &self.evap.settings);
        let (g, d, a) = (self.flow.g, self.evap.d, self.evap.seg_area_ref);
        let mdot = self.mdot;
        let v = s.vapour(self.h);
        let alpha = st.cf_ref_ht * nusselt_gnielinski(g * d / v.mu, v.prandtl()) * v.k / d;
        let c_ref = mdot * v.cp;
        let q = c_ref * (self.tw - v.t) * (1.0 - (-alpha * a / c_ref).exp());
        let h_out = self.h + q / mdot;
        let dp = if self.high {
            let v_out = 1.0 / s.vapour(h_out).rho;
            st.cf_ref_dp * pressure_drop::single_phase(v.rho, v.mu, g, d, self.evap.seg_len)
                + pressure_drop::acceleration(g, 1.0 / v.rho, v_out)
        } else {
            0.0
        };
        (q, h_out, dp)
    }
}

/// Homogeneous specific volume at quality `x`, clamped to [0, 1], from the reciprocal
/// densities `inv_rho` of liquid and vapour (high-fidelity momentum term).
#[inline]
fn homogeneous_volume(inv_rho: (f64, f64), x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * inv_rho.1 + (1.0 - x) * inv_rho.0
}
