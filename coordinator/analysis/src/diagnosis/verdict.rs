//! Steps 5 and 7 of a diagnosis: which refit to select, and what to conclude.
//!
//! A richer model is selected when the Bayesian information criterion, computed with the
//! effective number of independent samples of the residual, drops by at least
//! [`MIN_BIC_DECREASE`] (very strong evidence, R. E. Kass, A. E. Raftery, JASA 90 (1995)
//! 773–795) and the held-out error drops too. The residual is explained when what is left is
//! within [`NOISE_FACTOR`] of the noise floor.

use super::Fit;
use serde::Serialize;

/// An objective within this factor of the noise floor counts as explained by noise.
pub const NOISE_FACTOR: f64 = 1.5;

/// Share of the baseline objective removed above which a fit counts as explaining the data
/// even where the noise floor is too small to compare with (noise-free synthetic records).
pub const NEAR_EXACT: f64 = 0.9999;

/// Decrease of the information criterion that selects a richer model.
pub const MIN_BIC_DECREASE: f64 = 10.0;

/// What the diagnosis concluded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// The baseline leaves only noise: nothing is missing.
    Noise,
    /// The selected effects bring the error down to the noise.
    Explained,
    /// The selected effects remove part of the residual; something else is missing too.
    Partial,
    /// No candidate removes enough of the residual.
    Unexplained,
}

/// Whether `richer` beats `simpler`: a decisive drop of the information criterion and a
/// lower held-out error.
pub fn improves(richer: &Fit, simpler: &Fit) -> bool {
    // Both criteria with the richer model's effective sample count, so the difference is a
    // likelihood ratio plus the penalty of the extra parameters.
    let n = richer.effective_samples;
    let extra = (richer.parameters.len() as f64 - simpler.parameters.len() as f64).max(0.0);
    let delta_bic = n
        * (richer.objective.max(f64::MIN_POSITIVE) / simpler.objective.max(f64::MIN_POSITIVE)).ln()
        + extra * n.ln();
    delta_bic <= -MIN_BIC_DECREASE && richer.held_out_objective < simpler.held_out_objective
}

/// Whether `fit` leaves nothing but noise: within [`NOISE_FACTOR`] of the floor, or (where
/// the floor is too small to compare with) [`NEAR_EXACT`] of the baseline removed.
pub fn explains(fit: &Fit, baseline: &Fit, noise_floor: f64) -> bool {
    fit.objective <= NOISE_FACTOR * noise_floor
        || (baseline.objective - fit.objective) >= NEAR_EXACT * baseline.objective
}

/// The refit to select: the best single effect that improves on the baseline (without such
/// a single, the best pair that does: a pair may succeed where each effect alone falls
/// short), then, as long as one improves on the set chosen so far, the best refit of one
/// effect more that contains it. "Best" is the lowest refitted objective (between fits of as
/// many parameters, the lowest information criterion), ties broken by the effects' names:
/// never the order the refits ran in.
pub fn select<'a>(baseline: &Fit, refits: &'a [Fit]) -> Option<&'a Fit> {
    let lowest = |fits: Vec<&'a Fit>| {
        fits.into_iter().min_by(|a, b| {
            a.objective
                .total_cmp(&b.objective)
                .then_with(|| a.effects.cmp(&b.effects))
        })
    };
    let of_size = |n: usize, over: &Fit| -> Option<&'a Fit> {
        lowest(
            refits
                .iter()
                .filter(|f| f.effects.len() == n && improves(f, over))
                .filter(|f| over.effects.iter().all(|e| f.effects.contains(e)))
                .collect(),
        )
    };
    let mut chosen = of_size(1, baseline).or_else(|| of_size(2, baseline))?;
    while let Some(richer) = of_size(chosen.effects.len() + 1, chosen) {
        chosen = richer;
    }
    Some(chosen)
}

/// The verdict on the `chosen` refit (none: unexplained), and the share of the baseline's
/// excess over the noise floor that it removes.
pub fn judge(baseline: &Fit, chosen: Option<&Fit>, noise_floor: f64) -> (Verdict, f64) {
    let verdict = match chosen {
        None => Verdict::Unexplained,
        Some(fit) if explains(fit, baseline, noise_floor) => Verdict::Explained,
        Some(_) => Verdict::Partial,
    };
    let after = chosen.map_or(baseline.objective, |f| f.objective);
    let excess = (baseline.objective - noise_floor).max(f64::MIN_POSITIVE);
    let explained_fraction = ((baseline.objective - after) / excess).clamp(0.0, 1.0);
    (verdict, explained_fraction)
}

