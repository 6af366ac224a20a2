//! Boundary conditions of the test bench: five ramps, one after another.
//!
//! Each input holds its start value until its ramp begins, moves to its end value along a
//! quintic "smootherstep" `s(τ) = 6τ⁵ − 15τ⁴ + 10τ³` (C², so the integrator sees no kink),
//! and holds the end value afterwards. The schedule (s):
//!
//! | input | ramp |
//! |---|---|
//! | refrigerant mass flow | 60 → 90 |
//! | refrigerant inlet enthalpy | 95 → 125 |
//! | refrigerant outlet pressure | 130 → 160 |
//! | air inlet temperature | 165 → 195 |
//! | air mass flow | 200 → 230 |
//!
//! All inputs are settled by 230 s; the run lasts 300 s.

/// Start and end of each ramp (s), in the order of [`Inputs`]' fields.
pub const SCHEDULE: [(f64, f64); 5] = [
    (60.0, 90.0),
    (95.0, 125.0),
    (130.0, 160.0),
    (165.0, 195.0),
    (200.0, 230.0),
];

/// Time (s) before which every input is at its start value.
pub const FIRST_RAMP: f64 = 60.0;
/// Time (s) after which every input is at its end value.
pub const LAST_RAMP_END: f64 = 230.0;

/// The inputs at one instant (SI units: kg/s, J/kg, Pa, K).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Inputs {
    pub mdot_ref: f64,
    pub h_in: f64,
    pub p_out: f64,
    pub t_air_in: f64,
    pub mdot_air: f64,
}

/// Start and end values of the five inputs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ramps {
    pub start: Inputs,
    pub end: Inputs,
}

fn smootherstep(t: f64, (a, b): (f64, f64)) -> f64 {
    let tau = ((t - a) / (b - a)).clamp(0.0, 1.0);
    tau * tau * tau * (tau * (6.0 * tau - 15.0) + 10.0)
}

impl Ramps {
    /// Constant inputs.
    pub fn constant(inputs: Inputs) -> Self {
        Self {
            start: inputs,
            end: inputs,
        }
    }

    pub fn at(&self, t: f64) -> Inputs {
        let mix = |a: f64, b: f64, k: usize| a + (b - a) * smootherstep(t, SCHEDULE[k]);
        let (s, e) = (&self.start, &self.end);
        Inputs {
            mdot_ref: mix(s.mdot_ref, e.mdot_ref, 0),
            h_in: mix(s.h_in, e.h_in, 1),
            p_out: mix(s.p_out, e.p_out, 2),
            t_air_in: mix(s.t_air_in, e.t_air_in, 3),
            mdot_air: mix(s.mdot_air, e.mdot_air, 4),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_run_in_turn_and_settle() {
        let start = Inputs {
            mdot_ref: 1.0,
            h_in: 2.0,
            p_out: 3.0,
            t_air_in: 4.0,
            mdot_air: 5.0,
        };
        let end = Inputs {
            mdot_ref: 10.0,
            h_in: 20.0,
            p_out: 30.0,
            t_air_in: 40.0,
            mdot_air: 50.0,
        };
        let r = Ramps { start, end };
        assert_eq!(r.at(0.0), start);
        assert_eq!(r.at(FIRST_RAMP), start);
        assert_eq!(r.at(LAST_RAMP_END), end);
        assert_eq!(r.at(300.0), end);
        let mid = r.at(75.0);
        assert!((mid.mdot_ref - 5.5).abs() < 1e-12);
        assert_eq!(mid.h_in, 2.0);
        let later = r.at(110.0);
        assert_eq!(later.mdot_ref, 10.0);
        assert!((later.h_in - 11.0).abs() < 1e-12);
    }
}
