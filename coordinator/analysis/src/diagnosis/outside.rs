//! Found outside the library (`calib diagnose --discover`, `Diagnose` with `discover`): after
//! the diagnosis, discovery on the campaign's record with the final fit's parameters, each
//! proposal refitted, never written into the campaign: what the outputs call "found outside
//! the library".

use super::discovery::scan::{scan, HarmonicScan, ScanStart};
use super::discovery::{
    discover, joint_model, record_of, refit_discovered, DiscoveredEffect, Discovery,
    DiscoveryOptions, ProposalRefit,
};
use super::Diagnosis;
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::Evaluator;
use calib_engine::optim::problem::Progress;
use serde_json::json;

/// What discovery found after a diagnosis.
#[derive(Debug, Clone)]
pub struct Found {
    /// Why nothing was looked for (a model discovery cannot invert); `None` when it looked.
    pub unavailable: Option<String>,
    pub discovery: Option<Discovery>,
    /// The harmonic scan, run where the library's diagnosis leaves more than noise.
    pub scan: Option<HarmonicScan>,
    /// The refit of each proposal, in the order of [`Found::proposals`].
    pub refits: Vec<ProposalRefit>,
}

impl Found {
    /// Each proposal with its refit.
    pub fn proposals(&self) -> Vec<(&DiscoveredEffect, Option<&ProposalRefit>)> {
        let mut proposals = self
            .discovery
            .as_ref()
            .map(Discovery::proposals)
            .unwrap_or_default();
        proposals.extend(self.scan.as_ref().and_then(|s| s.proposal.as_ref()));
        proposals
            .into_iter()
            .enumerate()
            .map(|(k, p)| (p, self.refits.get(k)))
            .collect()
    }

    /// The `found_outside_the_library` entry of diagnosis.json.
    pub fn json(&self) -> serde_json::Value {
        match &self.discovery {
            Some(found) if self.unavailable.is_none() => json!({
                "available": true,
                "discovery": found,
                "proposals": self.proposals().iter().map(|(p, _)| p.to_toml()).collect::<Vec<_>>(),
                "harmonic_scan": self.scan,
                "refits": self.refits,
            }),
            _ => json!({
                "available": false,
                "reason": self.unavailable.clone().unwrap_or_default(),
            }),
        }
    }

    /// The section of diagnosis.md, and the summary printed (the same text).
    pub fn text(&self) -> String {
        match (&self.unavailable, &self.discovery) {
            (None, Some(found)) => summary(found, self.scan.as_ref(), &self.refits),
            (why, _) => format!(
                "found outside the library: nothing looked for. {}\n",
                why.as_deref().unwrap_or_default()
            ),
        }
    }

    /// diagnosis.md's section: a heading and the text.
    pub fn markdown(&self) -> String {
        format!(
            "\n## Found outside the library\n\n```text\n{}```\n",
            self.text()
        )
    }
}

/// Discover on `d`'s record with its final fit, and refit each proposal with `evaluator`.
pub fn found_outside_the_library<E: Evaluator>(
    d: &Diagnosis,
    evaluator: &E,
    progress: &dyn Progress,
) -> Result<Found> {
    let fit = &d.final_fit;
    let mut params = d.campaign.base.clone();
    for (p, v) in fit.free.iter().zip(&fit.point) {
        params[p.index] = *v;
    }
    // A model or a record discovery cannot read leaves the library's diagnosis whole: the
    // report says why nothing was looked for.
    let found = joint_model(&d.campaign, params).and_then(|model| {
        let record = record_of(&d.campaign, &d.measurement, model.as_ref())?;
        discover(model.as_ref(), &record, &DiscoveryOptions::default())
            .map_err(|e| Error::InvalidRequest(format!("discovery: {e}")))
    });
    let found = match found {
        Ok(found) => found,
        Err(e) => {
            return Ok(Found {
                unavailable: Some(e.to_string()),
                discovery: None,
                scan: None,
                refits: Vec::new(),
            });
        }
    };
    let mut campaign = d.campaign.clone();
    campaign.free = fit.free.clone();
    let refit = |proposal: &DiscoveredEffect| {
        refit_discovered(
            &campaign,
            &fit.point,
            fit.objective,
            d.noise_floor,
            proposal,
            evaluator,
            progress,
        )
    };
    let mut refits = found
        .proposals()
        .into_iter()
        .map(refit)
        .collect::<Result<Vec<_>>>()?;
    let mut scanned = scan_if_unsettled(d, &found, &campaign, &refits, evaluator);
    // The scan's best is proposed only when its refit leaves nothing but noise (the
    // verdict's test): among 78 harmonics one fits a little better by chance.
    if let Some(scan) = scanned.as_mut() {
        if let Some(proposal) = scan.proposal.clone() {
            let r = refit(&proposal)?;
            if d.floor.holds(r.objective_after) {
                refits.push(r);
            } else {
                scan.withheld = Some(r.ratio_after());
                scan.proposal = None;
            }
        }
    }
    Ok(Found {
        unavailable: None,
        discovery: Some(found),
        scan: scanned,
        refits,
    })
}

