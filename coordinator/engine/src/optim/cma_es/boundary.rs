//! Keeping CMA-ES in the unit box: projection with a penalty.
//!
//! A sample `x` outside `[0, 1]^n` is simulated at its projection `p = clamp(x, 0, 1)` (so
//! every simulated point lies in the box, as the other solvers' do), and ranked by
//! `f(p) + (|f(p)| + ε) ‖x − p‖²`: among points with the same projection, the one further out
//! ranks worse, so the mean is pulled back to the box instead of drifting beyond a bound
//! along a direction the objective cannot see. The penalty is relative to the objective, so
//! it only breaks ties and orders near-equal costs; it never outweighs a real difference
//! between two points inside the box.

/// Added to `|f|` in the penalty, so a zero objective still orders points by distance.
const EPSILON: f64 = 1e-12;

/// The projection of `x` onto the unit box.
pub fn project(x: &[f64]) -> Vec<f64> {
    x.iter().map(|v| v.clamp(0.0, 1.0)).collect()
}

/// The ranking cost of a sample `x` whose projection scored `cost` (already sanitized: a
/// failure is `f64::MAX` and stays so).
pub fn penalised(x: &[f64], cost: f64) -> f64 {
    if cost >= f64::MAX {
        return cost;
    }
    let outside: f64 = x
        .iter()
        .map(|v| {
            let d = v - v.clamp(0.0, 1.0);
            d * d
        })
        .sum();
    cost + (cost.abs() + EPSILON) * outside
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn further_outside_ranks_worse_and_inside_is_unchanged() {
        assert_eq!(project(&[-0.5, 0.3, 1.5]), vec![0.0, 0.3, 1.0]);
        assert_eq!(penalised(&[0.2, 0.9], 3.0), 3.0);
        let near = penalised(&[-0.1, 0.5], 2.0);
        let far = penalised(&[-0.3, 0.5], 2.0);
        assert!(2.0 < near && near < far, "{near} {far}");
        assert!(penalised(&[-0.1], 0.0) > 0.0);
        assert_eq!(penalised(&[-0.1], f64::MAX), f64::MAX);
    }
}
