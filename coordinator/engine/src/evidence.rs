//! Evidence that a calibration found what it reports: how many runs reached the best
//! objective, and which calibrated values sit on a bound of their range.

use crate::campaign::FreeParameter;
use serde::{Deserialize, Serialize};

/// Relative distance to the best objective within which a run counts as having found it.
pub const BEST_TOLERANCE: f64 = 0.01;

/// Share of a parameter's range within which a value counts as being on that bound.
pub const BOUND_TOLERANCE: f64 = 0.01;

/// The objective below which a run counts as having reached the best `best`.
pub fn best_threshold(best: f64) -> f64 {
    best + BEST_TOLERANCE * best.abs() + f64::MIN_POSITIVE
}

/// How many of the runs reached the best objective within [`BEST_TOLERANCE`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RunsAtBest {
    pub count: usize,
    pub of: usize,
    pub tolerance: f64,
}

/// Count the `objectives` within [`BEST_TOLERANCE`] of their minimum.
pub fn runs_at_best(objectives: &[f64]) -> RunsAtBest {
    let best = objectives.iter().copied().fold(f64::INFINITY, f64::min);
    let threshold = best_threshold(best);
    RunsAtBest {
        count: objectives.iter().filter(|&&f| f <= threshold).count(),
        of: objectives.len(),
        tolerance: BEST_TOLERANCE,
    }
}

/// Whether each of `objectives` reached the best within [`BEST_TOLERANCE`], the best
/// being the least finite one (none did when none is finite): how every table and page
/// marks the runs at the best.
pub fn at_best_flags(objectives: &[f64]) -> Vec<bool> {
    let best = objectives
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .fold(f64::INFINITY, f64::min);
    if !best.is_finite() {
        return vec![false; objectives.len()];
    }
    let threshold = best_threshold(best);
    objectives.iter().map(|&f| f <= threshold).collect()
}

/// The bound of its range a value sits on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Bound {
    Min,
    Max,
}

impl Bound {
    /// `lower` or `upper`, for sentences.
    pub fn word(self) -> &'static str {
        match self {
            Bound::Min => "lower",
            Bound::Max => "upper",
        }
    }
}

/// The bound `value` sits on, if any: within [`BOUND_TOLERANCE`] of the range `[min, max]`
/// from it and, when the start value `nominal` lies off that bound, within the same share of
/// the way from `nominal` to it. The second test keeps a small value that the data resolve
/// well above a bound at 0 (a friction of 0.0012 in [0, 0.9] from 0.002) from counting as
/// pressed against it.
pub fn at_bound(value: f64, nominal: f64, min: f64, max: f64) -> Option<Bound> {
    let reach = BOUND_TOLERANCE * (max - min);
    if reach.is_nan() || reach <= 0.0 || !value.is_finite() {
        return None;
    }
    let near = |distance: f64, travel: f64| {
        distance <= reach && (travel <= 0.0 || distance <= BOUND_TOLERANCE * travel)
    };
    if near(value - min, nominal - min) {
        Some(Bound::Min)
    } else if near(max - value, max - nominal) {
        Some(Bound::Max)
    } else {
        None
    }
}

/// A calibrated parameter on a bound of its range.
#[derive(Debug, Clone, PartialEq)]
pub struct BoundHit {
    pub name: String,
    pub value: f64,
    pub bound: Bound,
    /// The bound's value.
    pub limit: f64,
    /// Whether the parameter is an effect (absent at 0).
    pub effect: bool,
}

/// The parameters of `free` whose value in `point` lies on a bound.
pub fn bound_hits(free: &[FreeParameter], point: &[f64]) -> Vec<BoundHit> {
    free.iter()
        .zip(point)
        .filter_map(|(p, &v)| {
            at_bound(v, p.nominal, p.min, p.max).map(|bound| BoundHit {
                name: p.name.clone(),
                value: v,
                bound,
                limit: match bound {
                    Bound::Min => p.min,
                    Bound::Max => p.max,
                },
                effect: p.effect,
            })
        })
        .collect()
}

