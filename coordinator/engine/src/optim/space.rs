//! The normalised search space: every free parameter mapped from its bounds to [0, 1].
//!
//! Optimisers search the unit box so that one step size and one tolerance fit parameters of
//! any scale. Methods that may step outside the box (Nelder–Mead's reflections) see the
//! objective folded back into it: a point `u` outside [0, 1] is mapped to its mirror image,
//! so the objective stays continuous and a physical parameter never leaves its bounds.

use crate::campaign::{FreeParameter, Scale};

#[derive(Debug, Clone, PartialEq)]
pub struct UnitBox {
    /// Bounds on each parameter's search scale (the value, or its decimal logarithm).
    lower: Vec<f64>,
    upper: Vec<f64>,
    log: Vec<bool>,
}

impl UnitBox {
    pub fn new(free: &[FreeParameter]) -> Self {
        let log: Vec<bool> = free.iter().map(|p| p.scale == Scale::Log10).collect();
        let scaled = |x: f64, log: bool| if log { x.log10() } else { x };
        Self {
            lower: free
                .iter()
                .zip(&log)
                .map(|(p, &l)| scaled(p.min, l))
                .collect(),
            upper: free
                .iter()
                .zip(&log)
                .map(|(p, &l)| scaled(p.max, l))
                .collect(),
            log,
        }
    }

    pub fn dim(&self) -> usize {
        self.lower.len()
    }

    /// Whether parameter `i` is searched on the scale of its decimal logarithm.
    pub fn is_log(&self, i: usize) -> bool {
        self.log[i]
    }

    /// Physical bounds of parameter `i`.
    pub fn bounds(&self, i: usize) -> (f64, f64) {
        (
            self.unscale(i, self.lower[i]),
            self.unscale(i, self.upper[i]),
        )
    }

    fn unscale(&self, i: usize, v: f64) -> f64 {
        if self.log[i] {
            10f64.powf(v)
        } else {
            v
        }
    }

    /// Physical values of a point of the (unbounded) search space, folded into the box.
    pub fn to_physical(&self, u: &[f64]) -> Vec<f64> {
        u.iter()
            .enumerate()
            .map(|(i, &u)| {
                let (lo, hi) = (self.lower[i], self.upper[i]);
                let v = (lo + (hi - lo) * fold(u)).clamp(lo, hi);
                let (min, max) = self.bounds(i);
                self.unscale(i, v).clamp(min, max)
            })
            .collect()
    }

    /// The point of the unit box that maps to `x`.
    pub fn to_unit(&self, x: &[f64]) -> Vec<f64> {
        x.iter()
            .enumerate()
            .map(|(i, &x)| {
                let (lo, hi) = (self.lower[i], self.upper[i]);
                let v = if self.log[i] {
                    x.max(f64::MIN_POSITIVE).log10()
                } else {
                    x
                };
                ((v - lo) / (hi - lo)).clamp(0.0, 1.0)
            })
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
            scale: Scale::Lin,
            experiment: None,
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

    #[test]
    fn a_log10_parameter_is_searched_on_the_scale_of_its_logarithm() {
        let p = FreeParameter {
            scale: Scale::Log10,
            experiment: None,
            ..free(1e-4, 1.0)
        };
        let b = UnitBox::new(&[p]);
        assert!((b.to_physical(&[0.5])[0] - 1e-2).abs() < 1e-15);
        assert!((b.to_unit(&[1e-3])[0] - 0.25).abs() < 1e-12);
        assert_eq!(b.to_physical(&[0.0]), vec![1e-4]);
        assert_eq!(b.to_physical(&[1.0]), vec![1.0]);
        assert_eq!(b.bounds(0), (1e-4, 1.0));
        for i in 0..=100 {
            let u = i as f64 / 100.0;
            let back = b.to_unit(&b.to_physical(&[u]))[0];
            assert!((back - u).abs() < 1e-12, "{u} -> {back}");
        }
    }
}
