//! Sparse regression: sequentially thresholded least squares (STLSQ, S. L. Brunton, J. L.
//! Proctor, J. N. Kutz, PNAS 113 (2016) 3932), its threshold chosen by cross-validation on
//! blocked folds in time, then ordinary least squares on the selected support with intervals
//! that account for correlated residuals.
//!
//! Columns are normalised to unit root mean square, so a coefficient is the RMS torque its
//! term contributes and the threshold reads in N m. Columns may form groups (a sine and a
//! cosine of one harmonic: the phase is not known in advance) that enter and leave together,
//! by the norm of their coefficients.

use nalgebra::{DMatrix, DVector};

/// The ridge of every least-squares solve inside STLSQ, relative to the normal matrix's mean
/// diagonal (STRidge, S. H. Rudy et al., Sci. Adv. 3 (2017) e1602614): collinear columns (low
/// harmonics and polynomials of an angle over a short range) would otherwise swap huge
/// opposite coefficients and defeat the threshold. The final fit on the support has none.
pub const RIDGE: f64 = 1e-3;

/// A regression problem on normalised columns: row-major `x` (n × p), `y`, and a group id per
/// column.
#[derive(Debug, Clone)]
pub struct Problem {
    pub x: DMatrix<f64>,
    pub y: DVector<f64>,
    pub groups: Vec<usize>,
    /// The sample index of each row (for blocked folds with a gap).
    pub rows: Vec<usize>,
    /// The ridge of the solves inside STLSQ ([`RIDGE`] by default).
    pub ridge: f64,
}

/// Normal equations of a subset of rows.
struct Normal {
    gram: DMatrix<f64>,
    xty: DVector<f64>,
    ridge: f64,
}

impl Normal {
    fn of(problem: &Problem, keep: &[bool]) -> Self {
        let rows: Vec<usize> = (0..problem.y.len()).filter(|&r| keep[r]).collect();
        let x = problem.x.select_rows(&rows);
        let y = problem.y.select_rows(&rows);
        Self {
            gram: x.tr_mul(&x),
            xty: x.tr_mul(&y),
            ridge: problem.ridge,
        }
    }

    /// Least squares on the columns in `support` (a tiny ridge keeps collinear columns
    /// solvable); zeros elsewhere.
    fn solve(&self, support: &[usize]) -> DVector<f64> {
        let p = self.xty.len();
        let mut out = DVector::zeros(p);
        if support.is_empty() {
            return out;
        }
        let mut g = self.gram.select_rows(support).select_columns(support);
        let b = self.xty.select_rows(support);
        let ridge = self.ridge * g.diagonal().mean().max(f64::MIN_POSITIVE);
        for i in 0..support.len() {
            g[(i, i)] += ridge;
        }
        let c = match g.clone().cholesky() {
            Some(ch) => ch.solve(&b),
            None => g
                .svd(true, true)
                .solve(&b, 1e-12)
                .unwrap_or_else(|_| b * 0.0),
        };
        for (k, &j) in support.iter().enumerate() {
            out[j] = c[k];
        }
        out
    }
}

/// The norm of each group's coefficients.
fn group_norms(c: &DVector<f64>, groups: &[usize]) -> Vec<f64> {
    let count = groups.iter().max().map_or(0, |g| g + 1);
    let mut norms = vec![0.0; count];
    for (j, g) in groups.iter().enumerate() {
        norms[*g] += c[j] * c[j];
    }
    norms.into_iter().map(f64::sqrt).collect()
}

/// STLSQ from the full least-squares solution `start`: drop every group whose coefficients'
/// norm is below `lambda`, refit on what is left, until the support no longer changes.
fn stlsq_from(
    normal: &Normal,
    start: &DVector<f64>,
    groups: &[usize],
    lambda: f64,
) -> DVector<f64> {
    let mut c = start.clone();
    let mut support: Vec<usize> = (0..c.len()).collect();
    for _ in 0..50 {
        let norms = group_norms(&c, groups);
        let next: Vec<usize> = support
            .iter()
            .copied()
            .filter(|&j| norms[groups[j]] >= lambda)
            .collect();
        if next == support {
            break;
        }
        support = next;
        c = normal.solve(&support);
    }
    c
}

/// STLSQ on all rows at threshold `lambda`.
pub fn stlsq(problem: &Problem, lambda: f64) -> DVector<f64> {
    let normal = Normal::of(problem, &vec![true; problem.y.len()]);
    let all: Vec<usize> = (0..problem.x.ncols()).collect();
    let start = normal.solve(&all);
    stlsq_from(&normal, &start, &problem.groups, lambda)
}

