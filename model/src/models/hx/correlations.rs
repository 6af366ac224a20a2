//! Heat-transfer correlations: air side (louvered fins) and refrigerant side (flow
//! boiling, single-phase vapour), plus dry-air properties.
//!
//! Sources:
//! - Y.-J. Chang, C.-C. Wang, "A generalized heat transfer correlation for louver fin
//!   geometry", Int. J. Heat Mass Transfer 40 (1997) 533–544 (Colburn j factor).
//! - J. C. Chen, "Correlation for boiling heat transfer to saturated fluids in convective
//!   flow", Ind. Eng. Chem. Process Des. Dev. 5 (1966) 322–329 (flow boiling), with the
//!   nucleate term of H. K. Forster, N. Zuber, "Dynamics of vapor bubbles and boiling heat
//!   transfer", AIChE J. 1 (1955) 531–535.
//! - F. W. Dittus, L. M. K. Boelter, Univ. Calif. Publ. Eng. 2 (1930) 443–461 (the
//!   liquid-only coefficient inside Chen's correlation).
//! - V. Gnielinski, "New equations for heat and mass transfer in turbulent pipe and channel
//!   flow", Int. Chem. Eng. 16 (1976) 359–368 (single-phase vapour).
//! - S. W. Churchill, R. Usagi, "A general expression for the correlation of rates of
//!   transfer and other phenomena", AIChE J. 18 (1972) 1121–1128 (the blend of laminar and
//!   turbulent Nusselt numbers).
//! - Fin efficiency of a straight fin of uniform thickness with an adiabatic tip at
//!   mid-height: F. P. Incropera et al., *Fundamentals of Heat and Mass Transfer*, §3.6.

use super::refrigerant::Saturation;

/// Fully developed laminar Nusselt number used as the floor of the single-phase blends
/// (uniform heat flux, circular duct).
pub const NU_LAMINAR: f64 = 4.36;

/// Dry air at atmospheric pressure (SI units).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Air {
    pub rho: f64,
    pub cp: f64,
    pub mu: f64,
    pub k: f64,
}

impl Air {
    /// Properties at temperature `t` (K), 101 325 Pa: ideal gas, Sutherland's viscosity,
    /// a power law for conductivity, constant heat capacity (fits to standard tables
    /// within 1 % over −20…60 °C).
    pub fn at(t: f64) -> Self {
        let t = t.max(150.0);
        Self {
            rho: 101_325.0 / (287.05 * t),
            cp: 1006.0,
            mu: 1.716e-5 * (t / 273.15).powf(1.5) * (273.15 + 110.4) / (t + 110.4),
            k: 0.0241 * (t / 273.15).powf(0.81),
        }
    }

    pub fn prandtl(&self) -> f64 {
        self.cp * self.mu / self.k
    }
}

/// Chang & Wang (1997) Colburn factor of a louvered fin,
/// `j = Re_Lp^−0.49 (θ/90)^0.27 (Fp/Lp)^−0.14 (Fl/Lp)^−0.29 (Td/Lp)^−0.23 (Ll/Lp)^0.68
/// (Tp/Lp)^−0.28 (δf/Lp)^−0.05`, with `Re_Lp` on the louver pitch and the velocity in the
/// minimum free-flow area. The geometry group is constant; see [`LouverGroup`].
pub fn colburn_j(re_lp: f64, group: f64) -> f64 {
    re_lp.max(1.0).powf(-0.49) * group
}

/// The geometry part of Chang & Wang's correlation.
#[allow(clippy::too_many_arguments)]
pub fn louver_group(
    louver_angle_deg: f64,
    fin_pitch: f64,
    fin_length: f64,
    tube_depth: f64,
    louver_length: f64,
    tube_pitch: f64,
    fin_thickness: f64,
    louver_pitch: f64,
) -> f64 {
    let lp = louver_pitch;
    (louver_angle_deg / 90.0).powf(0.27)
        * (fin_pitch / lp).powf(-0.14)
        * (fin_length / lp).powf(-0.29)
        * (tube_depth / lp).powf(-0.23)
        * (louver_length / lp).powf(0.68)
        * (tube_pitch / lp).powf(-0.28)
        * (fin_thickness / lp).powf(-0.05)
}

