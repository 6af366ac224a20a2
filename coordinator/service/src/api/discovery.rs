//! What discovery found outside the effect library ([`calib_analysis::diagnosis::outside`]) as the
//! API's typed `FoundOutsideLibrary`: every figure computed here, on the server, for clients
//! that only show them.

use calib_analysis::diagnosis::discovery::scan::{HarmonicScan, Scanned};
use calib_analysis::diagnosis::discovery::{
    DiscoveredEffect, EffectInterval, EffectParameter, FoundHarmonic, FoundTerm, JointDiscovery,
    OutputResidual, ProposalRefit, RefitStage,
};
use calib_analysis::diagnosis::outside::{formula_in_words, words, Found};
use calib_analysis::profile::Threshold;
use calib_proto::v1 as pb;

/// `found` as `DiagnosisState.found_outside_the_library` carries it.
pub fn found_message(found: &Found) -> pb::FoundOutsideLibrary {
    let Some(discovery) = found
        .discovery
        .as_ref()
        .filter(|_| found.unavailable.is_none())
    else {
        return pb::FoundOutsideLibrary {
            available: false,
            reason: found.unavailable.clone().unwrap_or_default(),
            ..Default::default()
        };
    };
    let joint_of = |effect: &DiscoveredEffect| {
        discovery
            .joints
            .iter()
            .find(|j| j.proposal.as_ref().is_some_and(|p| p.name == effect.name))
    };
    pb::FoundOutsideLibrary {
        available: true,
        reason: String::new(),
        searched: discovery.joints.iter().map(search_message).collect(),
        proposals: found
            .proposals()
            .into_iter()
            .map(|(effect, refit)| proposal_message(effect, joint_of(effect), refit))
            .collect(),
        harmonic_scan: found.scan.as_ref().map(scan_message),
    }
}

fn scan_message(s: &HarmonicScan) -> pb::HarmonicScan {
    let scanned = |s: &Scanned| pb::ScannedHarmonic {
        joint: s.joint.clone(),
        multiple: s.multiple as u64,
        share: s.share,
        objective: s.objective,
        held_out_objective: s.held_out_objective,
    };
    pb::HarmonicScan {
        objective: s.objective,
        held_out_objective: s.held_out_objective,
        scanned: s.scanned.iter().map(scanned).collect(),
        best: s.best.as_ref().map(scanned),
        withheld: s.withheld,
    }
}

fn search_message(j: &JointDiscovery) -> pb::DiscoverySearch {
    pb::DiscoverySearch {
        torque: j.joint.clone(),
        samples: j.samples as u64,
        effective_samples: j.effective_samples,
        candidates: j.candidates as u64,
        library: j.library as u64,
        residual_rms: j.residual_rms,
        remaining_rms: j.remaining_rms,
        unseen: j.unseen.clone().unwrap_or_default(),
        threshold: j.threshold,
        cross_validation: j
            .cross_validation
            .iter()
            .map(|c| pb::CrossValidationPoint {
                threshold: c.threshold,
                error: c.error,
                standard_error: c.standard_error,
                terms: c.terms as u64,
            })
            .collect(),
    }
}

fn proposal_message(
    effect: &DiscoveredEffect,
    joint: Option<&JointDiscovery>,
    refit: Option<&ProposalRefit>,
) -> pb::DiscoveredEffect {
    pb::DiscoveredEffect {
        name: effect.name.clone(),
        // Discovery finds generalized torques on joints (the only place it inverts).
        torque: effect.place.clone(),
        output: String::new(),
        formula: effect.formula.clone(),
        formula_words: formula_in_words(effect),
        terms: effect
            .terms
            .iter()
            .map(|t| term_message(t, &effect.parameters))
            .collect(),
        harmonics: effect.harmonics.iter().map(harmonic_message).collect(),
        residual_rms: joint.map_or(f64::NAN, |j| j.residual_rms),
        remaining_rms: joint.map_or(f64::NAN, |j| j.remaining_rms),
        effects_toml: effect.to_toml(),
        refit: refit.map(refit_message),
    }
}

