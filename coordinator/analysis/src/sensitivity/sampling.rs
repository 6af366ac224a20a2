//! Sample designs in the unit box of the scaled parameter space and the estimators that read
//! them: Morris elementary effects and Sobol indices (Saltelli sampling, Jansen estimators,
//! bootstrap confidence intervals).

use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Levels of the Morris grid: each coordinate takes values k/(LEVELS − 1).
pub const MORRIS_LEVELS: usize = 4;

/// The Morris step: half the levels, `p / (2 (p − 1))` = 2/3 of the box for four levels.
pub fn morris_delta() -> f64 {
    MORRIS_LEVELS as f64 / (2.0 * (MORRIS_LEVELS as f64 - 1.0))
}

/// `trajectories` Morris trajectories of `dim + 1` unit-box points each, one after the
/// other: each starts on the grid and moves one coordinate at a time (in a random order) by
/// ±Δ, staying on the grid and inside the box.
pub fn morris_design(dim: usize, trajectories: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let delta = morris_delta();
    let step = 1.0 / (MORRIS_LEVELS as f64 - 1.0);
    // Start levels from which +Δ stays in the box.
    let low_levels = (0..MORRIS_LEVELS)
        .map(|k| k as f64 * step)
        .filter(|x| x + delta <= 1.0 + 1e-12)
        .collect::<Vec<_>>();
    let mut points = Vec::with_capacity(trajectories * (dim + 1));
    for _ in 0..trajectories {
        let mut x: Vec<f64> = Vec::with_capacity(dim);
        let mut up = Vec::with_capacity(dim);
        for _ in 0..dim {
            let low = low_levels[rng.random_range(0..low_levels.len())];
            let upward = rng.random_bool(0.5);
            x.push(if upward { low } else { low + delta });
            up.push(upward);
        }
        let mut order: Vec<usize> = (0..dim).collect();
        order.shuffle(&mut rng);
        points.push(x.clone());
        for &i in &order {
            x[i] += if up[i] { delta } else { -delta };
            points.push(x.clone());
        }
    }
    points
}

/// Morris statistics of one quantity for each parameter.
#[derive(Debug, Clone, PartialEq)]
pub struct MorrisEffects {
    /// Mean of the elementary effects.
    pub mu: Vec<f64>,
    /// Mean of their absolute values.
    pub mu_star: Vec<f64>,
    /// Their standard deviation (sample, n − 1).
    pub sigma: Vec<f64>,
    /// Elementary effects used per parameter (those between two evaluated points).
    pub effects: Vec<usize>,
}

/// Elementary effects of a [`morris_design`] (`points`) whose quantity is `values`
/// (`None` where the evaluation failed: the effects that need that point are left out).
/// An effect is the change of the quantity divided by the step in the unit box.
pub fn morris_effects(points: &[Vec<f64>], values: &[Option<f64>], dim: usize) -> MorrisEffects {
    let mut effects: Vec<Vec<f64>> = vec![Vec::new(); dim];
    for (t, chunk) in points.chunks(dim + 1).enumerate() {
        let base = t * (dim + 1);
        for k in 0..dim {
            let (a, b) = (&chunk[k], &chunk[k + 1]);
            let i = (0..dim)
                .find(|&i| a[i] != b[i])
                .expect("consecutive trajectory points differ in one coordinate");
            if let (Some(fa), Some(fb)) = (values[base + k], values[base + k + 1]) {
                effects[i].push((fb - fa) / (b[i] - a[i]));
            }
        }
    }
    let mean = |v: &[f64]| {
        if v.is_empty() {
            f64::NAN
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        }
    };
    let mu: Vec<f64> = effects.iter().map(|e| mean(e)).collect();
    let mu_star = effects
        .iter()
        .map(|e| mean(&e.iter().map(|x| x.abs()).collect::<Vec<_>>()))
        .collect();
    let sigma = effects
        .iter()
        .zip(&mu)
        .map(|(e, m)| {
            if e.len() < 2 {
                0.0
            } else {
                (e.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (e.len() - 1) as f64).sqrt()
            }
        })
        .collect();
    MorrisEffects {
        mu,
        mu_star,
        sigma,
        effects: effects.iter().map(Vec::len).collect(),
    }
}