/// Efficiency of a straight fin of half-height `half_height` (tip adiabatic by symmetry).
pub fn fin_efficiency(h: f64, conductivity: f64, thickness: f64, half_height: f64) -> f64 {
    let ml = (2.0 * h / (conductivity * thickness)).sqrt() * half_height;
    if ml < 1e-9 {
        1.0
    } else {
        ml.tanh() / ml
    }
}

/// Churchill–Usagi blend of the laminar floor and a turbulent Nusselt number.
fn blend(nu_turbulent: f64) -> f64 {
    ln_blend(nu_turbulent.max(0.0).powi(10)).exp()
}

/// The logarithm of [`blend`], given the turbulent Nusselt number to the tenth power.
fn ln_blend(nu_turbulent_10: f64) -> f64 {
    0.1 * (NU_LAMINAR.powi(10) + nu_turbulent_10).ln()
}

/// Dittus–Boelter (heating) with the laminar floor.
pub fn nusselt_dittus_boelter(re: f64, pr: f64) -> f64 {
    if re <= 0.0 {
        return NU_LAMINAR;
    }
    dittus_boelter_with(re.ln(), pr.powf(0.4))
}

/// [`nusselt_dittus_boelter`] given `ln Re` (of a positive Reynolds number) and `Pr^0.4`.
fn dittus_boelter_with(ln_re: f64, pr_04: f64) -> f64 {
    ln_dittus_boelter_with(ln_re, pr_04).exp()
}

/// The logarithm of [`dittus_boelter_with`].
fn ln_dittus_boelter_with(ln_re: f64, pr_04: f64) -> f64 {
    let nu_turbulent = 0.023 * (0.8 * ln_re).exp() * pr_04;
    ln_blend(nu_turbulent.powi(10))
}

/// Gnielinski with the Filonenko friction factor, blended with the laminar floor; the
/// turbulent expression vanishes at Re = 1000, so the blend is smooth in Re.
pub fn nusselt_gnielinski(re: f64, pr: f64) -> f64 {
    nusselt_gnielinski_with(re, pr, pr.powf(2.0 / 3.0))
}

/// [`nusselt_gnielinski`] given `Pr^(2/3)` as well.
pub fn nusselt_gnielinski_with(re: f64, pr: f64, pr_23: f64) -> f64 {
    if re <= 1000.0 {
        return NU_LAMINAR;
    }
    let f = (0.79 * re.ln() - 1.64).powi(-2);
    let nu = (f / 8.0) * (re - 1000.0) * pr / (1.0 + 12.7 * (f / 8.0).sqrt() * (pr_23 - 1.0));
    blend(nu)
}

/// Terms of Chen's flow-boiling coefficient at quality `x`, mass flux `g` (kg/(m² s)),
/// hydraulic diameter `d` and wall superheat `dt_sat = T_w − T_sat` (K).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ChenCoefficient {
    /// `F·h_l`, forced convection (W/(m² K)).
    pub convective: f64,
    /// `S·h_FZ`, nucleate boiling (W/(m² K)); 0 when the wall is not superheated.
    pub nucleate: f64,
}

