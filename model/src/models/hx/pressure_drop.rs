//! Refrigerant- and air-side pressure drop.
//!
//! Sources:
//! - L. Friedel, "Improved friction pressure drop correlations for horizontal and vertical
//!   two-phase pipe flow", European Two-Phase Flow Group Meeting, Ispra, 1979, paper E2
//!   (two-phase frictional multiplier).
//! - S. W. Churchill, "Friction-factor equation spans all fluid-flow regimes", Chem. Eng.
//!   75 (1977) 91–92 (single-phase vapour; smooth channel).
//! - Momentum (acceleration) term of the homogeneous model: J. G. Collier, J. R. Thome,
//!   *Convective Boiling and Condensation*, 3rd ed., Oxford 1994, §2.
//! - Air side: W. M. Kays, A. L. London, *Compact Heat Exchangers*, 3rd ed., McGraw-Hill
//!   1984 — core friction `Δp = f (A/A_c) G_c²/(2ρ)`. For the louvered fin the Fanning
//!   factor is taken proportional to Chang & Wang's Colburn factor, `f = 4 j`, a ratio
//!   within the range of Kays & London's louvered-fin surfaces (f/j ≈ 3…6); this is an
//!   assumption of the model, scaled by `CF_Airdp`.

use super::refrigerant::Saturation;

const G_ACC: f64 = 9.81;

/// Quantities of the friction correlations that depend on the mass flux `g` and the
/// diameter `d` alone, computed once per march.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flow {
    /// Mass flux `G` (kg/(m² s)).
    pub g: f64,
    /// `G D`, `1/(G D)`, `(G D)^−0.25`.
    gd: f64,
    inv_gd: f64,
    inv_gd_025: f64,
    /// `2 G²/D`.
    two_g2_d: f64,
    /// `−0.045 ln(G²/(g D)) − 0.035 ln(G² D)`: the flow part of `−ln(Fr^0.045 We^0.035)`.
    ln_fr_we: f64,
}

impl Flow {
    pub fn new(g: f64, d: f64) -> Self {
        let gd = g * d;
        let g2 = g * g;
        Self {
            g,
            gd,
            inv_gd: 1.0 / gd,
            inv_gd_025: 1.0 / gd.sqrt().sqrt(),
            two_g2_d: 2.0 * g2 / d,
            ln_fr_we: -0.045 * (g2 / (G_ACC * d)).ln() - 0.035 * (g2 * d).ln(),
        }
    }

    /// Friedel's Fanning factor (`16/Re` below Re = 1055, `0.079 Re^−0.25` above) at
    /// `Re = G D/μ`, given `μ^0.25`.
    #[inline]
    fn fanning_friedel(&self, mu: f64, mu_025: f64) -> f64 {
        // Re < 1055 ⇔ G D < 1055 μ.
        if self.gd < 1055.0 * mu {
            16.0 * mu * self.inv_gd
        } else {
            0.079 * mu_025 * self.inv_gd_025
        }
    }
}