/// The Saltelli design of `n` base samples in `dim` dimensions, as one list of unit-box
/// points: the rows of A (`n`), then those of B (`n`), then for each parameter i the rows
/// of AB_i (A with column i taken from B), `n (dim + 2)` points in all. A and B are the two
/// halves of one Owen-scrambled Sobol sequence in `2 dim` dimensions, seeded by `seed`.
pub fn saltelli_design(dim: usize, n: usize, seed: u64) -> Vec<Vec<f64>> {
    let scramble = ((seed ^ (seed >> 32)) as u32) ^ 0x5A17_E111;
    let row = |j: usize, offset: usize| -> Vec<f64> {
        (0..dim)
            .map(|d| {
                f64::from(sobol_burley::sample(
                    j as u32 + 1,
                    (offset + d) as u32,
                    scramble,
                ))
            })
            .collect()
    };
    let a: Vec<Vec<f64>> = (0..n).map(|j| row(j, 0)).collect();
    let b: Vec<Vec<f64>> = (0..n).map(|j| row(j, dim)).collect();
    let mut points = Vec::with_capacity(n * (dim + 2));
    points.extend(a.iter().cloned());
    points.extend(b.iter().cloned());
    for i in 0..dim {
        for j in 0..n {
            let mut p = a[j].clone();
            p[i] = b[j][i];
            points.push(p);
        }
    }
    points
}

/// The largest base sample a Saltelli design takes (the Sobol sequence's indices 1 to
/// 2^16 − 1), and the most dimensions (twice the parameters).
pub const SALTELLI_MAX_SAMPLES: usize = (1 << 16) - 1;
pub const SALTELLI_MAX_DIMENSIONS: usize = sobol_burley::NUM_DIMENSIONS as usize;

// The coordinator's bound on a sensitivity request's samples fits the design.
const _: () = assert!(calib_engine::limits::MAX_SENSITIVITY_SAMPLES <= SALTELLI_MAX_SAMPLES);

/// Sobol indices of one quantity, with bootstrap confidence intervals (95 %).
#[derive(Debug, Clone, PartialEq)]
pub struct SobolIndices {
    pub first: Vec<f64>,
    pub first_ci: Vec<(f64, f64)>,
    pub total: Vec<f64>,
    pub total_ci: Vec<(f64, f64)>,
    /// Variance of the quantity over the sample.
    pub variance: f64,
}

/// Bootstrap resamples behind each confidence interval.
pub const BOOTSTRAP_RESAMPLES: usize = 500;

/// Sobol indices from the values of a [`saltelli_design`] of `n` base samples (`values` in
/// the design's order; `None` where the evaluation failed: every base sample j with a failed
/// point among A_j, B_j and AB_i,j is left out whole). Jansen's estimators:
/// `V_T,i = Σ (f(A) − f(AB_i))² / 2n`, `V_i = V − Σ (f(B) − f(AB_i))² / 2n`, divided by the
/// variance `V` of f over A and B. A quantity that does not vary gets indices of 0.
pub fn sobol_indices(values: &[Option<f64>], dim: usize, n: usize, seed: u64) -> SobolIndices {
    let at = |block: usize, j: usize| values[block * n + j];
    let kept: Vec<usize> = (0..n)
        .filter(|&j| (0..dim + 2).all(|block| at(block, j).is_some()))
        .collect();
    let fa: Vec<f64> = kept.iter().map(|&j| at(0, j).unwrap()).collect();
    let fb: Vec<f64> = kept.iter().map(|&j| at(1, j).unwrap()).collect();
    let fab: Vec<Vec<f64>> = (0..dim)
        .map(|i| kept.iter().map(|&j| at(2 + i, j).unwrap()).collect())
        .collect();
    let rows: Vec<usize> = (0..kept.len()).collect();
    let (first, total, variance) = jansen(&fa, &fb, &fab, &rows);
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0xB007_57A9);
    let mut first_draws = vec![Vec::with_capacity(BOOTSTRAP_RESAMPLES); dim];
    let mut total_draws = vec![Vec::with_capacity(BOOTSTRAP_RESAMPLES); dim];
    if !kept.is_empty() {
        for _ in 0..BOOTSTRAP_RESAMPLES {
            let sample: Vec<usize> = (0..kept.len())
                .map(|_| rng.random_range(0..kept.len()))
                .collect();
            let (s, t, _) = jansen(&fa, &fb, &fab, &sample);
            for i in 0..dim {
                first_draws[i].push(s[i]);
                total_draws[i].push(t[i]);
            }
        }
    }
    SobolIndices {
        first,
        first_ci: first_draws.iter_mut().map(|d| interval(d)).collect(),
        total,
        total_ci: total_draws.iter_mut().map(|d| interval(d)).collect(),
        variance,
    }
}