fn term_message(t: &FoundTerm, parameters: &[EffectParameter]) -> pb::DiscoveredTerm {
    let bounds = parameters.iter().find(|p| p.name == t.parameter);
    pb::DiscoveredTerm {
        function: t.function.clone(),
        words: words(&t.function),
        parameter: t.parameter.clone(),
        estimate: t.estimate,
        ci_low: t.ci_low,
        ci_high: t.ci_high,
        min: bounds.map_or(f64::NAN, |p| p.min),
        max: bounds.map_or(f64::NAN, |p| p.max),
    }
}

fn harmonic_message(h: &FoundHarmonic) -> pb::DiscoveredHarmonic {
    pb::DiscoveredHarmonic {
        angle: h.angle.clone(),
        multiple: u32::try_from(h.multiple).unwrap_or(u32::MAX),
        amplitude: h.amplitude,
        ci_low: h.ci_low,
        ci_high: h.ci_high,
        phase: h.phase,
    }
}

/// The refit of a proposal; its `effect` field is the proposal less the folded terms, as a
/// campaign takes it.
fn refit_message(r: &ProposalRefit) -> pb::ProposalRefit {
    // The block refitted, as the message a campaign takes: the same text, the same values.
    let kept = super::defined_effects::from_block(&r.toml)
        .ok()
        .and_then(|mut effects| effects.pop());
    pb::ProposalRefit {
        objective_before: r.objective_before,
        objective_after: r.objective_after,
        noise_floor: r.noise_floor,
        ratio_before: r.ratio_before(),
        ratio_after: r.ratio_after(),
        folded: r.folded.clone(),
        parameters: r
            .parameters
            .iter()
            .map(|p| pb::RefitParameter {
                name: p.name.clone(),
                value: p.value,
                min: p.min,
                max: p.max,
            })
            .collect(),
        evaluations: r.evaluations as u64,
        effect: kept,
        effects_toml: r.toml.clone(),
        stages: r.stages.iter().map(stage_message).collect(),
        residual: r.residual.iter().map(residual_message).collect(),
        threshold: r.threshold.as_ref().map(threshold_message),
        intervals: r.intervals.iter().map(interval_message).collect(),
    }
}

fn stage_message(s: &RefitStage) -> pb::RefitStage {
    pb::RefitStage {
        start: s.window.0,
        stop: s.window.1,
        objective: s.objective,
        evaluations: s.evaluations as u64,
        method: s.method.clone(),
    }
}

fn residual_message(r: &OutputResidual) -> pb::RefitResidual {
    pb::RefitResidual {
        output: r.output.clone(),
        rms: r.rms,
        lag1: r.lag1,
        ljung_box: r.ljung_box,
        ljung_box_critical: r.ljung_box_critical,
        white: r.white,
    }
}

fn threshold_message(t: &Threshold) -> pb::ProfileThreshold {
    pb::ProfileThreshold {
        chi_square: t.chi_square,
        s2: t.s2,
        samples: t.samples as u64,
        parameters: t.parameters as u64,
        effective_samples: t.effective_samples,
        inflation: t.inflation,
        delta: t.delta,
    }
}