/// One threshold's cross-validated error: mean over folds of the test mean square, and its
/// standard error across folds.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CvPoint {
    pub threshold: f64,
    pub error: f64,
    pub standard_error: f64,
    /// Terms selected at this threshold on all rows.
    pub terms: usize,
}

/// Cross-validation of the thresholds on `folds` contiguous blocks of rows; a test block's
/// neighbours within `gap` samples are left out of its training set (the filter correlates
/// them). The grid: no term at all, then 40 thresholds from twice the RMS of `y` (no term
/// contributes more) down to a thousandth of it, in decreasing order.
pub fn cross_validate(problem: &Problem, folds: usize, gap: usize) -> Vec<CvPoint> {
    let n = problem.y.len();
    let p = problem.x.ncols();
    let all: Vec<usize> = (0..p).collect();
    let full = Normal::of(problem, &vec![true; n]);
    let full_c = full.solve(&all);
    let scale = (problem.y.norm_squared() / n.max(1) as f64)
        .sqrt()
        .max(f64::MIN_POSITIVE);
    let mut grid = vec![f64::INFINITY];
    grid.extend((0..40).map(|k| 2.0 * scale * 10f64.powf(-3.0 * k as f64 / 39.0)));
    // Per fold, the test mean square at every threshold.
    let by_fold: Vec<Vec<f64>> = (0..folds)
        .filter_map(|fold| {
            let (lo, hi) = (fold * n / folds, (fold + 1) * n / folds);
            if hi <= lo {
                return None;
            }
            let (first, last) = (problem.rows[lo], problem.rows[hi - 1]);
            let train: Vec<bool> = problem
                .rows
                .iter()
                .map(|&r| r + gap < first || r > last + gap)
                .collect();
            let normal = Normal::of(problem, &train);
            let start = normal.solve(&all);
            let test_x = problem.x.rows(lo, hi - lo);
            let test_y = problem.y.rows(lo, hi - lo);
            Some(
                grid.iter()
                    .map(|&lambda| {
                        let c = stlsq_from(&normal, &start, &problem.groups, lambda);
                        (test_y - test_x * c).norm_squared() / (hi - lo) as f64
                    })
                    .collect(),
            )
        })
        .collect();
    let folds = by_fold.len().max(1);
    let errors = (0..grid.len()).map(|g| by_fold.iter().map(|e| e[g]).collect::<Vec<f64>>());
    grid.iter()
        .zip(errors)
        .map(|(&threshold, e)| {
            let mean = e.iter().sum::<f64>() / folds as f64;
            let var = e.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (folds - 1).max(1) as f64;
            let c = stlsq_from(&full, &full_c, &problem.groups, threshold);
            CvPoint {
                threshold,
                error: mean,
                standard_error: (var / folds as f64).sqrt(),
                terms: c.iter().filter(|v| **v != 0.0).count(),
            }
        })
        .collect()
}

/// The one-standard-error rule: the largest threshold (the sparsest model) whose error is
/// within one standard error of the smallest error.
pub fn choose_threshold(cv: &[CvPoint]) -> f64 {
    let best = cv
        .iter()
        .min_by(|a, b| a.error.total_cmp(&b.error))
        .expect("a threshold grid");
    cv.iter()
        .filter(|p| p.error <= best.error + best.standard_error)
        .map(|p| p.threshold)
        .fold(best.threshold, f64::max)
}

/// Ordinary least squares on raw columns with the covariance of its coefficients, the noise
/// estimated from the residual and widened by the residual's correlation.
#[derive(Debug, Clone)]
pub struct Ols {
    pub coefficients: DVector<f64>,
    pub covariance: DMatrix<f64>,
    pub residual: DVector<f64>,
    /// Rows over the effective count of independent ones (≥ 1).
    pub inflation: f64,
}

pub fn ols(x: &DMatrix<f64>, y: &DVector<f64>, max_lag: usize) -> Option<Ols> {
    let (n, p) = x.shape();
    if n <= p + 1 {
        return None;
    }
    let gram = x.tr_mul(x);
    let inverse = gram.try_inverse()?;
    let coefficients = &inverse * x.tr_mul(y);
    let residual = y - x * &coefficients;
    let sigma2 = residual.norm_squared() / (n - p) as f64;
    let inflation = correlation_inflation(residual.as_slice(), max_lag);
    Some(Ols {
        covariance: inverse * (sigma2 * inflation),
        coefficients,
        residual,
        inflation,
    })
}

