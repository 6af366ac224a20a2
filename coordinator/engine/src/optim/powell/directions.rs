//! The direction set: its reset to the coordinate axes, and Powell's rule for replacing
//! the direction of largest decrease by the sweep's average direction (Numerical Recipes
//! §10.7), guarded against directions that become linearly dependent.

use super::line_search::point_on_line;
use super::{sanitize, Powell};
use argmin::core::{CostFunction, Error, Problem, SyncAlias};

/// Smallest accepted volume spanned by the unit search directions.
const MIN_DIRECTION_VOLUME: f64 = 1e-10;

/// Where a sweep started and which direction decreased `f` most.
pub(super) struct Sweep<'a> {
    pub x0: &'a [f64],
    pub f0: f64,
    pub biggest_drop: f64,
    pub biggest_index: usize,
}

impl Powell {
    pub(super) fn reset_directions(&mut self, n: usize) {
        self.directions = (0..n)
            .map(|i| {
                let mut e = vec![0.0; n];
                e[i] = 1.0;
                e
            })
            .collect();
        self.axes = true;
    }

    /// After a sweep that ended at `x` (cost `fx`): evaluates the extrapolated point, and
    /// when the replacement rule accepts the average direction, minimises along it and
    /// makes it the last direction. The point and cost reached, and whether the
    /// direction set changed.
    pub(super) fn replace_direction<O>(
        &mut self,
        problem: &mut Problem<O>,
        mut x: Vec<f64>,
        mut fx: f64,
        sweep: &Sweep,
    ) -> Result<(Vec<f64>, f64, bool), Error>
    where
        O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
    {
        let n = x.len();
        // Extrapolate along the sweep's average direction and decide whether it
        // replaces the direction of largest decrease.
        let extrapolated: Vec<f64> = x
            .iter()
            .zip(sweep.x0)
            .map(|(&xn, &xs)| (2.0 * xn - xs).clamp(0.0, 1.0))
            .collect();
        let clamped = x
            .iter()
            .zip(sweep.x0)
            .zip(&extrapolated)
            .any(|((&xn, &xs), &xe)| xe != 2.0 * xn - xs);
        let mut new_direction: Vec<f64> = extrapolated.iter().zip(&x).map(|(e, p)| e - p).collect();
        let length = norm(&new_direction);
        let mut replaced = false;
        if length > self.line_tol(0.0) {
            let fe = sanitize(problem.cost(&extrapolated)?);
            let keep_average_direction = fe < sweep.f0 && {
                let curvature =
                    2.0 * (sweep.f0 - 2.0 * fx + fe) * (sweep.f0 - fx - sweep.biggest_drop).powi(2);
                curvature - sweep.biggest_drop * (sweep.f0 - fe).powi(2) < 0.0
            };
            if keep_average_direction {
                new_direction.iter_mut().for_each(|c| *c /= length);
                let mut known = vec![(length, fe)];
                if !clamped {
                    known.push((-length, sweep.f0));
                }
                let (t, f) = self.line_search(problem, &x, fx, &new_direction, length, &known)?;
                if t != 0.0 {
                    x = point_on_line(&x, &new_direction, t);
                }
                fx = f;

                let mut candidate = self.directions.clone();
                candidate[sweep.biggest_index] = candidate[n - 1].clone();
                candidate[n - 1] = new_direction;
                if direction_volume(&candidate) >= MIN_DIRECTION_VOLUME {
                    self.directions = candidate;
                    self.axes = false;
                    self.steps[sweep.biggest_index] = self.steps[n - 1];
                    self.steps[n - 1] = self.next_step(t, length);
                    replaced = true;
                }
            }
        }
        Ok((x, fx, replaced))
    }
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|c| c * c).sum::<f64>().sqrt()
}

/// Volume of the parallelepiped spanned by unit vectors (`|det|`, by Gram–Schmidt).
fn direction_volume(directions: &[Vec<f64>]) -> f64 {
    let mut basis: Vec<Vec<f64>> = Vec::with_capacity(directions.len());
    let mut volume = 1.0;
    for d in directions {
        let mut r = d.clone();
        for e in &basis {
            let dot: f64 = r.iter().zip(e).map(|(a, b)| a * b).sum();
            r.iter_mut().zip(e).for_each(|(a, b)| *a -= dot * b);
        }
        let len = norm(&r);
        volume *= len;
        if len == 0.0 {
            return 0.0;
        }
        r.iter_mut().for_each(|a| *a /= len);
        basis.push(r);
    }
    volume
}
