//! `calib diagnose --discover`: after the diagnosis, discovery on the campaign's record with
//! the final fit's parameters, the proposal printed and refitted, never written into the
//! campaign file: the outputs call it "found outside the library".

use super::Failure;
use calib_coordinator::diagnosis::discovery::{
    discover, joint_model, record_of, refit_discovered, Discovery, DiscoveryOptions, ProposalRefit,
};
use calib_coordinator::diagnosis::Diagnosis;
use calib_coordinator::evaluator::Evaluator;
use calib_coordinator::optim::problem::Progress;
use serde_json::json;

/// What discovery found, as the diagnosis outputs carry it.
pub struct Found {
    /// The `found_outside_the_library` entry of diagnosis.json.
    pub json: serde_json::Value,
    /// The section of diagnosis.md, and the summary printed (the same text).
    pub text: String,
}

/// Discover on `d`'s record with its final fit, and refit each proposal with `evaluator`.
pub fn found_outside_the_library<E: Evaluator>(
    d: &Diagnosis,
    evaluator: &E,
    progress: &dyn Progress,
) -> Result<Found, Failure> {
    let fit = &d.final_fit;
    let mut params = d.campaign.base.clone();
    for (p, v) in fit.free.iter().zip(&fit.point) {
        params[p.index] = *v;
    }
    let model = match joint_model(&d.campaign, params) {
        Ok(model) => model,
        Err(e) => {
            let why = e.to_string();
            return Ok(Found {
                json: json!({ "available": false, "reason": why }),
                text: format!("found outside the library: nothing looked for. {why}\n"),
            });
        }
    };
    let record = record_of(&d.campaign, &d.measurement, model.as_ref())?;
    let found = discover(model.as_ref(), &record, &DiscoveryOptions::default())
        .map_err(|e| Failure::input(format!("discovery: {e}")))?;
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
        json: json!({
            "available": true,
            "discovery": found,
            "proposals": found.proposals().iter().map(|p| p.to_toml()).collect::<Vec<_>>(),
            "refits": refits,
        }),
        text: summary(&found, &refits),
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
        if !r.folded.is_empty() {
            s.push_str(&format!(
                "  refit of {}: {} folded into the joint's own friction\n",
                r.effect,
                r.folded.join(", ")
            ));
        }
        s.push_str(&format!(
            "  refit of {}: objective {:.4e} -> {:.4e}, {:.3} -> {:.3} times the noise floor ({:.4e})\n",
            r.effect,
            r.objective_before,
            r.objective_after,
            r.ratio_before(),
            r.ratio_after(),
            r.noise_floor
        ));
        for p in &r.parameters {
            s.push_str(&format!("    {:<28} {:>13.6e}\n", p.name, p.value));
        }
    }
    s
}

/// A function of the library in words.
fn words(function: &str) -> String {
    if let Some(inner) = function
        .strip_prefix("sign(")
        .and_then(|f| f.strip_suffix(')'))
    {
        return format!("a constant torque along the motion of {inner} (a dry friction's sign)");
    }
    for (f, what) in [("sin(", "sine"), ("cos(", "cosine")] {
        if let Some(inner) = function.strip_prefix(f).and_then(|f| f.strip_suffix(')')) {
            if let Some((m, angle)) = inner.split_once(" * ") {
                return format!("the {what} of {m} periods per turn of {angle}");
            }
            return format!("the {what} of {inner}");
        }
    }
    if function.starts_with("abs(") {
        return "a drag growing with the square of the speed".into();
    }
    if function == "1" {
        return "a constant torque".into();
    }
    let factors: Vec<&str> = function.split(" * ").collect();
    format!("the product of {}", factors.join(", "))
}
