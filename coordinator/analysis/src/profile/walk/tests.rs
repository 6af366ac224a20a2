use super::*;
use nalgebra::{DMatrix, DVector};

/// `f(u) = f0 + (u − c)ᵀ H (u − c)` over the first three coordinates; the fourth has no
/// effect at all.
struct Quadratic {
    c: DVector<f64>,
    h: DMatrix<f64>,
    f0: f64,
}

impl Quadratic {
    fn new() -> Self {
        Quadratic {
            c: DVector::from_vec(vec![0.4, 0.5, 0.6]),
            h: DMatrix::from_row_slice(3, 3, &[2.0, 1.2, 0.0, 1.2, 1.0, 0.3, 0.0, 0.3, 0.5]) * 1e4,
            f0: 3.0,
        }
    }

    fn value(&self, u: &[f64]) -> f64 {
        let d = DVector::from_vec(u[..3].to_vec()) - &self.c;
        self.f0 + (d.transpose() * &self.h * &d)[(0, 0)]
    }

    /// The exact profile interval of coordinate `i` at threshold `delta`: `c_i ± √(Δ (H⁻¹)_ii)`.
    fn interval(&self, i: usize, delta: f64) -> (f64, f64) {
        let inverse = self.h.clone().try_inverse().unwrap();
        let half = (delta * inverse[(i, i)]).sqrt();
        (self.c[i] - half, self.c[i] + half)
    }
}

fn problem<'a>(batch: &'a Batch<'a>, best: Vec<f64>, f0: f64, std: Vec<f64>) -> Problem<'a> {
    let n = best.len();
    Problem {
        batch,
        best,
        best_objective: f0,
        threshold: 1.0,
        std,
        slopes: vec![vec![0.0; n]; n],
        max_steps: DEFAULT_MAX_STEPS,
        failure: 1e30,
        reoptimisation: Reoptimisation::default(),
    }
}

#[test]
fn a_quadratic_profile_crosses_at_the_exact_interval() {
    let q = Quadratic::new();
    let batch = |points: &[Vec<f64>]| Ok(points.iter().map(|u| q.value(u)).collect());
    let best = vec![0.4, 0.5, 0.6, 0.5];
    // Deviations three times too large and no slopes: the warm starts are poor, so the
    // re-optimisation has to find the valley itself.
    let inverse = q.h.clone().try_inverse().unwrap();
    let std: Vec<f64> = (0..3)
        .map(|i| 3.0 * inverse[(i, i)].sqrt())
        .chain([f64::INFINITY])
        .collect();
    let p = problem(&batch, best, q.f0, std);
    for i in 0..3 {
        let (low, high) = q.interval(i, 1.0);
        let half = high - q.c[i];
        let down = walk(&p, i, -1.0).unwrap();
        let up = walk(&p, i, 1.0).unwrap();
        assert_eq!(down.end, End::Threshold, "{i}: {down:?}");
        assert_eq!(up.end, End::Threshold, "{i}: {up:?}");
        let (a, b) = (down.crossing.unwrap(), up.crossing.unwrap());
        assert!((a - low).abs() < 2e-3 * half, "{i}: {a} vs {low}");
        assert!((b - high).abs() < 2e-3 * half, "{i}: {b} vs {high}");
        assert!(down.points.iter().any(|pt| pt.reoptimised), "{i}");
        assert!(up.evaluations < 300, "{i}: {} evaluations", up.evaluations);
    }
}

