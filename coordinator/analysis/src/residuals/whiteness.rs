//! What is left between model and data: size, whiteness, and the noise level it is to be
//! compared with.
//!
//! - **Autocorrelation** of the residual at lags 1…K, and the Ljung–Box statistic
//!   `Q = N(N+2) Σ_k ρ_k² / (N−k)`, χ²-distributed with K degrees of freedom for white noise
//!   (G. M. Ljung, G. E. P. Box, "On a measure of lack of fit in time series models",
//!   Biometrika 65 (1978) 297–303). The residual counts as white when `Q` is below the 99%
//!   quantile (Wilson–Hilferty approximation of the χ² quantile).
//! - **Noise level from the data alone**: the k-th differences of a smooth signal sampled
//!   finely vanish as `h^k`, while those of white noise keep the variance `C(2k, k)·σ²`.
//!   The estimate is the smallest over k = 2…6 of the robust scale (1.4826 × median absolute
//!   value) of the k-th differences, divided by `√C(2k, k)`: low orders still carry signal,
//!   high orders only noise (T. Gasser, L. Sroka, C. Jennen-Steinmetz, "Residual variance and
//!   residual pattern in nonlinear regression", Biometrika 73 (1986) 625–633, for the idea).
//! - **Effective sample size** `N·(1−ρ₁)/(1+ρ₁)` of an AR(1)-like residual, used to keep
//!   information criteria and confidence intervals honest when the residual is correlated.

use serde::Serialize;

/// Largest autocorrelation lag examined.
pub const MAX_LAG: usize = 20;

/// Statistics of one output's residual.
#[derive(Debug, Clone, Serialize)]
pub struct ResidualStats {
    pub samples: usize,
    pub rms: f64,
    pub mean: f64,
    /// Autocorrelation at lags 1..=K.
    pub autocorrelation: Vec<f64>,
    pub ljung_box: f64,
    /// The 99% quantile of χ²(K) that `ljung_box` is compared with.
    pub ljung_box_critical: f64,
    pub white: bool,
}

impl ResidualStats {
    pub fn of(residual: &[f64]) -> Self {
        let n = residual.len();
        let mean = residual.iter().sum::<f64>() / n.max(1) as f64;
        let rms = (residual.iter().map(|r| r * r).sum::<f64>() / n.max(1) as f64).sqrt();
        let lags = MAX_LAG.min(n.saturating_sub(2) / 4).max(1);
        let autocorrelation = autocorrelation(residual, lags);
        let nf = n as f64;
        let ljung_box = nf
            * (nf + 2.0)
            * autocorrelation
                .iter()
                .enumerate()
                .map(|(k, r)| r * r / (nf - (k + 1) as f64))
                .sum::<f64>();
        let critical = chi_square_quantile_99(lags as f64);
        Self {
            samples: n,
            rms,
            mean,
            autocorrelation,
            ljung_box,
            ljung_box_critical: critical,
            white: ljung_box < critical,
        }
    }
}

/// Sample autocorrelation at lags 1..=`lags` (about the mean).
pub fn autocorrelation(x: &[f64], lags: usize) -> Vec<f64> {
    let n = x.len();
    let mean = x.iter().sum::<f64>() / n.max(1) as f64;
    let c0: f64 = x.iter().map(|v| (v - mean).powi(2)).sum();
    (1..=lags)
        .map(|k| {
            if c0 == 0.0 || k >= n {
                return 0.0;
            }
            let ck: f64 = (0..n - k).map(|i| (x[i] - mean) * (x[i + k] - mean)).sum();
            ck / c0
        })
        .collect()
}

/// The 99% quantile of χ²(k), by the Wilson–Hilferty approximation (good to ~1% for k ≥ 3).
pub fn chi_square_quantile_99(k: f64) -> f64 {
    const Z99: f64 = 2.326_347_874;
    let a = 2.0 / (9.0 * k);
    k * (1.0 - a + Z99 * a.sqrt()).powi(3)
}

/// Standard deviation of the measurement noise of a finely sampled signal, from the signal
/// alone (see the module documentation).
pub fn noise_level(signal: &[f64]) -> f64 {
    let mut best = f64::INFINITY;
    let mut diff: Vec<f64> = signal.to_vec();
    let mut binomial = 1.0; // C(2k, k)
    for k in 1..=6usize {
        diff = diff.windows(2).map(|w| w[1] - w[0]).collect();
        binomial = binomial * ((2 * k) * (2 * k - 1)) as f64 / (k * k) as f64;
        if k < 2 || diff.len() < 8 {
            continue;
        }
        let mut abs: Vec<f64> = diff.iter().map(|d| d.abs()).collect();
        let mid = abs.len() / 2;
        let (_, median, _) = abs.select_nth_unstable_by(mid, f64::total_cmp);
        let sigma = 1.4826 * *median / binomial.sqrt();
        best = best.min(sigma);
    }
    if best.is_finite() {
        best
    } else {
        0.0
    }
}

/// Effective number of independent samples of a residual with lag-1 autocorrelation `rho1`.
pub fn effective_samples(n: usize, rho1: f64) -> f64 {
    let rho = rho1.clamp(0.0, 0.999);
    (n as f64 * (1.0 - rho) / (1.0 + rho)).clamp(2.0_f64.min(n as f64), n as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use rand_distr::Normal;

    fn gaussian(rng: &mut ChaCha8Rng, sigma: f64) -> f64 {
        rng.sample(Normal::new(0.0, sigma).expect("a finite standard deviation"))
    }

    #[test]
    fn white_noise_is_white_and_a_sine_is_not() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let noise: Vec<f64> = (0..4000).map(|_| gaussian(&mut rng, 0.002)).collect();
        let s = ResidualStats::of(&noise);
        assert!(s.white, "Q = {} vs {}", s.ljung_box, s.ljung_box_critical);
        assert!((s.rms - 0.002).abs() < 1e-4);
        let sine: Vec<f64> = (0..4000).map(|i| (i as f64 * 0.01).sin() * 0.01).collect();
        assert!(!ResidualStats::of(&sine).white);
    }

    #[test]
    fn noise_level_is_found_under_a_swinging_signal() {
        let mut rng = ChaCha8Rng::seed_from_u64(2);
        // A pendulum-like swing at 100 Hz with 2 mrad noise.
        let signal: Vec<f64> = (0..4000)
            .map(|i| {
                let t = i as f64 * 0.01;
                2.0 * (5.5 * t).sin() * (-0.05 * t).exp() + gaussian(&mut rng, 0.002)
            })
            .collect();
        let sigma = noise_level(&signal);
        assert!((sigma / 0.002 - 1.0).abs() < 0.15, "σ = {sigma}");
    }

    #[test]
    fn chi_square_quantile_matches_tables() {
        // χ²(20) 99% = 37.566, χ²(10) 99% = 23.209.
        assert!((chi_square_quantile_99(20.0) - 37.566).abs() < 0.1);
        assert!((chi_square_quantile_99(10.0) - 23.209).abs() < 0.1);
    }
}
