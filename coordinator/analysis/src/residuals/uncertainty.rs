//! Confidence intervals of fitted parameters from the Jacobian at the optimum.
//!
//! Linearised least squares: `Cov = s² (JᵀJ)⁻¹` with `s² = SSE / (N − n)` (J weighted like
//! the objective), `(JᵀJ)⁻¹ = V Σ⁻² Vᵀ` from the singular value decomposition of `J`; when
//! `J` is rank deficient (see [`super::linear::RANK_TOLERANCE`]) every interval is
//! unbounded. A correlated residual carries fewer independent samples than its count,
//! so the covariance is widened by `N / N_eff` (see [`super::whiteness::effective_samples`]).
//! 95% intervals are `value ± 1.96 √Cov_ii`. Where a parameter's interval is wide or two
//! parameters correlate beyond ±0.95, the data cannot tell them apart; the report shows the
//! correlation matrix so a user sees it.

use super::linear::LeastSquares;
use calib_engine::campaign::FreeParameter;
use serde::Serialize;

/// A fitted parameter with its 95% confidence interval.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Interval {
    pub name: String,
    pub value: f64,
    pub ci_low: f64,
    pub ci_high: f64,
    pub std: f64,
    pub effect: bool,
}

/// Intervals and correlation matrix of `free` at `point`.
pub fn intervals(
    free: &[FreeParameter],
    point: &[f64],
    jacobian: &[Vec<f64>],
    sse: f64,
    samples: usize,
    effective_samples: f64,
) -> (Vec<Interval>, Vec<Vec<f64>>) {
    let n = free.len();
    let dof = samples.saturating_sub(n).max(1) as f64;
    let s2 = sse / dof;
    let inflation = (samples as f64 / effective_samples.max(1.0)).max(1.0);
    let cov = LeastSquares::new(jacobian).covariance();
    let std: Vec<f64> = (0..n)
        .map(|i| match &cov {
            Some(c) => (c[i][i].max(0.0) * s2 * inflation).sqrt(),
            None => f64::INFINITY,
        })
        .collect();
    let intervals = free
        .iter()
        .zip(point)
        .zip(&std)
        .map(|((p, &v), &s)| Interval {
            name: p.name.clone(),
            value: v,
            ci_low: v - 1.96 * s,
            ci_high: v + 1.96 * s,
            std: s,
            effect: p.effect,
        })
        .collect();
    let correlation = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| match &cov {
                    Some(c) if c[i][i] > 0.0 && c[j][j] > 0.0 => {
                        c[i][j] / (c[i][i] * c[j][j]).sqrt()
                    }
                    _ => f64::NAN,
                })
                .collect()
        })
        .collect();
    (intervals, correlation)
}
