//! Which effects a diagnosis considers, and the campaign that refits a set of them.

use super::{Candidate, Fit};
use calib_engine::campaign::{Campaign, FreeParameter, Method};

/// A candidate whose ranking descent already removed this share of the residual starts its
/// refit from there; below it, larger sizes of the effect are tried as starts too.
pub const WELL_RANKED: f64 = 0.9;

/// The candidate effects of a campaign: every effect of its model that the campaign does not
/// already calibrate or fix, restricted to its mapped outputs and to the campaign's list if it
/// has one. A base parameter that is also an effect is a candidate only when held at 0.
pub fn candidate_effects(campaign: &Campaign) -> Vec<FreeParameter> {
    let info = campaign.model.info();
    let mapped: Vec<&str> = campaign.outputs.iter().map(|o| o.model.as_str()).collect();
    info.effects
        .iter()
        .filter(|e| {
            campaign
                .diagnosis
                .candidates
                .as_ref()
                .is_none_or(|list| list.contains(&e.name))
        })
        .filter(|e| match e.name.split_once('(') {
            Some((_, rest)) => mapped.contains(&rest.trim_end_matches(')')),
            None => true,
        })
        .filter_map(|e| {
            let index = info.parameter_index(&e.name)?;
            let free = campaign.free.iter().any(|p| p.index == index);
            (!free && campaign.base[index] == 0.0).then(|| FreeParameter {
                name: e.name.clone(),
                index,
                nominal: 0.0,
                min: e.min,
                max: e.max,
                effect: true,
                scale: calib_engine::campaign::Scale::Lin,
                experiment: None,
            })
        })
        .collect()
}

/// `campaign` with the free parameters of `fit` but the effect `out` (held off, at 0), each
/// starting where `fit` left it: the refit of backward elimination ([`super::prune`]).
pub(super) fn refit_campaign_from(campaign: &Campaign, fit: &Fit, out: &str) -> Campaign {
    let mut c = campaign.clone();
    c.free = fit
        .free
        .iter()
        .zip(&fit.point)
        .filter(|(p, _)| p.name != out)
        .map(|(p, v)| FreeParameter {
            nominal: v.clamp(p.min, p.max),
            ..p.clone()
        })
        .collect();
    c.search.extra_starts.clear();
    c
}

/// The free parameter of `candidate`'s effect, in bounds scaled to its estimated size.
pub(super) fn scaled(candidate: &Candidate, specs: &[FreeParameter]) -> FreeParameter {
    let spec = specs
        .iter()
        .find(|s| s.name == candidate.effect)
        .expect("candidates come from the specs");
    let reach = (20.0 * candidate.estimate.abs())
        .max(100.0 * candidate.step.abs())
        .max(100.0 * candidate.centre);
    let (min, max) = if spec.min >= 0.0 {
        (0.0, reach.min(spec.max))
    } else {
        ((-reach).max(spec.min), reach.min(spec.max))
    };
    FreeParameter {
        min,
        max: if max > min { max } else { spec.max },
        ..spec.clone()
    }
}

