//! The Jacobian of the residuals by finite differences in the unit box.
//!
//! Column `j` is `(r(x + h e_j) − r(x)) / h`: a forward difference, or a backward one
//! (`h < 0`) where a forward step would leave the box, so no difference point lies outside
//! `[0, 1]^n`. All columns are evaluated together, in the batch of the iteration that asks
//! for them.

use super::linear::Columns;

/// The difference step in the unit box: 10⁻⁶ of a parameter's range, far above the
/// rounding of the residuals and below the curvature of any fit.
pub const STEP: f64 = 1e-6;

/// The signed step of each parameter at `x`: forward, or backward at the upper bound.
pub fn steps(x: &[f64], step: f64) -> Vec<f64> {
    x.iter()
        .map(|&v| if v + step <= 1.0 { step } else { -step })
        .collect()
}

/// The difference points around `x`, one per parameter, in order.
pub fn points(x: &[f64], steps: &[f64]) -> Vec<Vec<f64>> {
    (0..x.len())
        .map(|j| {
            let mut p = x.to_vec();
            p[j] += steps[j];
            p
        })
        .collect()
}

/// The columns from the residuals at `x` and at each difference point. A difference point
/// whose simulation failed (no residuals) gives a zero column: that parameter does not move
/// until a later Jacobian sees it.
pub fn columns(r: &[f64], around: &[Vec<f64>], steps: &[f64]) -> Columns {
    around
        .iter()
        .zip(steps)
        .map(|(rj, h)| {
            if rj.len() != r.len() {
                return vec![0.0; r.len()];
            }
            rj.iter().zip(r).map(|(a, b)| (a - b) / h).collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn steps_stay_in_the_box() {
        let x = [0.0, 0.5, 1.0, 1.0 - 1e-7];
        let h = steps(&x, STEP);
        assert_eq!(h, vec![STEP, STEP, -STEP, -STEP]);
        for p in points(&x, &h) {
            assert!(p.iter().all(|v| (0.0..=1.0).contains(v)), "{p:?}");
        }
    }

    #[test]
    fn columns_are_differences_and_failures_are_zero() {
        // r(x) = (x0², 3 x1) at (0.5, 1.0): the second step is backward.
        let x = [0.5, 1.0];
        let h = steps(&x, 1e-3);
        let r = |p: &[f64]| vec![p[0] * p[0], 3.0 * p[1]];
        let around: Vec<Vec<f64>> = points(&x, &h).iter().map(|p| r(p)).collect();
        let c = columns(&r(&x), &around, &h);
        assert!((c[0][0] - 1.0).abs() < 2e-3 && c[0][1] == 0.0, "{c:?}");
        assert!((c[1][1] - 3.0).abs() < 1e-9 && c[1][0] == 0.0, "{c:?}");
        let failed = columns(&r(&x), &[vec![], around[1].clone()], &h);
        assert_eq!(failed[0], vec![0.0, 0.0]);
    }
}