/// Friedel's two-phase frictional pressure drop (Pa) over length `len` at mean quality `x`,
/// for the flow `flow`, given `1/ρ_l` and `1/ρ_v` of the saturation state:
/// `Δp = Φ_lo² · 2 f_lo G² L / (D ρ_l)`, with the multiplier
/// `Φ_lo² = E + 3.24 F H / (Fr^0.045 We^0.035)`,
/// `E = (1−x)² + x² ρ_l f_vo / (ρ_v f_lo)`, `F = x^0.78 (1−x)^0.224`,
/// `H = (ρ_l/ρ_v)^0.91 (μ_v/μ_l)^0.19 (1 − μ_v/μ_l)^0.7`,
/// `Fr = G²/(g D ρ_h²)`, `We = G² D/(σ ρ_h)`, `ρ_h` the homogeneous density, and Friedel's
/// own Fanning factors (`16/Re` below Re = 1055, `0.079 Re^−0.25` above). `H` and the
/// viscosity powers come precomputed with the saturation state.
///
/// The factors that depend on the flow alone are taken out of the segment: with
/// `v_h = 1/ρ_h`,
/// `Fr^0.045 We^0.035 = (G²/(g D))^0.045 (G² D)^0.035 v_h^0.125 σ^−0.035`, whose first
/// two factors come with `flow`; the Fanning factors and `2 G²/D` likewise, so that the
/// only divisions left are by `f_lo` and in the caller's `1/ρ_l`, `1/ρ_v`.
pub fn friedel_at(s: &Saturation, inv_rho: (f64, f64), x: f64, flow: &Flow, len: f64) -> f64 {
    let (inv_rho_l, inv_rho_v) = inv_rho;
    let f_lo = flow.fanning_friedel(s.mu_l, s.groups.mu_l_025);
    let f_vo = flow.fanning_friedel(s.mu_v, s.groups.mu_v_025);
    // `ρ_l f_vo / (ρ_v f_lo)` does not depend on x: it is computed before x is known.
    let e1 = s.rho_l * f_vo * inv_rho_v / f_lo;
    let x = x.clamp(0.0, 1.0);
    let e = (1.0 - x).powi(2) + x * x * e1;
    let phi = if x <= 0.0 || x >= 1.0 {
        e
    } else {
        let v_h = x * inv_rho_v + (1.0 - x) * inv_rho_l;
        let ln_vs = 0.035 * s.sigma.ln() - 0.125 * v_h.ln();
        let ratio = (0.78 * x.ln() + 0.224 * (1.0 - x).ln() + flow.ln_fr_we + ln_vs).exp();
        e + 3.24 * s.groups.friedel_h * ratio
    };
    phi * f_lo * flow.two_g2_d * len * inv_rho_l
}

/// Churchill (1977) Fanning friction factor of a smooth channel, all regimes.
pub fn fanning_churchill(re: f64) -> f64 {
    let re = re.max(1e-6);
    // ln(1/(7/Re)^0.9) = 0.9 ln(Re/7).
    let a = (2.457 * 0.9 * (re / 7.0).ln()).powi(16);
    let b = (37_530.0 / re).powi(16);
    // (A + B)^−1.5 through a square root, cheaper than `powf`.
    let ab = a + b;
    2.0 * ((8.0 / re).powi(12) + 1.0 / (ab * ab.sqrt())).powf(1.0 / 12.0)
}

/// Single-phase frictional pressure drop (Pa): `Δp = 2 f G² L / (D ρ)`.
pub fn single_phase(rho: f64, mu: f64, g: f64, d: f64, len: f64) -> f64 {
    let f = fanning_churchill(g * d / mu);
    2.0 * f * g * g * len / (d * rho)
}

/// Momentum pressure change (Pa) between specific volumes `v_in` and `v_out` (homogeneous
/// flow): `Δp = G² (v_out − v_in)`; positive when the flow accelerates.
pub fn acceleration(g: f64, v_in: f64, v_out: f64) -> f64 {
    g * g * (v_out - v_in)
}

/// The low-fidelity density-profile model: `Δp = CF·Δp0·(ṁ/ṁ0)²·(ρ0/ρ̄)`.
pub fn density_profile(cf: f64, dp0: f64, mdot: f64, mdot0: f64, rho0: f64, rho_mean: f64) -> f64 {
    cf * dp0 * (mdot / mdot0).powi(2) * rho0 / rho_mean
}

/// Air-side core pressure drop (Pa): `Δp = f (A/A_c) G_c²/(2ρ)`, `f = 4 j`.
pub fn air_core(j: f64, area_ratio: f64, g_c: f64, rho: f64) -> f64 {
    4.0 * j * area_ratio * g_c * g_c / (2.0 * rho)
}

#[cfg(test)]
mod tests {
    use super::super::refrigerant::saturation;
    use super::*;