/// The campaign of a refit: the baseline's free parameters (starting at the baseline optimum)
/// plus the effects of `set`, in bounds scaled to their estimated size.
pub(super) fn refit_campaign(
    campaign: &Campaign,
    baseline: &Fit,
    set: &[&Candidate],
    specs: &[FreeParameter],
) -> Campaign {
    let mut c = campaign.clone();
    for (p, v) in c.free.iter_mut().zip(&baseline.point) {
        p.nominal = v.clamp(p.min, p.max);
    }
    for candidate in set {
        c.free.push(scaled(candidate, specs));
    }
    // Informed starts: each effect at its estimate with the other parameters where the
    // ranking's descent left them (or at the baseline optimum).
    let estimates: Vec<f64> = set.iter().map(|c| c.estimate).collect();
    for candidate in set {
        if candidate.point.len() == baseline.point.len() + 1 {
            let mut start = candidate.point[..baseline.point.len()].to_vec();
            start.extend(&estimates);
            c.search.extra_starts.push(start);
        }
    }
    let mut at_baseline = baseline.point.clone();
    at_baseline.extend(&estimates);
    c.search.extra_starts.push(at_baseline);
    if let [single] = set {
        // Larger sizes too (unless the ranking's descent already found the effect): the baseline's parameters compensate for the missing effect, so
        // the effect's best size with them held is often far below its true size.
        let sign = if single.estimate < 0.0 { -1.0 } else { 1.0 };
        for m in [10.0, 100.0].iter().filter(|_| single.score < WELL_RANKED) {
            let mut start = baseline.point.clone();
            start.push(sign * m * single.centre);
            c.search.extra_starts.push(start);
        }
    }
    let free = c.free.clone();
    for start in c.search.extra_starts.iter_mut() {
        for (v, p) in start.iter_mut().zip(&free) {
            *v = v.clamp(p.min, p.max);
        }
    }
    if !c.search.methods.contains(&Method::NelderMead) {
        c.search.methods.push(Method::NelderMead);
    }
    c.search.starts = c.search.starts.max(4);
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::testing::fit;
    use std::path::Path;

    fn example(name: &str) -> Campaign {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
        Campaign::load(&dir.join(name)).unwrap()
    }

    fn names(c: &Campaign) -> Vec<String> {
        candidate_effects(c).into_iter().map(|p| p.name).collect()
    }

    #[test]
    fn candidates_are_the_effects_the_campaign_leaves_out() {
        let c = example("furuta.toml");
        let all = names(&c);
        for expected in [
            "viscous_friction.arm",
            "quadratic_drag.pendulum",
            "offset(armJoint.phi)",
            "lag(pendulumJoint.phi)",
        ] {
            assert!(all.iter().any(|n| n == expected), "{expected}: {all:?}");
        }
        // Calibrated already, or an output the campaign does not compare.
        assert!(
            !all.iter().any(|n| n.starts_with("coulomb_friction")),
            "{all:?}"
        );
        assert!(!all.iter().any(|n| n.contains("armJoint.w")), "{all:?}");
        for p in candidate_effects(&c) {
            assert!(
                p.effect && p.nominal == 0.0 && p.min <= 0.0 && p.max > 0.0,
                "{p:?}"
            );
        }
    }

    #[test]
    fn a_campaign_list_restricts_the_candidates() {
        let mut c = example("furuta.toml");
        c.diagnosis.candidates = Some(vec!["stiffness.arm".into(), "gain(armJoint.w)".into()]);
        assert_eq!(names(&c), ["stiffness.arm"]);
    }

    #[test]
    fn a_refit_frees_the_effect_near_its_estimate_and_starts_from_the_baseline() {
        let c = example("furuta.toml");
        let specs = candidate_effects(&c);
        let baseline = fit(&[
            ("armFriction", 0.012, 0.0, 0.9, 0.0101, false),
            ("pendulumFriction", 0.002, 0.0, 0.9, 0.0012, false),
        ]);
        let candidate = Candidate {
            effect: "viscous_friction.arm".into(),
            score: 0.5,
            linear_score: 0.5,
            estimate: 0.002,
            linear_estimate: 0.002,
            step: 1e-5,
            objective: None,
            point: vec![0.0098, 0.0012, 0.0019],
            centre: 1e-4,
        };
        let refit = refit_campaign(&c, &baseline, &[&candidate], &specs);
        assert_eq!(refit.free.len(), 3);
        assert_eq!(
            (refit.free[0].nominal, refit.free[1].nominal),
            (0.0101, 0.0012)
        );
        let effect = &refit.free[2];
        assert_eq!(effect.name, "viscous_friction.arm");
        // 20 times the estimate, within the model's range.
        assert_eq!((effect.min, effect.max), (0.0, 0.04));
        // From the ranking's descent, from the baseline with the estimate, and larger sizes
        // (the ranking's score is below WELL_RANKED).
        assert_eq!(
            refit.search.extra_starts,
            [
                vec![0.0098, 0.0012, 0.002],
                vec![0.0101, 0.0012, 0.002],
                vec![0.0101, 0.0012, 0.001],
                vec![0.0101, 0.0012, 0.01],
            ]
        );
        assert!(refit.search.methods.contains(&Method::NelderMead));
        assert!(refit.search.starts >= 4);
    }
}
