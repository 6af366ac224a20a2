//! Found outside the library (`calib diagnose --discover`, `Diagnose` with `discover`): after
//! the diagnosis, discovery on the campaign's record with the final fit's parameters, each
//! proposal refitted, never written into the campaign: what the outputs call "found outside
//! the library".

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
    /// The refit of each proposal, in the order of [`Discovery::proposals`].
    pub refits: Vec<ProposalRefit>,
}

impl Found {
    /// Each proposal with its refit.
    pub fn proposals(&self) -> Vec<(&DiscoveredEffect, Option<&ProposalRefit>)> {
        let proposals = self
            .discovery
            .as_ref()
            .map(Discovery::proposals)
            .unwrap_or_default();
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
                "proposals": found.proposals().iter().map(|p| p.to_toml()).collect::<Vec<_>>(),
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
            (None, Some(found)) => summary(found, &self.refits),
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
                refits: Vec::new(),
            });
        }
    };
    let mut campaign = d.campaign.clone();
    campaign.free = fit.free.clone();
    let mut refits = Vec::new();
    for proposal in found.proposals() {
        refits.push(refit_discovered(
            &campaign,
            &fit.point,
            fit.objective,
            d.noise_floor,
            proposal,
            evaluator,
            progress,
        )?);
    }
    Ok(Found {
        unavailable: None,
        discovery: Some(found),
        refits,
    })
}

/// The proposal in symbols and words, each term with its interval, the block to paste, and
/// its refit against the noise floor.
fn summary(found: &Discovery, refits: &[ProposalRefit]) -> String {
    let mut s =
        String::from("found outside the library (a proposal, not added to the campaign):\n");
    if found.proposals().is_empty() {
        s.push_str("  nothing: no function of the library explains the residual torque\n");
    }
    for joint in &found.joints {
        if let Some(why) = &joint.unseen {
            s.push_str(&format!("  {}: not looked at: {why}\n", joint.joint));
        }
    }
    for joint in &found.joints {
        let Some(p) = &joint.proposal else { continue };
        s.push_str(&format!(
            "  torque on {}: {}\n  (residual torque RMS {:.3e} -> {:.3e} N m)\n",
            p.place, p.formula, joint.residual_rms, joint.remaining_rms
        ));
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