    #[test]
    fn churchill_matches_laminar_and_blasius_limits() {
        assert!((fanning_churchill(500.0) / (16.0 / 500.0) - 1.0).abs() < 0.01);
        let bl = 0.079 * 2e4f64.powf(-0.25);
        assert!((fanning_churchill(2e4) / bl - 1.0).abs() < 0.05);
    }

    /// Friedel's Fanning factor, as the paper writes it.
    fn fanning_friedel(re: f64) -> f64 {
        if re < 1055.0 {
            16.0 / re.max(1e-9)
        } else {
            0.079 * re.powf(-0.25)
        }
    }

    /// Friedel's multiplier `Φ_lo²`, term by term as the paper writes it (see
    /// [`friedel_at`]): the reference the model's form is held to, to rounding and the
    /// tabulated viscosity powers (10⁻¹⁰).
    fn friedel_multiplier(s: &Saturation, x: f64, g: f64, d: f64) -> f64 {
        let x = x.clamp(0.0, 1.0);
        let f_lo = fanning_friedel(g * d / s.mu_l);
        let f_vo = fanning_friedel(g * d / s.mu_v);
        let e = (1.0 - x).powi(2) + x * x * s.rho_l * f_vo / (s.rho_v * f_lo);
        if x <= 0.0 || x >= 1.0 {
            return e;
        }
        let rho_h = s.homogeneous_density(x);
        let fr = g * g / (G_ACC * d * rho_h * rho_h);
        let we = g * g * d / (s.sigma * rho_h);
        let f = x.powf(0.78) * (1.0 - x).powf(0.224);
        e + 3.24 * f * s.groups.friedel_h / (fr.powf(0.045) * we.powf(0.035))
    }

    /// `Δp = Φ_lo² · 2 f_lo G² L / (D ρ_l)`, as the paper writes it.
    fn friedel(s: &Saturation, x: f64, g: f64, d: f64, len: f64) -> f64 {
        let f_lo = fanning_friedel(g * d / s.mu_l);
        friedel_multiplier(s, x, g, d) * 2.0 * f_lo * g * g * len / (d * s.rho_l)
    }

    #[test]
    fn the_models_form_of_friedel_equals_the_papers() {
        for p in [1.5e5, 3e5, 6e5] {
            let s = saturation(p);
            let inv_rho = (1.0 / s.rho_l, 1.0 / s.rho_v);
            for (g, d) in [(20.0, 1e-3), (170.0, 1e-3), (600.0, 1.1e-3)] {
                let flow = Flow::new(g, d);
                for x in [0.0, 0.05, 0.3, 0.6, 0.95, 1.0] {
                    let paper = friedel(&s, x, g, d, 0.2);
                    let model = friedel_at(&s, inv_rho, x, &flow, 0.2);
                    assert!(
                        (model / paper - 1.0).abs() < 1e-10,
                        "p {p}, G {g}, x {x}: {model} vs {paper}"
                    );
                }
            }
        }
    }

    #[test]
    fn friedel_multiplier_limits() {
        let s = saturation(3e5);
        let (g, d) = (170.0, 1e-3);
        // x = 0: liquid only, Φ² = 1.
        assert!((friedel_multiplier(&s, 0.0, g, d) - 1.0).abs() < 1e-12);
        // x = 1: vapour only, Φ² = ρ_l f_vo / (ρ_v f_lo).
        let f_lo = fanning_friedel(g * d / s.mu_l);
        let f_vo = fanning_friedel(g * d / s.mu_v);
        let e1 = s.rho_l * f_vo / (s.rho_v * f_lo);
        assert!((friedel_multiplier(&s, 1.0, g, d) / e1 - 1.0).abs() < 1e-9);
        // Gradient in the middle: tens of kPa per metre in a 1 mm channel.
        let dpdz = friedel(&s, 0.6, g, d, 1.0);
        assert!(dpdz > 5e3 && dpdz < 1e5, "{dpdz}");
    }
}