/// Where neither the library nor the regression's proposals leave only noise, the harmonic
/// scan from `d`'s final fit; one that cannot run (a simulation failed) is said in the log
/// and leaves the rest whole.
fn scan_if_unsettled<E: Evaluator>(
    d: &Diagnosis,
    found: &Discovery,
    campaign: &calib_engine::campaign::Campaign,
    refits: &[ProposalRefit],
    evaluator: &E,
) -> Option<HarmonicScan> {
    if d.explained() || refits.iter().any(|r| d.floor.holds(r.objective_after)) {
        return None;
    }
    let joints: Vec<String> = found.joints.iter().map(|j| j.joint.clone()).collect();
    let holdout = super::window::with_window(campaign, d.holdout_window);
    let from = ScanStart {
        campaign,
        holdout: &holdout,
        measurement: &d.measurement,
        point: &d.final_fit.point,
        effective_samples: d.final_fit.effective_samples,
    };
    scan(&from, &joints, evaluator)
        .inspect_err(|e| tracing::warn!(error = %e, "the harmonic scan could not run"))
        .ok()
}

/// The proposal in symbols and words, each term with its interval, the block to paste, and
/// its refit against the noise floor.
fn summary(found: &Discovery, scan: Option<&HarmonicScan>, refits: &[ProposalRefit]) -> String {
    let mut s =
        String::from("found outside the library (a proposal, not added to the campaign):\n");
    let scanned = scan.and_then(|s| s.proposal.as_ref());
    if let (Some(ratio), Some(best)) = (
        scan.and_then(|s| s.withheld),
        scan.and_then(|s| s.best.as_ref()),
    ) {
        s.push_str(&format!(
            "  harmonic scan: the best of k = 2..40, {} periods per turn of {}.phi, refits to {:.2}x the noise floor: not proposed (a harmonic is proposed only when its refit leaves nothing but noise)\n",
            best.multiple, best.joint, ratio
        ));
    }
    if found.proposals().is_empty() && scanned.is_none() {
        s.push_str("  nothing: no function of the library explains the residual torque\n");
    }
    for joint in &found.joints {
        if let Some(why) = &joint.unseen {
            s.push_str(&format!("  {}: not looked at: {why}\n", joint.joint));
        }
    }
    for (p, joint) in found
        .joints
        .iter()
        .filter_map(|j| j.proposal.as_ref().map(|p| (p, Some(j))))
        .chain(scanned.map(|p| (p, None)))
    {
        match joint {
            Some(joint) => s.push_str(&format!(
                "  torque on {}: {}\n  (residual torque RMS {:.3e} -> {:.3e} N m)\n",
                p.place, p.formula, joint.residual_rms, joint.remaining_rms
            )),
            None => {
                let scan = scan.expect("a scanned proposal comes from a scan");
                let best = scan.best.as_ref().expect("a proposal has a best");
                s.push_str(&format!(
                    "  torque on {}: {}\n  (harmonic scan, k = 2..40 on every joint's angle, each refitted: the objective {:.4e} -> {:.4e}, the lowest of {}; held out {:.4e} -> {:.4e})\n",
                    p.place,
                    p.formula,
                    scan.objective,
                    best.objective,
                    scan.scanned.len(),
                    scan.held_out_objective,
                    best.held_out_objective
                ));
            }
        }
        for t in &p.terms {
            s.push_str(&format!(
                "    {} = {:.4e}  95% [{:.4e}, {:.4e}]  times {}: {}\n",
                t.parameter,
                t.estimate,
                t.ci_low,
                t.ci_high,
                t.function,
                words(&t.function)
            ));
        }
        for h in &p.harmonics {
            s.push_str(&format!(
                "    amplitude of {} periods per turn of {}: {:.4e}  95% [{:.4e}, {:.4e}], phase {:.3} rad\n",
                h.multiple, h.angle, h.amplitude, h.ci_low, h.ci_high, h.phase
            ));
        }
        s.push_str("\n  to try it, paste into the campaign file:\n\n");
        s.push_str(&p.to_toml());
        s.push('\n');
    }
    for r in refits {
        s.push_str(&r.summary());
    }
    s
}

/// A proposal's formula in words: each term's parameter times its function in words.
pub fn formula_in_words(effect: &DiscoveredEffect) -> String {
    effect
        .terms
        .iter()
        .map(|t| {
            if t.function == "1" {
                format!("{} (a constant torque)", t.parameter)
            } else {
                format!("{} times {}", t.parameter, words(&t.function))
            }
        })
        .collect::<Vec<_>>()
        .join(", plus ")
}

/// A function of the library in words (one wording for the proposal and its refit).
pub use super::discovery::words::function_in_words as words;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::discovery::FoundTerm;

    fn term(parameter: &str, function: &str) -> FoundTerm {
        FoundTerm {
            function: function.into(),
            parameter: parameter.into(),
            estimate: 1e-3,
            ci_low: 0.9e-3,
            ci_high: 1.1e-3,
        }
    }

    #[test]
    fn a_proposal_reads_in_words() {
        let effect = DiscoveredEffect {
            name: "discovered.armJoint".into(),
            place: "armJoint".into(),
            formula: "a1 * sin(8 * armJoint.phi) + c1 * sign(armJoint.w) + c2".into(),
            parameters: vec![],
            terms: vec![
                term("a1", "sin(8 * armJoint.phi)"),
                term("c1", "sign(armJoint.w)"),
                term("c2", "1"),
                term("c3", "armJoint.w * armJoint.w * armJoint.w"),
            ],
            harmonics: vec![],
        };
        assert_eq!(
            formula_in_words(&effect),
            "a1 times the sine of 8 periods per turn of armJoint.phi, plus c1 times a constant \
             torque along the motion of armJoint.w (a dry friction's sign), plus c2 (a constant \
             torque), plus c3 times the cube of armJoint.w"
        );
        assert_eq!(words("cos(armJoint.phi)"), "the cosine of armJoint.phi");
    }
}
