//! Start points that land somewhere useful: a screening batch, then the best distinct points.
//!
//! Users type wide bounds ([0, 0.9] for a bearing friction whose value is 0.01). Quasi-random
//! starts spread evenly over such a box land mostly where nothing moves: a joint whose
//! friction holds it still makes the objective flat, and a local method started there sees
//! no slope and stops. A multistart of more than one start therefore first screens the box
//! with one batch of space-filling points (spread over every worker like any batch), then
//! starts its local searches from the best screened points that lie apart from each other,
//! in the spirit of multi-level single linkage (A. H. G. Rinnooy Kan, G. T. Timmer,
//! "Stochastic global optimization methods part II: Multi level methods", Math. Programming
//! 39 (1987) 57–78): a point starts a run only if no better start lies within the critical
//! distance of it.
//!
//! **Parameters bounded at zero.** A parameter whose range starts at 0 and whose nominal value
//! is a small part of it (at most [`SMALL_NOMINAL`] of the upper bound) is screened on a
//! logarithmic scale: the screening coordinate `s ∈ [0, 1]` maps to
//! `u = 10^(−d (1 − s))` of the range, `d` decades below the upper bound, with `d` at least
//! [`DECADES`] and at least two decades below the nominal value. Each decade then gets the
//! same share of the screening points, so values near the nominal are screened as densely as
//! the top of the range. Local methods still search the linear box, with steps relative to
//! each coordinate's distance from its bound (see [`super::space::initial_steps`]).

use super::space::UnitBox;

/// Screening points per start beyond the nominal one (default of `[search] screening`).
pub const POINTS_PER_START: usize = 40;

/// Fewest screening points per free parameter.
pub const POINTS_PER_PARAMETER: usize = 20;

/// A nominal value at most this fraction of a zero-based range is screened logarithmically.
pub const SMALL_NOMINAL: f64 = 0.05;

/// Fewest decades a logarithmically screened parameter spans below its upper bound.
pub const DECADES: f64 = 4.0;

/// The default number of screening points for `starts` starts over `dim` parameters: none
/// for a single start (the nominal point), else forty per further start, at least twenty per
/// parameter.
pub fn default_count(starts: usize, dim: usize) -> usize {
    if starts <= 1 {
        0
    } else {
        (POINTS_PER_START * (starts - 1)).max(POINTS_PER_PARAMETER * dim)
    }
}

/// How each parameter is screened: `None` linearly over the unit box, `Some(d)`
/// logarithmically over `d` decades below the upper bound.
pub fn screening_scales(space: &UnitBox, nominal_unit: &[f64]) -> Vec<Option<f64>> {
    (0..space.dim())
        .map(|i| {
            let (lo, _) = space.bounds(i);
            let u = nominal_unit[i];
            (lo == 0.0 && u > 0.0 && u <= SMALL_NOMINAL && !space.is_log(i))
                .then(|| DECADES.max(2.0 - u.log10()))
        })
        .collect()
}

/// The point of the unit box at screening coordinates `s`.
pub fn to_unit(s: &[f64], scales: &[Option<f64>]) -> Vec<f64> {
    s.iter()
        .zip(scales)
        .map(|(&s, scale)| match scale {
            Some(decades) => 10f64.powf(-decades * (1.0 - s)),
            None => s,
        })
        .collect()
}

/// The screening coordinates of a unit-box point (inverse of [`to_unit`]).
pub fn to_screening(u: &[f64], scales: &[Option<f64>]) -> Vec<f64> {
    u.iter()
        .zip(scales)
        .map(|(&u, scale)| match scale {
            Some(decades) if u > 0.0 => (1.0 + u.log10() / decades).clamp(0.0, 1.0),
            Some(_) => 0.0,
            None => u,
        })
        .collect()
}

/// `count` screening points (screening coordinates): a scrambled Sobol sequence seeded by the
/// campaign (Burley's Owen-scrambled Sobol, as the plain starts use).
pub fn screening_sample(dim: usize, count: usize, seed: u64) -> Vec<Vec<f64>> {
    // A scramble apart from the plain starts' one, so the two never coincide.
    let scramble = ((seed ^ (seed >> 32)) as u32) ^ 0x5CEE_4A11;
    (0..count)
        .map(|i| {
            (0..dim as u32)
                .map(|d| f64::from(sobol_burley::sample(i as u32 + 1, d, scramble)))
                .collect()
        })
        .collect()
}