/// What a value on its bound means, in one sentence a person can act on.
pub fn bound_sentence(hit: &BoundHit) -> String {
    if hit.bound == Bound::Min && hit.limit == 0.0 {
        return format!(
            "`{}` = {:.6e} sits on its lower bound 0: the data want none of it (or a negative value, which its range forbids); if that term should be there, question the model rather than the bound.",
            hit.name, hit.value
        );
    }
    if hit.effect && hit.bound == Bound::Max {
        return format!(
            "`{}` = {:.6e} sits on the upper bound {} of the range searched: the effect may be larger still; free it with an [[effects]] entry and a wider max to find out.",
            hit.name, hit.value, hit.limit
        );
    }
    let widen = match hit.bound {
        Bound::Min => "lower it",
        Bound::Max => "raise it",
    };
    format!(
        "`{}` = {:.6e} sits on its {} bound {}: this is not a fit but a limit, so either the bound is wrong ({widen} and calibrate again) or the model lacks what this parameter is compensating for.",
        hit.name,
        hit.value,
        hit.bound.word(),
        hit.limit
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn free(name: &str, min: f64, max: f64) -> FreeParameter {
        FreeParameter {
            name: name.into(),
            index: 0,
            nominal: min,
            min,
            max,
            effect: false,
            scale: crate::campaign::Scale::Lin,
            experiment: None,
        }
    }

    #[test]
    fn runs_within_one_percent_of_the_best_count() {
        let found = runs_at_best(&[2.0, 1.0, 1.0099, 1.0101, 1e30]);
        assert_eq!(
            found,
            RunsAtBest {
                count: 2,
                of: 5,
                tolerance: 0.01
            }
        );
    }

    #[test]
    fn flags_mark_the_runs_within_one_percent_of_the_least_finite_objective() {
        let flags = at_best_flags(&[2.0, 1.0, f64::INFINITY, 1.0099, f64::NAN, 1.0101]);
        assert_eq!(flags, [false, true, false, true, false, false]);
        assert_eq!(
            at_best_flags(&[f64::INFINITY, f64::INFINITY]),
            [false, false]
        );
    }

    #[test]
    fn a_perfect_fit_counts_only_exact_runs() {
        assert_eq!(runs_at_best(&[0.0, 0.0, 1e-300]).count, 2);
        assert_eq!(runs_at_best(&[]).count, 0);
    }

    #[test]
    fn values_within_one_percent_of_the_range_are_on_a_bound() {
        // Started on the bound (an effect, absent at 0): the range alone decides.
        assert_eq!(at_bound(0.0, 0.0, 0.0, 0.9), Some(Bound::Min));
        assert_eq!(at_bound(0.009, 0.0, 0.0, 0.9), Some(Bound::Min));
        assert_eq!(at_bound(0.0091, 0.0, 0.0, 0.9), None);
        assert_eq!(at_bound(0.45, 0.45, 0.0, 0.9), None);
        assert_eq!(at_bound(0.8911, 0.5, 0.0, 0.9), None);
        assert_eq!(at_bound(0.8971, 0.5, 0.0, 0.9), Some(Bound::Max));
        assert_eq!(at_bound(4.999, 1.0, 0.1, 5.0), Some(Bound::Max));
        assert_eq!(at_bound(4.9, 1.0, 0.1, 5.0), None);
        assert_eq!(at_bound(f64::NAN, 1.0, 0.1, 5.0), None);
        assert_eq!(at_bound(1.0, 1.0, 1.0, 1.0), None);
    }

    #[test]
    fn a_small_value_resolved_above_zero_is_not_on_its_bound() {
        // Close to 0 on the scale of the range, but far from it on the scale of the start.
        assert_eq!(at_bound(0.00117, 0.002, 0.0, 0.9), None);
        assert_eq!(at_bound(1e-7, 0.002, 0.0, 0.9), Some(Bound::Min));
        assert_eq!(at_bound(0.0, 0.002, 0.0, 0.9), Some(Bound::Min));
    }

    #[test]
    fn hits_name_the_parameter_and_the_bound() {
        let params = [
            free("a", 0.1, 5.0),
            free("b", 0.1, 5.0),
            free("c", 0.0, 1.0),
        ];
        let hits = bound_hits(&params, &[5.0, 1.4, 0.001]);
        assert_eq!(hits.len(), 2);
        assert_eq!((hits[0].name.as_str(), hits[0].bound), ("a", Bound::Max));
        assert_eq!(hits[0].limit, 5.0);
        assert_eq!((hits[1].name.as_str(), hits[1].bound), ("c", Bound::Min));
        let upper = bound_sentence(&hits[0]);
        assert!(upper.contains("upper bound 5:"), "{upper}");
        assert!(upper.contains("raise it"), "{upper}");
        let zero = bound_sentence(&hits[1]);
        assert!(zero.contains("lower bound 0"), "{zero}");
        assert!(zero.contains("none of it"), "{zero}");
        let effect = BoundHit {
            effect: true,
            ..hits[0].clone()
        };
        assert!(bound_sentence(&effect).contains("[[effects]]"));
    }
}
