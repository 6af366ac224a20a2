//! A proposal's harmonics as an amplitude and a phase, the form its refit takes.
//!
//! Discovery finds a harmonic as `a·sin(m·q) + b·cos(m·q)`: linear in `a` and `b`, as the
//! regression needs. The refit writes it `amp·sin(m·q + phase)` (`a = amp·cos(phase)`,
//! `b = amp·sin(phase)`): the same torque, whose amplitude is then a parameter of its own,
//! with a profile likelihood interval of its own. The multiple `m` stays the integer
//! discovery found, written into the formula, never a parameter.

use super::proposal::BOUND_WIDENING;
use super::{DiscoveredEffect, EffectParameter, FoundHarmonic, FoundTerm};
use std::f64::consts::PI;

/// `effect` with each sine–cosine pair (`aK`, `bK`) written as `ampK * sin(m * q + phaseK)`;
/// the other terms as they are. The amplitude starts at the harmonic's estimate, bounded by
/// [`BOUND_WIDENING`] times its interval's half-width on either side (not below 0: the
/// phase carries the sign), the phase at its estimate within as many half-widths (at most
/// π on either side).
pub fn amplitude_phase(effect: &DiscoveredEffect) -> DiscoveredEffect {
    let mut formula = Vec::new();
    let mut parameters = Vec::new();
    let mut terms = Vec::new();
    let mut k = 0;
    while k < effect.terms.len() {
        let term = &effect.terms[k];
        let pair = effect.terms.get(k + 1).and_then(|next| {
            let harmonic = pair_of(effect, term, next)?;
            Some((next, harmonic))
        });
        if let Some((cosine, harmonic)) = pair {
            let index = &term.parameter[1..];
            let (amp, phase) = (format!("amp{index}"), format!("phase{index}"));
            let inner = &term.function["sin(".len()..term.function.len() - 1];
            formula.push(format!("{amp} * sin({inner} + {phase})"));
            parameters.extend(harmonic_parameters(term, cosine, harmonic, &amp, &phase));
            k += 2;
            continue;
        }
        formula.push(if term.function == "1" {
            term.parameter.clone()
        } else {
            format!("{} * {}", term.parameter, term.function)
        });
        if let Some(p) = effect.parameters.iter().find(|p| p.name == term.parameter) {
            parameters.push(p.clone());
        }
        terms.push(term.clone());
        k += 1;
    }
    DiscoveredEffect {
        formula: formula.join(" + "),
        parameters,
        terms,
        ..effect.clone()
    }
}

/// The harmonic that the terms `sine`, `cosine` form (`aK·sin(m·q)`, `bK·cos(m·q)`).
fn pair_of<'a>(
    effect: &'a DiscoveredEffect,
    sine: &FoundTerm,
    cosine: &FoundTerm,
) -> Option<&'a FoundHarmonic> {
    let inner = sine
        .function
        .strip_prefix("sin(")
        .and_then(|f| f.strip_suffix(')'))?;
    let index = sine.parameter.strip_prefix('a')?;
    if cosine.function != format!("cos({inner})") || cosine.parameter != format!("b{index}") {
        return None;
    }
    effect.harmonics.iter().find(|h| {
        let argument = match h.multiple {
            1 => h.angle.clone(),
            m => format!("{m} * {}", h.angle),
        };
        inner == argument
    })
}

