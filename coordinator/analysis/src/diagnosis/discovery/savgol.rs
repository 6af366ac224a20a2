//! Savitzky–Golay filters: a least-squares polynomial fitted to a sliding window of samples,
//! read at the window's centre (its value or its slope). On a uniform grid the fit is a
//! fixed set of weights, computed once.

use nalgebra::DMatrix;

/// The weights of one window: `value` reads the fitted polynomial at the centre, `slope` its
/// first derivative (per sample; divide by the step).
#[derive(Debug, Clone)]
pub struct SavitzkyGolay {
    pub half: usize,
    value: Vec<f64>,
    slope: Vec<f64>,
}

impl SavitzkyGolay {
    /// A window of `2·half + 1` samples and a polynomial of degree `order` (< 2·half + 1).
    pub fn new(half: usize, order: usize) -> Self {
        let n = 2 * half + 1;
        assert!(
            order < n,
            "Savitzky-Golay: order {order} needs more than {n} samples"
        );
        // Abscissae scaled to [-1, 1] keep the normal matrix well conditioned.
        let scale = half.max(1) as f64;
        let v = DMatrix::from_fn(n, order + 1, |i, k| {
            ((i as f64 - half as f64) / scale).powi(k as i32)
        });
        let normal = v.transpose() * &v;
        let inverse = normal
            .try_inverse()
            .expect("a Vandermonde matrix of distinct abscissae has full rank");
        let rows = inverse * v.transpose();
        let value = rows.row(0).iter().copied().collect();
        let slope = if order >= 1 {
            rows.row(1).iter().map(|w| w / scale).collect()
        } else {
            vec![0.0; n]
        };
        Self { half, value, slope }
    }

    /// The smoothed series; NaN within `half` samples of either end (or where the window
    /// holds a NaN).
    pub fn smooth(&self, y: &[f64]) -> Vec<f64> {
        self.apply(y, &self.value, 1.0)
    }

    /// The first derivative of the series with sample step `dt`; NaN as in [`Self::smooth`].
    pub fn derivative(&self, y: &[f64], dt: f64) -> Vec<f64> {
        self.apply(y, &self.slope, 1.0 / dt)
    }

    /// The gain of "slope of the running integral" (the filter a candidate column goes
    /// through) at angular frequency `omega` [rad per sample]: 1 at 0, falling to 0 beyond the
    /// window's reach.
    pub fn integral_slope_gain(&self, omega: f64) -> f64 {
        if omega.abs() < 1e-12 {
            return 1.0;
        }
        let h = self.half as f64;
        let response: f64 = self
            .slope
            .iter()
            .enumerate()
            .map(|(k, w)| w * (omega * (k as f64 - h)).sin())
            .sum();
        (response / omega).abs()
    }

    fn apply(&self, y: &[f64], weights: &[f64], factor: f64) -> Vec<f64> {
        let h = self.half;
        (0..y.len())
            .map(|i| {
                if i < h || i + h >= y.len() {
                    return f64::NAN;
                }
                let window = &y[i - h..=i + h];
                factor * window.iter().zip(weights).map(|(a, w)| a * w).sum::<f64>()
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn polynomials_up_to_the_order_pass_exactly() {
        let f = SavitzkyGolay::new(10, 3);
        let dt = 0.01;
        let t: Vec<f64> = (0..100).map(|i| i as f64 * dt).collect();
        let y: Vec<f64> = t
            .iter()
            .map(|t| 1.0 - 2.0 * t + 3.0 * t * t - t * t * t)
            .collect();
        let s = f.smooth(&y);
        let d = f.derivative(&y, dt);
        assert!(s[..10].iter().all(|v| v.is_nan()) && s[90..].iter().all(|v| v.is_nan()));
        for i in 10..90 {
            let ti = t[i];
            assert!((s[i] - y[i]).abs() < 1e-12, "value at {i}");
            let slope = -2.0 + 6.0 * ti - 3.0 * ti * ti;
            assert!(
                (d[i] - slope).abs() < 1e-9,
                "slope at {i}: {} vs {slope}",
                d[i]
            );
        }
    }

    #[test]
    fn the_integral_slope_passes_slow_and_stops_fast_motion() {
        let f = SavitzkyGolay::new(10, 3);
        assert!((f.integral_slope_gain(0.0) - 1.0).abs() < 1e-12);
        assert!((f.integral_slope_gain(0.01) - 1.0).abs() < 1e-3);
        assert!(f.integral_slope_gain(std::f64::consts::PI) < 0.05);
    }

    #[test]
    fn noise_is_reduced() {
        // Alternating ±1 (the highest frequency) is almost removed by a 21-sample window.
        let f = SavitzkyGolay::new(10, 3);
        let y: Vec<f64> = (0..200)
            .map(|i| if i % 2 == 0 { 1.0 } else { -1.0 })
            .collect();
        let s = f.smooth(&y);
        assert!(s[10..190].iter().all(|v| v.abs() < 0.1), "{:?}", &s[10..14]);
    }
}