#[test]
fn with_the_linearised_slopes_the_warm_starts_follow_a_quadratic_valley_exactly() {
    let q = Quadratic::new();
    let batch = |points: &[Vec<f64>]| Ok(points.iter().map(|u| q.value(u)).collect());
    let inverse = q.h.clone().try_inverse().unwrap();
    let std: Vec<f64> = (0..3)
        .map(|i| inverse[(i, i)].sqrt())
        .chain([f64::INFINITY])
        .collect();
    let mut p = problem(&batch, vec![0.4, 0.5, 0.6, 0.5], q.f0, std);
    for i in 0..3 {
        for j in 0..3 {
            p.slopes[i][j] = inverse[(i, j)] / inverse[(i, i)];
        }
    }
    let (low, high) = q.interval(1, 1.0);
    let up = walk(&p, 1, 1.0).unwrap();
    let down = walk(&p, 1, -1.0).unwrap();
    // Exact warm starts: the profile is the objective there, and √rise is linear.
    assert!((up.crossing.unwrap() - high).abs() < 1e-9, "{up:?}");
    assert!((down.crossing.unwrap() - low).abs() < 1e-9, "{down:?}");
    // Below a tenth of the threshold the warm start is kept as it is.
    for pt in up.points.iter().chain(&down.points) {
        assert!(pt.rise > ACCEPT || !pt.reoptimised, "{pt:?}");
    }
    assert!(up.evaluations < 80, "{}", up.evaluations);
}

#[test]
fn a_coordinate_without_effect_is_open_on_both_sides_within_a_few_evaluations() {
    let q = Quadratic::new();
    let batch = |points: &[Vec<f64>]| Ok(points.iter().map(|u| q.value(u)).collect());
    let p = problem(
        &batch,
        vec![0.4, 0.5, 0.6, 0.3],
        q.f0,
        vec![1e-3, 1e-3, 1e-3, f64::INFINITY],
    );
    for direction in [-1.0, 1.0] {
        let side = walk(&p, 3, direction).unwrap();
        assert_eq!(side.end, End::Bound);
        assert_eq!(side.crossing, None);
        assert!(side.evaluations <= 4, "{} evaluations", side.evaluations);
        let last = side.points.last().unwrap();
        assert_eq!(last.unit[3], if direction > 0.0 { 1.0 } else { 0.0 });
        assert!(side
            .points
            .iter()
            .all(|pt| pt.rise == 0.0 && !pt.reoptimised));
    }
}

#[test]
fn a_best_point_on_a_bound_leaves_that_side_open_without_evaluating() {
    let batch = |points: &[Vec<f64>]| -> Result<Vec<f64>> {
        Ok(points.iter().map(|u| 1.0 + 1e4 * u[0] * u[0]).collect())
    };
    let p = problem(&batch, vec![0.0], 1.0, vec![0.01]);
    let down = walk(&p, 0, -1.0).unwrap();
    assert_eq!((down.end, down.evaluations), (End::Bound, 0));
    let up = walk(&p, 0, 1.0).unwrap();
    assert_eq!(up.end, End::Threshold);
    // One coordinate: nothing to re-optimise, 1e4 u² = 1 at u = 0.01.
    assert!((up.crossing.unwrap() - 0.01).abs() < 1e-3 * 0.01, "{up:?}");
}

#[test]
fn a_steep_non_quadratic_profile_is_refined_near_its_crossing() {
    // f = 1 + (u − 0.5)⁴ · 1e8: the crossing at 0.5 ± 0.01.
    let batch = |points: &[Vec<f64>]| -> Result<Vec<f64>> {
        Ok(points
            .iter()
            .map(|u| 1.0 + 1e8 * (u[0] - 0.5).powi(4))
            .collect())
    };
    let p = problem(&batch, vec![0.5], 1.0, vec![0.001]);
    let up = walk(&p, 0, 1.0).unwrap();
    assert_eq!(up.end, End::Threshold);
    assert!((up.crossing.unwrap() - 0.51).abs() < 0.02 * 0.01, "{up:?}");
    // Points are ordered outwards.
    let distances: Vec<f64> = up.points.iter().map(|pt| pt.unit[0] - 0.5).collect();
    assert!(distances.windows(2).all(|w| w[0] < w[1]), "{distances:?}");
}

#[test]
fn failed_simulations_leave_a_side_open() {
    let batch = |points: &[Vec<f64>]| -> Result<Vec<f64>> {
        Ok(points
            .iter()
            .map(|u| {
                if u[0] > 0.6 {
                    1e30
                } else {
                    1.0 + (u[0] - 0.5).powi(2)
                }
            })
            .collect())
    };
    let p = problem(&batch, vec![0.5], 1.0, vec![0.01]);
    let up = walk(&p, 0, 1.0).unwrap();
    assert_eq!(up.end, End::Failed);
    assert_eq!(up.crossing, None);
}
