//! Boundary conditions of the test bench: five ramps, one after another, each of which a
//! measured signal may replace.
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
//!
//! A model input ([`INPUTS`]: `mdot_ref`, `h_in`, `p_out`, `T_air_in`, `mdot_air`, in SI
//! units) driven by a signal ([`crate::inputs`]) takes the signal's value instead of its
//! ramp ([`Driven`]); the ramp's start and end parameters then do nothing for it. Inputs
//! without a signal keep their ramps, computed exactly as before, so an undriven run is the
//! same to the bit.

use crate::inputs::{InputSignal, Interpolation};

/// The model inputs, in the order of [`Inputs`]' fields: name, unit (SI), what it is, and
/// the start and end parameters of its ramp.
pub const INPUTS: [(&str, &str, &str, &str, &str); 5] = [
    (
        "mdot_ref",
        "kg/s",
        "refrigerant mass flow",
        "mdot_ref_start",
        "mdot_ref_end",
    ),
    (
        "h_in",
        "J/kg",
        "refrigerant inlet enthalpy",
        "h_in_start",
        "h_in_end",
    ),
    (
        "p_out",
        "Pa",
        "refrigerant outlet pressure",
        "p_out_start",
        "p_out_end",
    ),
    (
        "T_air_in",
        "K",
        "air inlet temperature",
        "T_air_in_start",
        "T_air_in_end",
    ),
    (
        "mdot_air",
        "kg/s",
        "air mass flow",
        "mdot_air_start",
        "mdot_air_end",
    ),
];

/// What Describe says of input `k`: what it is, and the ramp it follows when undriven.
pub fn input_description(k: usize) -> String {
    let (_, _, what, start, end) = INPUTS[k];
    let (a, b) = SCHEDULE[k];
    format!(
        "{what}; when no signal drives it, the built-in ramp from `{start}` to `{end}` \
         between {a} and {b} s (a driven input ignores those two parameters)"
    )
}

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

/// Measured signals in place of ramps: at most one per input, by [`INPUTS`] index.
#[derive(Debug, Clone, Default)]
pub struct Driven {
    signals: [Option<InputSignal>; 5],
    any: bool,
}

impl Driven {
    /// The signals of `inputs` (already checked against the model: each names one of the
    /// five inputs at most once).
    pub fn new(inputs: &crate::inputs::Inputs) -> Self {
        let mut driven = Self::default();
        for s in &inputs.signals {
            driven.signals[s.input] = Some(s.clone());
            driven.any = true;
        }
        driven
    }

    pub fn is_empty(&self) -> bool {
        !self.any
    }

    /// Replace the ramps' values in `inp` (time `t`) by the driven inputs' signals.
    #[inline]
    pub fn apply(&self, t: f64, inp: &mut Inputs) {
        if !self.any {
            return;
        }
        let [mdot_ref, h_in, p_out, t_air_in, mdot_air] = &self.signals;
        if let Some(s) = mdot_ref {
            inp.mdot_ref = s.at(t);
        }
        if let Some(s) = h_in {
            inp.h_in = s.at(t);
        }
        if let Some(s) = p_out {
            inp.p_out = s.at(t);
        }
        if let Some(s) = t_air_in {
            inp.t_air_in = s.at(t);
        }
        if let Some(s) = mdot_air {
            inp.mdot_air = s.at(t);
        }
    }

    /// A time up to which every input keeps its value of t = 0, that time included: the
    /// start of the first ramp of an undriven input, or the last sample before a driven
    /// signal first differs from its value at 0 (0 when it moves from the start; the sample
    /// before that when the two share their time, a step recorded as two rows). With
    /// nothing driven it is [`FIRST_RAMP`].
    pub fn steady_until(&self) -> f64 {
        if !self.any {
            return FIRST_RAMP;
        }
        let mut until = f64::INFINITY;
        for (k, signal) in self.signals.iter().enumerate() {
            until = until.min(match signal {
                None => SCHEDULE[k].0,
                Some(s) => constant_from_zero_until(s),
            });
        }
        until
    }
}

/// The last sample time up to which `s` keeps its value of t = 0, that time included (≥ 0;
/// infinite when it never changes).
fn constant_from_zero_until(s: &InputSignal) -> f64 {
    let (times, values) = (&*s.times, &*s.values);
    let v = s.at(0.0);
    // The first sample after 0; a line from the sample before it moves unless both agree.
    let k = times.partition_point(|&x| x <= 0.0);
    if s.interpolation == Interpolation::Linear && k > 0 && values[k - 1] != v {
        return 0.0;
    }
    let Some(j) = (k..times.len()).find(|&j| values[j] != v) else {
        return f64::INFINITY;
    };
    // At the time of the first differing sample the signal has its value; before it, up to
    // the last earlier sample time, it has `v`.
    let earlier = times[..j].partition_point(|&x| x < times[j]);
    match earlier {
        0 => 0.0,
        e => times[e - 1].max(0.0),
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

    fn signal(times: &[f64], values: &[f64], interpolation: Interpolation) -> InputSignal {
        InputSignal {
            input: 0,
            times: times.into(),
            values: values.into(),
            interpolation,
        }
    }

    #[test]
    fn a_signal_is_steady_up_to_its_last_sample_before_it_moves() {
        use Interpolation::{Hold, Linear};
        let until = |s: InputSignal| constant_from_zero_until(&s);
        // Flat to 5 s, then a line or a held step.
        for i in [Linear, Hold] {
            assert_eq!(until(signal(&[0.0, 5.0, 6.0], &[1.0, 1.0, 2.0], i)), 5.0);
            assert_eq!(until(signal(&[0.0, 5.0], &[1.0, 1.0], i)), f64::INFINITY);
            // A step recorded as two rows at 5 s: 5 s itself has the new value.
            assert_eq!(
                until(signal(
                    &[0.0, 2.0, 5.0, 5.0, 9.0],
                    &[1.0, 1.0, 1.0, 2.0, 2.0],
                    i
                )),
                2.0
            );
            // Moving from the first sample.
            assert_eq!(until(signal(&[0.0, 1.0], &[1.0, 1.1], i)), 0.0);
        }
        // Samples before 0: a line through 0 moves there, a held value does not.
        assert_eq!(
            until(signal(&[-1.0, 1.0, 2.0], &[0.0, 2.0, 2.0], Linear)),
            0.0
        );
        assert_eq!(
            until(signal(&[-1.0, 1.0, 2.0], &[0.0, 0.0, 2.0], Hold)),
            1.0
        );
        // Undriven inputs hold until their ramps.
        let mut driven = Driven::default();
        assert_eq!(driven.steady_until(), FIRST_RAMP);
        driven.signals[0] = Some(signal(&[0.0, 300.0], &[1.0, 1.0], Linear));
        driven.any = true;
        assert_eq!(driven.steady_until(), SCHEDULE[1].0);
    }
}
