//! Steps 5 and 7 of a diagnosis: which refit to select, and what to conclude.
//!
//! A richer model is selected when the Bayesian information criterion, computed with the
//! effective number of independent samples of the residual, drops by at least
//! [`MIN_BIC_DECREASE`] (very strong evidence, R. E. Kass, A. E. Raftery, JASA 90 (1995)
//! 773–795) and the held-out error drops too. The residual is explained when what is left is
//! no more than noise alone leaves, by a test with a stated false-positive rate
//! ([`Floor::limit`]), and never more than [`NOISE_FACTOR`] of the noise floor.

use super::Fit;
use serde::Serialize;

/// The most an objective may exceed the noise floor and still count as noise, however few
/// the samples.
pub const NOISE_FACTOR: f64 = 1.5;

/// Chance that a fit leaving nothing but white noise is judged to leave more
/// (the noise test's false-positive rate, one-sided).
pub const NOISE_TEST_LEVEL: f64 = 0.01;

/// Standard deviation of `√N · (Σe² / (N σ̂²) − 1)` for N samples of white Gaussian noise `e`,
/// σ̂ the level [`noise_level`](crate::residuals::whiteness::noise_level) estimates from the
/// same samples. The sum of squares alone would give √2; the estimate's own spread adds to
/// it, and its correlation with the sum (both read the same noise) takes some away. Measured
/// by simulation in this module's tests (`the_noise_test_keeps_its_false_positive_rate`).
pub const RATIO_SPREAD: f64 = 1.6;

/// Share of the baseline objective removed above which a fit counts as explaining the data
/// where the record holds no measurable noise (noise-free synthetic records), so that the
/// floor is not there to compare with.
pub const NEAR_EXACT: f64 = 0.9999;

/// What a perfect model would leave, and how far above it noise alone reaches.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Floor {
    /// `Σ_i k_i N σ_i²`: the objective a perfect model leaves, on average.
    pub value: f64,
    /// The ratio objective / floor that noise alone exceeds with probability
    /// [`NOISE_TEST_LEVEL`]: `1 + z·RATIO_SPREAD·√(Σ k_i² N σ_i⁴) / (Σ k_i N σ_i²)`, at most
    /// [`NOISE_FACTOR`].
    pub limit: f64,
    /// Whether the data hold measurable noise; where they do not (every output's third
    /// differences follow its curve, not noise), the floor is not a yardstick and a fit
    /// counts as exact when it removes [`NEAR_EXACT`] of the baseline.
    pub measured: bool,
}

impl Floor {
    /// The floor of outputs with noise levels `sigma`, weights `weights`, `samples` samples
    /// each; `noisy` says whether every output's data hold measurable noise.
    pub fn new(sigma: &[f64], weights: &[f64], samples: usize, noisy: bool) -> Floor {
        let n = samples as f64;
        let value: f64 = sigma.iter().zip(weights).map(|(s, k)| k * n * s * s).sum();
        let spread: f64 = sigma
            .iter()
            .zip(weights)
            .map(|(s, k)| k * k * n * s.powi(4))
            .sum::<f64>()
            .sqrt();
        let z = crate::residuals::whiteness::normal_quantile(1.0 - NOISE_TEST_LEVEL);
        let limit = if value > 0.0 {
            (1.0 + z * RATIO_SPREAD * spread / value).min(NOISE_FACTOR)
        } else {
            NOISE_FACTOR
        };
        Floor {
            value,
            limit,
            measured: noisy && value > 0.0,
        }
    }

    /// Whether an objective is no more than noise alone leaves.
    pub fn holds(&self, objective: f64) -> bool {
        objective <= self.limit * self.value
    }
}

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