/// Start and bounds of a harmonic's amplitude and phase. The phase's half-width follows
/// from the coefficients' (`δphase = δ(b cos φ − a sin φ) / amp`, their covariance left out).
fn harmonic_parameters(
    sine: &FoundTerm,
    cosine: &FoundTerm,
    h: &FoundHarmonic,
    amp: &str,
    phase: &str,
) -> [EffectParameter; 2] {
    let half = |t: &FoundTerm| 0.5 * (t.ci_high - t.ci_low);
    let amp_half = (h.ci_high - h.amplitude).max(0.0);
    let (s, c) = h.phase.sin_cos();
    let phase_half = if h.amplitude > 0.0 {
        (s * s * half(sine).powi(2) + c * c * half(cosine).powi(2)).sqrt() / h.amplitude
    } else {
        PI
    };
    let phase_reach = (BOUND_WIDENING * phase_half).min(PI);
    [
        EffectParameter {
            name: amp.to_string(),
            nominal: h.amplitude,
            min: (h.amplitude - BOUND_WIDENING * amp_half).max(0.0),
            max: h.amplitude + BOUND_WIDENING * amp_half,
        },
        EffectParameter {
            name: phase.to_string(),
            nominal: h.phase,
            min: h.phase - phase_reach,
            max: h.phase + phase_reach,
        },
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn term(parameter: &str, function: &str, estimate: f64, half: f64) -> FoundTerm {
        FoundTerm {
            function: function.into(),
            parameter: parameter.into(),
            estimate,
            ci_low: estimate - half,
            ci_high: estimate + half,
        }
    }

    #[test]
    fn a_harmonic_pair_becomes_an_amplitude_and_a_phase() {
        let (a, b) = (0.006, 0.0008);
        let effect = DiscoveredEffect {
            name: "discovered.armJoint".into(),
            place: "armJoint".into(),
            formula: "c1 * armJoint.w + a1 * sin(8 * armJoint.phi) + b1 * cos(8 * armJoint.phi)"
                .into(),
            parameters: ["c1", "a1", "b1"]
                .iter()
                .map(|n| EffectParameter {
                    name: n.to_string(),
                    nominal: 0.0,
                    min: -1.0,
                    max: 1.0,
                })
                .collect(),
            terms: vec![
                term("c1", "armJoint.w", -1e-3, 1e-4),
                term("a1", "sin(8 * armJoint.phi)", a, 6e-4),
                term("b1", "cos(8 * armJoint.phi)", b, 6e-4),
            ],
            harmonics: vec![FoundHarmonic {
                angle: "armJoint.phi".into(),
                multiple: 8,
                amplitude: f64::hypot(a, b),
                ci_low: f64::hypot(a, b) - 6e-4,
                ci_high: f64::hypot(a, b) + 6e-4,
                phase: b.atan2(a),
            }],
        };
        let polar = amplitude_phase(&effect);
        assert_eq!(
            polar.formula,
            "c1 * armJoint.w + amp1 * sin(8 * armJoint.phi + phase1)"
        );
        let names: Vec<_> = polar.parameters.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["c1", "amp1", "phase1"]);
        let (amp, phase) = (&polar.parameters[1], &polar.parameters[2]);
        assert_eq!(amp.nominal, f64::hypot(a, b));
        assert!((amp.min - (amp.nominal - 1.8e-3)).abs() < 1e-12, "{amp:?}");
        // Equal half-widths of a and b: the phase's is that over the amplitude.
        let reach = 3.0 * 6e-4 / amp.nominal;
        assert!(
            (phase.max - phase.nominal - reach).abs() < 1e-9,
            "{phase:?}"
        );
        // The same torque, value for value.
        for q in [0.0f64, 0.3, 1.7, -2.2] {
            let pair = a * (8.0 * q).sin() + b * (8.0 * q).cos();
            let polar = amp.nominal * (8.0 * q + phase.nominal).sin();
            assert!((pair - polar).abs() < 1e-15);
        }
        // A weak harmonic's amplitude is bounded below by 0.
        let mut weak = effect.clone();
        weak.harmonics[0].ci_high = weak.harmonics[0].amplitude + 0.01;
        assert_eq!(amplitude_phase(&weak).parameters[1].min, 0.0);
    }

    #[test]
    fn an_effect_without_harmonics_is_unchanged() {
        let effect = DiscoveredEffect {
            name: "discovered.armJoint".into(),
            place: "armJoint".into(),
            formula: "c1 * armJoint.w * armJoint.w * armJoint.w".into(),
            parameters: vec![EffectParameter {
                name: "c1".into(),
                nominal: -3e-4,
                min: -4e-4,
                max: -2e-4,
            }],
            terms: vec![term(
                "c1",
                "armJoint.w * armJoint.w * armJoint.w",
                -3e-4,
                3e-5,
            )],
            harmonics: vec![],
        };
        assert_eq!(amplitude_phase(&effect), effect);
    }
}