/// Critical distance (max-norm, screening coordinates) within which a worse point does not
/// start a run of its own: half the side of a cell of a grid of `starts` cells.
pub fn critical_distance(starts: usize, dim: usize) -> f64 {
    0.5 * (starts.max(1) as f64).powf(-1.0 / dim.max(1) as f64)
}

/// Up to `wanted` start points from screened points (screening coordinates and objectives):
/// best first, each farther than `radius` from every start already taken and from every point
/// in `taken`; when too few are that far apart, the best remaining points fill up. Failed
/// points (non-finite objective) are never taken. Indices into `screened`.
pub fn select(
    screened: &[(Vec<f64>, f64)],
    taken: &[Vec<f64>],
    wanted: usize,
    radius: f64,
) -> Vec<usize> {
    let mut order: Vec<usize> = (0..screened.len())
        .filter(|&i| screened[i].1.is_finite() && screened[i].1 < f64::MAX)
        .collect();
    order.sort_by(|&a, &b| screened[a].1.total_cmp(&screened[b].1));
    let far = |p: &[f64], q: &[f64]| p.iter().zip(q).any(|(a, b)| (a - b).abs() > radius);
    let mut chosen: Vec<usize> = Vec::new();
    for &i in &order {
        if chosen.len() == wanted {
            break;
        }
        let p = &screened[i].0;
        if taken.iter().all(|t| far(p, t)) && chosen.iter().all(|&c| far(p, &screened[c].0)) {
            chosen.push(i);
        }
    }
    for &i in &order {
        if chosen.len() == wanted {
            break;
        }
        if !chosen.contains(&i) {
            chosen.push(i);
        }
    }
    chosen
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_screening_round_trips_and_covers_each_decade_evenly() {
        let scales = [Some(4.0), None];
        for s in [0.0, 0.25, 0.5, 0.75, 1.0] {
            let u = to_unit(&[s, s], &scales);
            let back = to_screening(&u, &scales);
            assert!((back[0] - s).abs() < 1e-12 && back[1] == s, "{s}: {back:?}");
        }
        assert!((to_unit(&[0.5], &[Some(4.0)])[0] - 1e-2).abs() < 1e-15);
        let sample = screening_sample(1, 400, 7);
        let units: Vec<f64> = sample.iter().map(|s| to_unit(s, &[Some(4.0)])[0]).collect();
        for decade in 0..4 {
            let (lo, hi) = (10f64.powi(-decade - 1), 10f64.powi(-decade));
            let n = units.iter().filter(|&&u| u >= lo && u < hi).count();
            assert!((90..=110).contains(&n), "decade {decade}: {n} of 400");
        }
    }

    #[test]
    fn selection_takes_the_best_distinct_points_and_never_a_failure() {
        let screened = vec![
            (vec![0.10, 0.10], 1.0),
            (vec![0.11, 0.10], 0.5), // best
            (vec![0.90, 0.90], 2.0),
            (vec![0.50, 0.50], f64::MAX), // failed
            (vec![0.12, 0.11], 0.7),      // near the best: left for last
        ];
        assert_eq!(select(&screened, &[], 2, 0.05), vec![1, 2]);
        assert_eq!(select(&screened, &[], 4, 0.05), vec![1, 2, 4, 0]);
        // A start already taken (the nominal point) keeps its neighbourhood.
        assert_eq!(select(&screened, &[vec![0.9, 0.9]], 1, 0.05), vec![1]);
        assert_eq!(select(&screened, &[vec![0.1, 0.1]], 1, 0.05), vec![2]);
    }

    #[test]
    fn only_small_nominals_of_zero_based_ranges_are_screened_logarithmically() {
        use crate::campaign::FreeParameter;
        let p = |min: f64, nominal: f64, max: f64| FreeParameter {
            name: "p".into(),
            index: 0,
            nominal,
            min,
            max,
            effect: false,
            scale: crate::campaign::Scale::Lin,
            experiment: None,
        };
        let free = [p(0.0, 0.012, 0.9), p(0.0, 0.5, 0.9), p(0.1, 0.12, 0.9)];
        let space = UnitBox::new(&free);
        let nominal: Vec<f64> = space.to_unit(&[0.012, 0.5, 0.12]);
        let scales = screening_scales(&space, &nominal);
        assert!(scales[0].is_some_and(|d| d >= DECADES));
        assert_eq!(scales[1..], [None, None]);
    }
}