/// Jansen's first-order and total indices over the base samples `rows` (with repeats for a
/// bootstrap resample), and the variance.
fn jansen(fa: &[f64], fb: &[f64], fab: &[Vec<f64>], rows: &[usize]) -> (Vec<f64>, Vec<f64>, f64) {
    let dim = fab.len();
    let m = rows.len() as f64;
    if rows.is_empty() {
        return (vec![f64::NAN; dim], vec![f64::NAN; dim], f64::NAN);
    }
    let mean = rows.iter().map(|&j| fa[j] + fb[j]).sum::<f64>() / (2.0 * m);
    let variance = rows
        .iter()
        .map(|&j| (fa[j] - mean).powi(2) + (fb[j] - mean).powi(2))
        .sum::<f64>()
        / (2.0 * m);
    let scale = mean.abs().max(1.0);
    if variance.is_nan() || variance <= 1e-24 * scale * scale {
        return (vec![0.0; dim], vec![0.0; dim], variance.max(0.0));
    }
    let mut first = Vec::with_capacity(dim);
    let mut total = Vec::with_capacity(dim);
    for f in fab {
        let t = rows.iter().map(|&j| (fa[j] - f[j]).powi(2)).sum::<f64>() / (2.0 * m);
        let s = variance - rows.iter().map(|&j| (fb[j] - f[j]).powi(2)).sum::<f64>() / (2.0 * m);
        first.push(s / variance);
        total.push(t / variance);
    }
    (first, total, variance)
}