/// What a verdict sentence is made of.
pub struct Outcome<'a> {
    pub verdict: Verdict,
    pub selected: &'a [String],
    pub baseline: &'a Fit,
    pub final_fit: &'a Fit,
    pub noise_floor: f64,
    pub explained_fraction: f64,
}

/// One sentence a person can act on.
pub fn sentence(o: &Outcome) -> String {
    let (baseline, fin) = (o.baseline, o.final_fit);
    let ratio = fin.objective / o.noise_floor;
    match o.verdict {
        Verdict::Noise => format!(
            "The residual is consistent with sensor noise: the objective {:.4e} is {:.2}x the noise floor {:.4e} estimated from the data. Nothing is missing from the model; nothing was added.",
            baseline.objective, baseline.objective / o.noise_floor, o.noise_floor
        ),
        Verdict::Explained => format!(
            "Missing physics found: {}. Adding it brings the objective from {:.4e} to {:.4e} ({:.1}x lower, {:.2}x the noise floor) and the held-out objective from {:.4e} to {:.4e}.",
            o.selected.join(" + "),
            baseline.objective,
            fin.objective,
            baseline.objective / fin.objective,
            ratio,
            baseline.held_out_objective,
            fin.held_out_objective
        ),
        Verdict::Partial => format!(
            "Partly explained: {} removes {:.0}% of the residual above the noise floor (objective {:.4e} -> {:.4e}, still {:.2}x the noise floor, above the {NOISE_FACTOR}x that noise would leave). Something the candidates do not describe is missing too.",
            o.selected.join(" + "),
            100.0 * o.explained_fraction,
            baseline.objective,
            fin.objective,
            ratio
        ),
        Verdict::Unexplained => format!(
            "No candidate explains the residual: the objective {:.4e} is {:.2}x the noise floor, and no effect (alone or in pairs) lowers the information criterion decisively while also lowering the held-out error. The best attempt is listed below; the missing piece lies outside the candidate library.",
            baseline.objective,
            baseline.objective / o.noise_floor
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::testing::scored;

    const N: f64 = 1000.0;

    #[test]
    fn a_richer_model_must_lower_both_the_criterion_and_the_held_out_error() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        // Halving the error: ΔBIC = 1000 ln 0.5 + ln 1000 ≈ −686.
        assert!(improves(&scored(&["a"], 3, 5.0, 3.0, N), &baseline));
        // The same fit, worse on the held-out window: over-fitting.
        assert!(!improves(&scored(&["a"], 3, 5.0, 4.5, N), &baseline));
        // 0.5% lower: ΔBIC = 1000 ln 0.995 + ln 1000 ≈ +1.9, not worth a parameter.
        assert!(!improves(&scored(&["a"], 3, 9.95, 3.0, N), &baseline));
        // Fewer effective samples weigh the same drop less: 12 ln 0.5 + ln 12 ≈ −5.8.
        assert!(!improves(&scored(&["a"], 3, 5.0, 3.0, 12.0), &baseline));
    }

    #[test]
    fn the_best_single_is_selected_and_kept_over_pairs_that_do_not_contain_it() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let refits = [
            scored(&["a"], 3, 5.0, 3.0, N),
            scored(&["b"], 3, 3.0, 2.0, N),
            scored(&["a", "c"], 4, 1.0, 1.0, N),
        ];
        let chosen = select(&baseline, &refits).unwrap();
        assert_eq!(chosen.effects, ["b"]);
    }

    #[test]
    fn a_pair_with_the_best_single_replaces_it_when_it_improves_on_it() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let refits = [
            scored(&["a"], 3, 5.0, 3.0, N),
            scored(&["b"], 3, 3.0, 2.0, N),
            // 1000 ln(2.9/3) + ln 1000 ≈ −27: decisive over `b` alone.
            scored(&["a", "b"], 4, 2.9, 1.9, N),
        ];
        assert_eq!(select(&baseline, &refits).unwrap().effects, ["a", "b"]);
        // Barely better than `b`: the single stays.
        let refits = [
            scored(&["b"], 3, 3.0, 2.0, N),
            scored(&["a", "b"], 4, 2.999, 1.9, N),
        ];
        assert_eq!(select(&baseline, &refits).unwrap().effects, ["b"]);
    }

    #[test]
    fn the_selection_does_not_depend_on_the_order_the_refits_ran_in() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let mut refits = vec![
            scored(&["a"], 3, 5.0, 3.0, N),
            scored(&["b"], 3, 3.0, 2.0, N),
            scored(&["a", "b"], 4, 2.9, 1.9, N),
            scored(&["b", "c"], 4, 2.5, 1.5, N),
        ];
        assert_eq!(select(&baseline, &refits).unwrap().effects, ["b", "c"]);
        refits.reverse();
        assert_eq!(select(&baseline, &refits).unwrap().effects, ["b", "c"]);
        // Equal objectives: the names decide, not the order.
        let tied = [
            scored(&["z"], 3, 3.0, 2.0, N),
            scored(&["y"], 3, 3.0, 2.0, N),
        ];
        assert_eq!(select(&baseline, &tied).unwrap().effects, ["y"]);
    }

    #[test]
    fn one_effect_more_is_added_while_it_improves_on_the_set_chosen_so_far() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let refits = [
            scored(&["a"], 3, 5.0, 3.0, N),
            scored(&["a", "b"], 4, 3.0, 2.0, N),
            // Lower still, but without the pair chosen before it: not a step from it.
            scored(&["a", "c", "d"], 5, 0.5, 0.5, N),
            scored(&["a", "b", "c"], 5, 1.0, 1.0, N),
            // Contains the pair, but worse on the held-out window.
            scored(&["a", "b", "d"], 5, 0.9, 2.5, N),
        ];
        assert_eq!(select(&baseline, &refits).unwrap().effects, ["a", "b", "c"]);
        // Without the pair, the triples are not reached from the single.
        let no_pair: Vec<Fit> = refits
            .iter()
            .filter(|f| f.effects.len() != 2)
            .cloned()
            .collect();
        assert_eq!(select(&baseline, &no_pair).unwrap().effects, ["a"]);
    }

    #[test]
    fn a_pair_may_succeed_where_no_single_does() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let refits = [
            scored(&["a"], 3, 9.99, 3.9, N),
            scored(&["b"], 3, 12.0, 5.0, N),
            scored(&["a", "b"], 4, 2.0, 1.0, N),
        ];
        assert_eq!(select(&baseline, &refits).unwrap().effects, ["a", "b"]);
        assert!(select(&baseline, &refits[..2]).is_none());
    }

    #[test]
    fn the_verdict_follows_the_noise_floor() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let floor = 1.0;
        assert_eq!(judge(&baseline, None, floor), (Verdict::Unexplained, 0.0));
        let close = scored(&["a"], 3, 1.4, 1.0, N);
        let (verdict, fraction) = judge(&baseline, Some(&close), floor);
        assert_eq!(verdict, Verdict::Explained);
        assert!((fraction - 8.6 / 9.0).abs() < 1e-12, "{fraction}");
        let half = scored(&["a"], 3, 5.5, 2.0, N);
        let (verdict, fraction) = judge(&baseline, Some(&half), floor);
        assert_eq!(verdict, Verdict::Partial);
        assert!((fraction - 0.5).abs() < 1e-12, "{fraction}");
        // A noise-free record: nothing to compare with but the share removed.
        let exact = scored(&["a"], 3, 1e-5, 1e-5, N);
        assert_eq!(judge(&baseline, Some(&exact), 0.0).0, Verdict::Explained);
    }

    #[test]
    fn sentences_name_what_was_found_and_never_invent_an_effect() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let found = scored(&["viscous_friction.arm"], 3, 1.2, 0.5, N);
        let selected = ["viscous_friction.arm".to_string()];
        let outcome = |verdict, selected, final_fit| Outcome {
            verdict,
            selected,
            baseline: &baseline,
            final_fit,
            noise_floor: 1.0,
            explained_fraction: 0.25,
        };
        let explained = sentence(&outcome(Verdict::Explained, &selected, &found));
        assert!(explained.starts_with("Missing physics found: viscous_friction.arm."));
        assert!(explained.contains("1.0000e1 to 1.2000e0 (8.3x lower, 1.20x the noise floor)"));
        assert!(explained.contains("4.0000e0 to 5.0000e-1"), "{explained}");
        let partial = sentence(&outcome(Verdict::Partial, &selected, &found));
        assert!(partial.contains("removes 25% of the residual"), "{partial}");
        let none = sentence(&outcome(Verdict::Unexplained, &[], &baseline));
        assert!(none.starts_with("No candidate explains the residual"));
        assert!(!none.contains("viscous"), "{none}");
        let noise = sentence(&outcome(Verdict::Noise, &[], &baseline));
        assert!(noise.contains("10.00x the noise floor"), "{noise}");
    }
}