/// Whether `fit` leaves nothing but noise: no more than noise alone leaves above the floor
/// ([`Floor::holds`]), or, where the record holds no measurable noise, [`NEAR_EXACT`] of the
/// baseline removed.
pub fn explains(fit: &Fit, baseline: &Fit, floor: &Floor) -> bool {
    floor.holds(fit.objective)
        || (!floor.measured
            && (baseline.objective - fit.objective) >= NEAR_EXACT * baseline.objective)
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
pub fn judge(baseline: &Fit, chosen: Option<&Fit>, floor: &Floor) -> (Verdict, f64) {
    let verdict = match chosen {
        None => Verdict::Unexplained,
        Some(fit) if explains(fit, baseline, floor) => Verdict::Explained,
        Some(_) => Verdict::Partial,
    };
    let after = chosen.map_or(baseline.objective, |f| f.objective);
    let excess = (baseline.objective - floor.value).max(f64::MIN_POSITIVE);
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
    /// The ratio to the floor that noise alone exceeds only rarely ([`Floor::limit`]).
    pub noise_limit: f64,
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
            "Partly explained: {} removes {:.0}% of the residual above the noise floor (objective {:.4e} -> {:.4e}, still {:.2}x the noise floor, above the {:.2}x that noise alone leaves but {:.0}% of the time). Something the candidates do not describe is missing too.",
            o.selected.join(" + "),
            100.0 * o.explained_fraction,
            baseline.objective,
            fin.objective,
            ratio,
            o.noise_limit,
            100.0 * NOISE_TEST_LEVEL
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
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::Normal;

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

    /// A floor of value 1 whose noise test allows `limit`.
    fn floor(limit: f64, measured: bool) -> Floor {
        Floor {
            value: 1.0,
            limit,
            measured,
        }
    }

    #[test]
    fn the_verdict_follows_the_noise_floor() {
        let baseline = scored(&[], 2, 10.0, 4.0, N);
        let few = floor(NOISE_FACTOR, true);
        assert_eq!(judge(&baseline, None, &few), (Verdict::Unexplained, 0.0));
        let close = scored(&["a"], 3, 1.4, 1.0, N);
        let (verdict, fraction) = judge(&baseline, Some(&close), &few);
        assert_eq!(verdict, Verdict::Explained);
        assert!((fraction - 8.6 / 9.0).abs() < 1e-12, "{fraction}");
        // With many samples, 1.4x the floor is more than noise leaves.
        assert_eq!(
            judge(&baseline, Some(&close), &floor(1.05, true)).0,
            Verdict::Partial
        );
        let half = scored(&["a"], 3, 5.5, 2.0, N);
        let (verdict, fraction) = judge(&baseline, Some(&half), &few);
        assert_eq!(verdict, Verdict::Partial);
        assert!((fraction - 0.5).abs() < 1e-12, "{fraction}");
        // 99.999% of the baseline removed: exact where the record holds no noise to compare
        // with, and not where it does, however large the baseline.
        let exact = scored(&["a"], 3, 1e-4, 1e-5, N);
        let huge = scored(&[], 2, 1e5, 4.0, N);
        let tiny = Floor {
            value: 1e-6,
            ..floor(1.05, false)
        };
        assert_eq!(judge(&huge, Some(&exact), &tiny).0, Verdict::Explained);
        let measured = Floor {
            measured: true,
            ..tiny
        };
        assert_eq!(judge(&huge, Some(&exact), &measured).0, Verdict::Partial);
    }

    /// Residuals of a perfect model of a swinging output: its record is the swing plus white
    /// noise of `sigma`, quantised to `count`; the residual is the record minus the swing.
    fn perfect_fit(rng: &mut ChaCha8Rng, n: usize, sigma: f64, count: f64) -> (Vec<f64>, Vec<f64>) {
        let normal = Normal::new(0.0, sigma).expect("a finite standard deviation");
        let swing = |i: usize| {
            let t = i as f64 * 0.01;
            0.8 * (5.5 * t).sin() * (-0.05 * t).exp()
        };
        let record: Vec<f64> = (0..n)
            .map(|i| ((swing(i) + rng.sample(normal)) / count).round() * count)
            .collect();
        let residual = record
            .iter()
            .enumerate()
            .map(|(i, r)| r - swing(i))
            .collect();
        (record, residual)
    }

    #[test]
    fn the_noise_test_keeps_its_false_positive_rate() {
        use crate::residuals::whiteness::{holds_noise, noise_level};
        let mut rng = ChaCha8Rng::seed_from_u64(2027);
        let count = 2.0 * std::f64::consts::PI / 4096.0;
        let trials = 600;
        let n = 3000;
        let (mut rejected, mut deviations) = (0, Vec::new());
        for trial in 0..trials {
            // Two outputs, the noise of each 1–4 mrad, as the randomised benchmark draws it.
            let sigma = [0.001 + 0.003 * (trial % 7) as f64 / 6.0, 0.002];
            let fits: Vec<_> = sigma
                .iter()
                .map(|s| perfect_fit(&mut rng, n, *s, count))
                .collect();
            let levels: Vec<f64> = fits.iter().map(|(r, _)| noise_level(r)).collect();
            assert!(fits.iter().all(|(r, _)| holds_noise(r)));
            let floor = Floor::new(&levels, &[1.0, 1.0], n, true);
            let objective: f64 = fits.iter().flat_map(|(_, e)| e.iter().map(|x| x * x)).sum();
            if !floor.holds(objective) {
                rejected += 1;
            }
            deviations.push((objective / floor.value - 1.0) / (floor.limit - 1.0));
        }
        // The limit sits z(0.99) = 2.33 standard deviations above 1 if RATIO_SPREAD is right.
        let mean = deviations.iter().sum::<f64>() / trials as f64;
        let sd =
            (deviations.iter().map(|d| (d - mean).powi(2)).sum::<f64>() / trials as f64).sqrt();
        let z = crate::residuals::whiteness::normal_quantile(1.0 - NOISE_TEST_LEVEL);
        assert!(
            (sd * z - 1.0).abs() < 0.12,
            "the ratio's spread is {:.3} of RATIO_SPREAD's",
            sd * z
        );
        assert!(mean.abs() * z < 0.25, "the ratio is biased: {mean}");
        // 1% of 600 is 6; more than 15 would be a rate of 2.5%.
        assert!(
            rejected <= 15,
            "{rejected} of {trials} perfect fits called more than noise"
        );
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
            noise_limit: 1.05,
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