fn interval_message(i: &EffectInterval) -> pb::EffectInterval {
    pb::EffectInterval {
        name: i.name.clone(),
        value: i.value,
        ci_low: i.ci_low,
        ci_high: i.ci_high,
        linearised_low: i.linearised_low,
        linearised_high: i.linearised_high,
        evaluations: i.evaluations as u64,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use calib_analysis::diagnosis::discovery::refit::RefitParameter;
    use calib_analysis::diagnosis::discovery::{Discovery, EffectParameter};

    fn term(parameter: &str, function: &str, estimate: f64) -> FoundTerm {
        FoundTerm {
            function: function.into(),
            parameter: parameter.into(),
            estimate,
            ci_low: estimate - 1e-3,
            ci_high: estimate + 1e-3,
        }
    }

    fn parameter(name: &str, nominal: f64) -> EffectParameter {
        EffectParameter {
            name: name.into(),
            nominal,
            min: nominal - 3e-3,
            max: nominal + 3e-3,
        }
    }

    /// A proposal with a term folded into the friction: every term with its interval and
    /// bounds, the refit's ratios, and the effect to add being the block refitted.
    #[test]
    fn a_proposal_and_its_refit_as_messages() {
        let effect = DiscoveredEffect {
            name: "discovered.armJoint".into(),
            place: "armJoint".into(),
            formula: "c1 * sign(armJoint.w) + a1 * sin(8 * armJoint.phi)".into(),
            parameters: vec![parameter("c1", -0.004), parameter("a1", 0.006)],
            terms: vec![
                term("c1", "sign(armJoint.w)", -0.004),
                term("a1", "sin(8 * armJoint.phi)", 0.006),
            ],
            harmonics: vec![],
        };
        let kept = DiscoveredEffect {
            formula: "a1 * sin(8 * armJoint.phi)".into(),
            parameters: vec![parameter("a1", 0.006)],
            terms: vec![term("a1", "sin(8 * armJoint.phi)", 0.006)],
            ..effect.clone()
        };
        let joint = JointDiscovery {
            joint: "armJoint".into(),
            samples: 700,
            effective_samples: 120.0,
            candidates: 130,
            library: 200,
            threshold: 0.1,
            cross_validation: vec![],
            residual_rms: 6e-3,
            remaining_rms: 2e-3,
            terms: effect.terms.clone(),
            harmonics: vec![],
            proposal: Some(effect.clone()),
            unseen: None,
        };
        let refit = ProposalRefit {
            effect: effect.name.clone(),
            toml: kept.to_toml(),
            folded: vec!["sign(armJoint.w)".into()],
            objective_before: 300.0,
            objective_after: 3.0,
            noise_floor: 0.01,
            parameters: vec![RefitParameter {
                name: "discovered.armJoint.a1".into(),
                value: 0.0059,
                min: 0.003,
                max: 0.009,
            }],
            evaluations: 500,
            stages: vec![RefitStage {
                window: (0.0, 4.0),
                objective: 2.5,
                evaluations: 120,
                method: "nelder-mead".into(),
            }],
            intervals: vec![EffectInterval {
                name: "discovered.armJoint.a1".into(),
                value: 0.0059,
                ci_low: Some(0.0055),
                ci_high: None,
                linearised_low: 0.0054,
                linearised_high: 0.0064,
                evaluations: 40,
            }],
            ..ProposalRefit::default()
        };
        let found = Found {
            unavailable: None,
            discovery: Some(Discovery {
                joints: vec![joint],
            }),
            scan: Some(HarmonicScan {
                objective: 300.0,
                held_out_objective: 90.0,
                scanned: vec![],
                best: None,
                proposal: None,
                withheld: Some(49.8),
            }),
            refits: vec![refit],
        };
        let m = found_message(&found);
        assert!(m.available);
        assert_eq!(m.searched[0].torque, "armJoint");
        let p = &m.proposals[0];
        assert_eq!((p.torque.as_str(), p.residual_rms), ("armJoint", 6e-3));
        assert_eq!(
            p.terms[1].words,
            "the sine of 8 periods per turn of armJoint.phi"
        );
        // The bounds are the proposal's parameter's.
        let bounds = &effect.parameters[1];
        assert_eq!((p.terms[1].min, p.terms[1].max), (bounds.min, bounds.max));
        assert!(p.formula_words.starts_with("c1 times a constant torque"));
        let r = p.refit.as_ref().unwrap();
        assert_eq!((r.ratio_before, r.ratio_after), (300.0 / 0.01, 3.0 / 0.01));
        let e = r.effect.as_ref().unwrap();
        assert_eq!(e.formula, "a1 * sin(8 * armJoint.phi)");
        assert_eq!(e.parameters.len(), 1);
        assert_eq!(e.parameters[0].nominal, Some(0.006));
        // The refit's windows and intervals, and the scan's withheld best, are typed too.
        assert_eq!((r.stages[0].start, r.stages[0].stop), (0.0, 4.0));
        assert_eq!(r.stages[0].method, "nelder-mead");
        let interval = &r.intervals[0];
        assert_eq!((interval.ci_low, interval.ci_high), (Some(0.0055), None));
        assert_eq!(m.harmonic_scan.as_ref().unwrap().withheld, Some(49.8));

        let nothing = found_message(&Found {
            unavailable: Some("discovery is not available for model `hx_lowfi`".into()),
            discovery: None,
            scan: None,
            refits: vec![],
        });
        assert!(!nothing.available && nothing.proposals.is_empty());
        assert!(nothing.reason.contains("hx_lowfi"));
    }
}