/// `1 + 2·Σ ρ_k` over the lags up to `max_lag` while the autocorrelation `ρ_k` stays positive:
/// how many rows one independent sample is worth.
pub fn correlation_inflation(r: &[f64], max_lag: usize) -> f64 {
    let n = r.len();
    let mean = r.iter().sum::<f64>() / n.max(1) as f64;
    let var: f64 = r.iter().map(|v| (v - mean).powi(2)).sum();
    if var == 0.0 {
        return 1.0;
    }
    let mut factor = 1.0;
    for lag in 1..=max_lag.min(n.saturating_sub(1)) {
        let c: f64 = (lag..n).map(|i| (r[i] - mean) * (r[i - lag] - mean)).sum();
        let rho = c / var;
        if rho <= 0.0 {
            break;
        }
        factor += 2.0 * rho;
    }
    factor
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
        // Box–Muller.
        let (u, v): (f64, f64) = (rng.random::<f64>().max(1e-300), rng.random());
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }

    /// `n` rows of `p` unit-RMS gaussian columns, `y` from `truth` (column, coefficient) plus
    /// gaussian noise of `noise`; column pairs (2k, 2k+1) from `paired` on share a group.
    fn problem(
        n: usize,
        p: usize,
        truth: &[(usize, f64)],
        noise: f64,
        paired: usize,
        seed: u64,
    ) -> Problem {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x = DMatrix::from_fn(n, p, |_, _| gaussian(&mut rng));
        let mut y = DVector::from_fn(n, |_, _| noise * gaussian(&mut rng));
        for &(j, c) in truth {
            y += x.column(j) * c;
        }
        let groups = (0..p)
            .map(|j| {
                if j < paired {
                    j
                } else {
                    paired + (j - paired) / 2
                }
            })
            .collect();
        Problem {
            x,
            y,
            groups,
            rows: (0..n).collect(),
            ridge: RIDGE,
        }
    }

    fn support(c: &DVector<f64>) -> Vec<usize> {
        (0..c.len()).filter(|&j| c[j] != 0.0).collect()
    }

    #[test]
    fn a_sparse_model_is_recovered_with_its_threshold_from_cross_validation() {
        for seed in 0..5 {
            let p = problem(600, 30, &[(3, 2.0), (11, -0.5), (20, 0.2)], 0.3, 30, seed);
            let cv = cross_validate(&p, 5, 0);
            let lambda = choose_threshold(&cv);
            let c = stlsq(&p, lambda);
            assert_eq!(support(&c), [3, 11, 20], "seed {seed}, threshold {lambda}");
            assert!(
                (c[3] - 2.0).abs() < 0.05 && (c[11] + 0.5).abs() < 0.05,
                "{c}"
            );
            // Every threshold above the chosen one loses a true term or errs more.
            assert!(cv[0].terms == 0 && cv[0].error > 1.0, "{:?}", cv[0]);
        }
    }

    #[test]
    fn pure_noise_selects_nothing() {
        for seed in 0..5 {
            let p = problem(600, 30, &[], 0.3, 30, seed);
            let cv = cross_validate(&p, 5, 0);
            let c = stlsq(&p, choose_threshold(&cv));
            assert!(support(&c).is_empty(), "seed {seed}: {:?}", support(&c));
        }
    }

    #[test]
    fn a_group_enters_whole() {
        // Columns 10, 11 form a group (a sine and a cosine); only 10 carries signal, 11 enters
        // with it.
        let p = problem(600, 20, &[(10, 1.0)], 0.3, 10, 7);
        assert_eq!(p.groups[10], p.groups[11]);
        let c = stlsq(&p, choose_threshold(&cross_validate(&p, 5, 0)));
        assert_eq!(support(&c), [10, 11]);
        assert!(c[11].abs() < 0.1, "{c}");
    }

    #[test]
    fn intervals_hold_the_truth_and_widen_for_correlated_noise() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        let n = 4000;
        let x = DMatrix::from_fn(n, 1, |i, _| (i as f64 * 0.01).sin());
        // White noise, and the same noise averaged over 21 samples (correlated).
        let white: Vec<f64> = (0..n + 20).map(|_| gaussian(&mut rng)).collect();
        let smooth: Vec<f64> = (0..n)
            .map(|i| white[i..i + 21].iter().sum::<f64>() / 21f64.sqrt())
            .collect();
        for (noise, correlated) in [(&white[..n], false), (&smooth[..], true)] {
            let y = DVector::from_fn(n, |i, _| 0.5 * x[(i, 0)] + 0.1 * noise[i]);
            let fit = ols(&x, &y, 100).unwrap();
            let half = 1.96 * fit.covariance[(0, 0)].sqrt();
            assert!(
                (fit.coefficients[0] - 0.5).abs() < half,
                "{} ± {half}",
                fit.coefficients[0]
            );
            if correlated {
                assert!(fit.inflation > 10.0, "{}", fit.inflation);
            } else {
                assert!(fit.inflation < 1.5, "{}", fit.inflation);
            }
        }
    }
}