/// The 2.5 % and 97.5 % quantiles of bootstrap draws.
fn interval(draws: &mut [f64]) -> (f64, f64) {
    if draws.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    draws.sort_by(f64::total_cmp);
    let q = |p: f64| draws[((p * (draws.len() - 1) as f64).round() as usize).min(draws.len() - 1)];
    (q(0.025), q(0.975))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// Ishigami's function on [−π, π]³ (a = 7, b = 0.1), from the unit box.
    fn ishigami(u: &[f64]) -> f64 {
        let x: Vec<f64> = u.iter().map(|u| -PI + 2.0 * PI * u).collect();
        x[0].sin() + 7.0 * x[1].sin().powi(2) + 0.1 * x[2].powi(4) * x[0].sin()
    }

    #[test]
    fn sobol_indices_of_the_ishigami_function_match_the_analytic_ones() {
        // Analytic: S = (0.3139, 0.4424, 0), ST = (0.5576, 0.4424, 0.2437); within 0.02 at
        // 4096 base samples (20 480 evaluations).
        let n = 4096;
        let points = saltelli_design(3, n, 7);
        assert_eq!(points.len(), n * 5);
        let values: Vec<Option<f64>> = points.iter().map(|p| Some(ishigami(p))).collect();
        let s = sobol_indices(&values, 3, n, 7);
        let tolerance = 0.02;
        for (got, want) in s.first.iter().zip([0.3139, 0.4424, 0.0]) {
            assert!((got - want).abs() < tolerance, "first {:?}", s.first);
        }
        for (got, want) in s.total.iter().zip([0.5576, 0.4424, 0.2437]) {
            assert!((got - want).abs() < tolerance, "total {:?}", s.total);
        }
        // Each interval holds its estimate and is narrow at this sample size.
        for i in 0..3 {
            for (v, (lo, hi)) in [(s.first[i], s.first_ci[i]), (s.total[i], s.total_ci[i])] {
                assert!(lo <= v && v <= hi, "{v} outside [{lo}, {hi}]");
                assert!(hi - lo < 0.15, "[{lo}, {hi}]");
            }
        }
    }

    #[test]
    fn a_parameter_without_effect_has_a_total_index_of_exactly_zero() {
        let n = 64;
        let points = saltelli_design(3, n, 1);
        let values: Vec<Option<f64>> = points
            .iter()
            .map(|p| Some(3.0 * p[0] + p[1] * p[1]))
            .collect();
        let s = sobol_indices(&values, 3, n, 1);
        assert_eq!(s.total[2], 0.0);
        assert_eq!(s.total_ci[2], (0.0, 0.0));
        assert!(s.total[0] > 0.8 && s.total[1] > 0.05, "{:?}", s.total);
    }

    #[test]
    fn failed_base_samples_are_left_out_whole() {
        let n = 256;
        let points = saltelli_design(3, n, 3);
        let all: Vec<Option<f64>> = points.iter().map(|p| Some(ishigami(p))).collect();
        let mut some_failed = all.clone();
        // Fail one point of AB_1 at base sample 5: base sample 5 goes away entirely.
        some_failed[(2 + 1) * n + 5] = None;
        let mut without: Vec<Option<f64>> = Vec::new();
        for block in 0..5 {
            for j in 0..n {
                if j != 5 {
                    without.push(all[block * n + j]);
                }
            }
        }
        let a = sobol_indices(&some_failed, 3, n, 3);
        let b = sobol_indices(&without, 3, n - 1, 3);
        assert_eq!(a.first, b.first);
        assert_eq!(a.total, b.total);
    }

    #[test]
    fn morris_on_a_linear_function_gives_the_coefficients() {
        let coefficients = [2.0, -0.5, 0.0, 7.0];
        let points = morris_design(4, 10, 11);
        assert_eq!(points.len(), 10 * 5);
        for p in &points {
            assert!(p.iter().all(|x| (0.0..=1.0).contains(x)), "{p:?}");
        }
        let values: Vec<Option<f64>> = points
            .iter()
            .map(|p| Some(p.iter().zip(coefficients).map(|(x, c)| x * c).sum()))
            .collect();
        let m = morris_effects(&points, &values, 4);
        for (i, c) in coefficients.iter().enumerate() {
            assert!((m.mu_star[i] - c.abs()).abs() < 1e-12, "{m:?}");
            assert!((m.mu[i] - c).abs() < 1e-12, "{m:?}");
            assert!(m.sigma[i] < 1e-12, "{m:?}");
            assert_eq!(m.effects[i], 10);
        }
    }

    #[test]
    fn morris_separates_interaction_from_linear_effects() {
        // f = x0 + x1·x2: x0's effects are all 1, x1's and x2's vary with the other one.
        let points = morris_design(3, 20, 5);
        let values: Vec<Option<f64>> = points.iter().map(|p| Some(p[0] + p[1] * p[2])).collect();
        let mut failed = values.clone();
        failed[0] = None;
        let m = morris_effects(&points, &values, 3);
        assert!(
            m.sigma[0] < 1e-12 && m.sigma[1] > 0.1 && m.sigma[2] > 0.1,
            "{m:?}"
        );
        // A failed point costs the one effect that needs it.
        let f = morris_effects(&points, &failed, 3);
        assert_eq!(f.effects.iter().sum::<usize>(), 3 * 20 - 1);
    }
}
