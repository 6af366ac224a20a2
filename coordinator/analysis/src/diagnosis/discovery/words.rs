//! A refit in words: what `calib diagnose --discover` prints and diagnosis.md holds.

use super::ProposalRefit;

/// A function of the library (or a refitted harmonic) in words.
pub fn function_in_words(function: &str) -> String {
    if let Some(inner) = function
        .strip_prefix("sign(")
        .and_then(|f| f.strip_suffix(')'))
    {
        return format!("a constant torque along the motion of {inner} (a dry friction's sign)");
    }
    for (f, what) in [("sin(", "sine"), ("cos(", "cosine")] {
        let Some(inner) = function.strip_prefix(f).and_then(|f| f.strip_suffix(')')) else {
            continue;
        };
        let (argument, phase) = match inner.split_once(" + ") {
            Some((a, p)) => (a, format!(", shifted by the phase {p}")),
            None => (inner, String::new()),
        };
        return match argument.split_once(" * ") {
            Some((m, angle)) => format!("the {what} of {m} periods per turn of {angle}{phase}"),
            None => format!("the {what} of {argument}{phase}"),
        };
    }
    if function.starts_with("abs(") {
        return "a drag growing with the square of the speed".into();
    }
    if function == "1" {
        return "a constant torque".into();
    }
    let factors: Vec<&str> = function.split(" * ").collect();
    if factors.iter().all(|f| *f == factors[0]) {
        match factors.len() {
            2 => return format!("the square of {}", factors[0]),
            3 => return format!("the cube of {}", factors[0]),
            _ => {}
        }
    }
    format!("the product of {}", factors.join(", "))
}

/// Each term of a formula `p1 * f1 + p2 * f2 + …` as (parameter, function).
fn terms(formula: &str) -> Vec<(&str, &str)> {
    let mut out = Vec::new();
    let mut depth = 0usize;
    let mut start = 0;
    let bytes = formula.as_bytes();
    for (k, &b) in bytes.iter().enumerate() {
        match b {
            b'(' => depth += 1,
            b')' => depth = depth.saturating_sub(1),
            b'+' if depth == 0 => {
                out.push(formula[start..k].trim());
                start = k + 1;
            }
            _ => {}
        }
    }
    out.push(formula[start..].trim());
    out.into_iter()
        .map(|t| t.split_once(" * ").unwrap_or((t, "1")))
        .collect()
}

/// The refit of a proposal: folded terms, the growing windows, the objective before and
/// after against the noise floor, the formula refitted in symbols and words, every
/// parameter with the effect's profile intervals, the residual left, and the block with
/// the refitted values.
pub fn refit_summary(r: &ProposalRefit) -> String {
    let mut s = String::new();
    if !r.folded.is_empty() {
        s.push_str(&format!(
            "  refit of {}: {} folded into the joint's own friction\n",
            r.effect,
            r.folded.join(", ")
        ));
    }
    s.push_str(&format!(
        "  refit of {} on growing windows (each searched from the last one's optimum):\n",
        r.effect
    ));
    for stage in &r.stages {
        s.push_str(&format!(
            "    [{:.2}, {:.2}] s  objective {:.4e}  ({}, {} evaluations)\n",
            stage.window.0, stage.window.1, stage.objective, stage.method, stage.evaluations
        ));
    }
    s.push_str(&format!(
        "  refit of {}: objective {:.4e} -> {:.4e}, {:.4} -> {:.4} times the noise floor ({:.4e}); {} evaluations\n",
        r.effect,
        r.objective_before,
        r.objective_after,
        r.ratio_before(),
        r.ratio_after(),
        r.noise_floor,
        r.evaluations
    ));
    if let Some(formula) = formula_of(&r.toml) {
        s.push_str(&format!("    formula refitted: {formula}\n"));
        for (parameter, function) in terms(&formula) {
            s.push_str(&format!(
                "      {parameter} times {}\n",
                function_in_words(function)
            ));
        }
    }
    let end = |v: Option<f64>| v.map_or_else(|| "open".to_string(), |v| format!("{v:.6e}"));
    for p in &r.parameters {
        s.push_str(&format!("    {:<32} {:>13.6e}", p.name, p.value));
        if let Some(i) = r.intervals.iter().find(|i| i.name == p.name) {
            s.push_str(&format!(
                "  profile 95% [{}, {}]  (linearised [{:.6e}, {:.6e}])",
                end(i.ci_low),
                end(i.ci_high),
                i.linearised_low,
                i.linearised_high
            ));
        }
        s.push('\n');
    }
    if let Some(t) = &r.threshold {
        s.push_str(&format!(
            "    (profile: the others re-optimised, up to a rise of the objective of {:.4e}, \
             chi-square(1) 95% x s^2 {:.4e} x N/N_eff {:.3})\n",
            t.delta, t.s2, t.inflation
        ));
    }
    for o in &r.residual {
        s.push_str(&format!(
            "    residual {:<24} rms {:.4e}  lag-1 autocorrelation {:+.3}  Ljung-Box {:.1} (white below {:.1}): {}\n",
            o.output,
            o.rms,
            o.lag1,
            o.ljung_box,
            o.ljung_box_critical,
            if o.white { "white" } else { "structured" }
        ));
    }
    if !r.toml.is_empty() {
        s.push_str("\n  the block with the refitted values:\n\n");
        s.push_str(&r.toml);
        s.push('\n');
    }
    s
}

/// The formula of an `[[effects]]` block.
fn formula_of(block: &str) -> Option<String> {
    let value: toml::Value = toml::from_str(block).ok()?;
    value["effects"][0]["formula"].as_str().map(String::from)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn functions_and_terms_read_in_words() {
        assert_eq!(
            function_in_words("sin(8 * armJoint.phi + phase1)"),
            "the sine of 8 periods per turn of armJoint.phi, shifted by the phase phase1"
        );
        assert_eq!(
            function_in_words("armJoint.w * armJoint.w * armJoint.w"),
            "the cube of armJoint.w"
        );
        assert_eq!(
            function_in_words("armJoint.phi * armJoint.w"),
            "the product of armJoint.phi, armJoint.w"
        );
        assert_eq!(
            terms("c1 * armJoint.w + amp1 * sin(8 * armJoint.phi + phase1) + c2"),
            [
                ("c1", "armJoint.w"),
                ("amp1", "sin(8 * armJoint.phi + phase1)"),
                ("c2", "1")
            ]
        );
    }
}