/// Chen (1966): `h = F h_l + S h_FZ` with
/// - `h_l = (k_l/D)·0.023 Re_l^0.8 Pr_l^0.4`, `Re_l = G(1−x)D/μ_l` (laminar floor);
/// - `1/X_tt = (x/(1−x))^0.9 (ρ_l/ρ_v)^0.5 (μ_v/μ_l)^0.1`,
///   `F = max(1, 2.35 (1/X_tt + 0.213)^0.736)`;
/// - `S = 1/(1 + 2.53·10⁻⁶ (Re_l F^1.25)^1.17)`;
/// - `h_FZ = 0.00122 k_l^0.79 c_pl^0.45 ρ_l^0.49 / (σ^0.5 μ_l^0.29 h_lv^0.24 ρ_v^0.24)
///   ΔT_sat^0.24 Δp_sat^0.75` (Forster–Zuber), with `Δp_sat = ΔT_sat / (dT_sat/dp)`
///   (Clausius–Clapeyron, linearised about the local saturation state).
///
/// The property groups come precomputed with the saturation state
/// ([`Saturation::groups`](super::refrigerant::Groups)).
pub fn chen(s: &Saturation, x: f64, g: f64, d: f64, dt_sat: f64) -> ChenCoefficient {
    // Powers are taken as exponentials of logarithms (each `powf` costs about as much as a
    // logarithm and an exponential together, and the logarithms are shared), or as a
    // product where the exponent allows: `Nu_t^10 = (0.023 Pr_l^0.4)^10 Re_l^8`.
    let x = x.clamp(1e-4, 0.9999);
    // Re_l = (G D/μ_l)(1 − x): the factor independent of x first, off the path from x.
    let re_l = g * d / s.mu_l * (1.0 - x);
    let nu_t10 = (0.023 * s.groups.pr_l_04).powi(10) * re_l.powi(8);
    let ln_nu_l = ln_blend(nu_t10);
    let inv_xtt = (0.9 * (x / (1.0 - x)).ln()).exp() * s.groups.martinelli;
    // F = max(1, 2.35 (1/X_tt + 0.213)^0.736), through its logarithm.
    let ln_f = (2.35f64.ln() + 0.736 * (inv_xtt + 0.213).ln()).max(0.0);
    // F h_l, h_l = Nu_l k_l / D.
    let convective = (ln_f + ln_nu_l).exp() * (s.k_l / d);
    let nucleate = if dt_sat > 0.0 {
        // (Re_l F^1.25)^1.17.
        let re_tp_117 = (1.17 * (re_l.ln() + 1.25 * ln_f)).exp();
        let supp = 1.0 / (1.0 + 2.53e-6 * re_tp_117);
        // ΔT_sat^0.24 Δp_sat^0.75 with Δp_sat = ΔT_sat / (dT_sat/dp).
        let driving = (0.99 * dt_sat.ln() - 0.75 * s.dt_dp.ln()).exp();
        supp * s.groups.forster_zuber * driving
    } else {
        0.0
    };
    ChenCoefficient {
        convective,
        nucleate,
    }
}

#[cfg(test)]
mod tests {
    use super::super::refrigerant::saturation;
    use super::*;

    #[test]
    fn gnielinski_is_continuous_and_matches_dittus_boelter_when_turbulent() {
        let a = nusselt_gnielinski(999.999, 0.8);
        let b = nusselt_gnielinski(1000.001, 0.8);
        assert!((a - b).abs() < 1e-6);
        let g = nusselt_gnielinski(3e4, 0.8);
        let db = nusselt_dittus_boelter(3e4, 0.8);
        assert!((g / db - 1.0).abs() < 0.2, "{g} vs {db}");
    }

    #[test]
    fn chen_coefficient_is_in_the_microchannel_range() {
        // R134a at 3 bar, G = 170 kg/(m² s), D = 1 mm, x = 0.5, 2 K wall superheat:
        // a few kW/(m² K), as measured in multiport tubes.
        let s = saturation(3e5);
        let c = chen(&s, 0.5, 170.0, 1e-3, 2.0);
        let h = c.convective + c.nucleate;
        assert!(h > 1500.0 && h < 15000.0, "{c:?}");
        assert!(c.nucleate > 0.0);
        assert_eq!(chen(&s, 0.5, 170.0, 1e-3, -1.0).nucleate, 0.0);
    }

    #[test]
    fn louvered_fin_air_side_coefficient_is_plausible() {
        // 1.7 m/s face velocity, bench geometry: Re_Lp ≈ 150–250, h ≈ 60–150 W/(m² K).
        let air = Air::at(298.15);
        let vc = 2.3;
        let re = air.rho * vc * 0.0011 / air.mu;
        let group = louver_group(27.0, 0.0013, 0.008, 0.04, 0.0068, 0.010, 0.0001, 0.0011);
        let j = colburn_j(re, group);
        let h = j * air.rho * vc * air.cp / air.prandtl().powf(2.0 / 3.0);
        assert!(h > 60.0 && h < 150.0, "Re {re}, j {j}, h {h}");
    }
}
