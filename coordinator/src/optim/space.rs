//! The normalised search space: every free parameter mapped from its bounds to [0, 1].
//!
//! Optimisers search the unit box so that one step size and one tolerance fit parameters of
//! any scale. Methods that may step outside the box (Nelder–Mead's reflections) see the
//! objective folded back into it: a point `u` outside [0, 1] is mapped to its mirror image,
//! so the objective stays continuous and a physical parameter never leaves its bounds.

use crate::campaign::FreeParameter;

#[derive(Debug, Clone, PartialEq)]
pub struct UnitBox {
    lower: Vec<f64>,
    upper: Vec<f64>,
}

impl UnitBox {
    pub fn new(free: &[FreeParameter]) -> Self {
        Self {
            lower: free.iter().map(|p| p.min).collect(),
            upper: free.iter().map(|p| p.max).collect(),
        }
    }

    pub fn dim(&self) -> usize {
        self.lower.len()
    }

    /// Physical values of a point of the (unbounded) search space, folded into the box.
    pub fn to_physical(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .zip(self.lower.iter().zip(&self.upper))
            .map(|(&u, (&lo, &hi))| {
                let x = lo + (hi - lo) * fold(u);
                x.clamp(lo, hi)
            })
            .collect()
    }

    /// The point of the unit box that maps to `x`.
    pub fn to_unit(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .zip(self.lower.iter().zip(&self.upper))
            .map(|(&x, (&lo, &hi))| ((x - lo) / (hi - lo)).clamp(0.0, 1.0))
            .collect()
    }
}

/// Relative size of the first steps of local methods: each coordinate moves by this fraction
/// of its distance from the lower bound (the convention of `scipy.optimize.minimize`'s
/// Nelder–Mead, which the seed used), measured in the unit box.
pub const RELATIVE_STEP: f64 = 0.05;

/// First step of a coordinate that sits on its lower bound.
pub const STEP_AT_BOUND: f64 = 0.00025;

/// First steps of a local method started at `start` (unit box): small and scaled to each
/// coordinate, so a start near a bound explores near it instead of across the box.
pub fn initial_steps(start: &[f64]) -> Vec<f64> {
    start
        .iter()
        .map(|&u| {
            if u > 0.0 {
                (RELATIVE_STEP * u).min(0.5)
            } else {
                STEP_AT_BOUND
            }
        })
        .collect()
}

/// Mirror `u` into [0, 1]: periodic with period 2, identity on [0, 1].
fn fold(u: f64) -> f64 {
    if (0.0..=1.0).contains(&u) {
        return u;
    }
    if !u.is_finite() {
        return 0.5;
    }
    let r = u.rem_euclid(2.0);
    if r > 1.0 {
        2.0 - r
    } else {
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn free(min: f64, max: f64) -> FreeParameter {
        FreeParameter {
            name: "x".into(),
            index: 0,
            nominal: min,
            min,
            max,
            effect: false,
        }
    }

    #[test]
    fn folding_keeps_points_inside_and_is_continuous() {
        let b = UnitBox::new(&[free(2.0, 4.0)]);
        assert_eq!(b.to_physical(&[0.25]), vec![2.5]);
        assert_eq!(b.to_physical(&[1.25]), vec![3.5]);
        assert_eq!(b.to_physical(&[-0.25]), vec![2.5]);
        assert_eq!(b.to_physical(&[2.25]), vec![2.5]);
        for i in -300..300 {
            let u = i as f64 * 0.01;
            let x = b.to_physical(&[u])[0];
            assert!((2.0..=4.0).contains(&x));
            let x2 = b.to_physical(&[u + 1e-9])[0];
            assert!((x2 - x).abs() < 1e-8);
        }
        assert_eq!(b.to_unit(&[3.0]), vec![0.5]);
    }
}
