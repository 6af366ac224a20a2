//! The walk along one side of one parameter's profile, in the unit box.
//!
//! From the best point the parameter is moved away step by step; at each value the other
//! coordinates are re-optimised, warm-started where the previous points say the valley
//! goes, and the rise of the objective over the best one is compared with the threshold Δ.
//!
//! * **Warm start.** The first step moves the others along the linearised conditional
//!   optimum (`du_j/du_i = ρ_ij σ_j / σ_i`, in the unit box); later steps extrapolate the
//!   last two profile points linearly.
//! * **Re-optimisation only where it matters.** The profile at a value is at most the
//!   objective at the warm start. When that rise is already below [`ACCEPT`]·Δ the point is
//!   kept as it is: re-optimising could only lower a value that is far under the threshold.
//!   A parameter without any effect therefore costs one evaluation per step. Otherwise
//!   Powell's method (the calibration's, in the unit box of the other coordinates) minimises
//!   from the warm start, to a tolerance of [`FTOL`]·Δ on the objective. Its line searches
//!   start at each coordinate's linearised deviation, or at [`Reoptimisation::min_step`] of
//!   the box when that is larger: an objective that is rough on small scales (a stick–slip
//!   model whose events come and go with the parameters) needs brackets wider than the
//!   roughness, which its linearised deviations do not give.
//! * **Steps.** The first is half the linearised standard deviation (at most
//!   [`FIRST_STEP_MAX`] of the box, and that when the deviation is unknown). After a point
//!   at distance `d` with rise `r < Δ`, a quadratic profile would cross at `d·√(Δ/r)`; the
//!   next distance aims a little beyond, `d·clamp(1.2·√(Δ/r), 1.25, 4)`, so that a nearly
//!   quadratic profile is bracketed in two steps and a flat one reaches its bound in a few
//!   (×4 per step). Steps are cut at the bound.
//! * **Ends.** The side ends at the threshold (the crossing interpolated linearly in
//!   `√rise`, exact for a quadratic profile, after at most [`REFINEMENTS`] extra points
//!   while the bracketing rise exceeds 2Δ), at the bound with the rise still under Δ
//!   (open), where simulations fail (open), or after the most steps allowed (open).

use argmin::core::{CostFunction, Executor, SyncAlias};
use calib_engine::error::{Error, Result};
use calib_engine::optim::budget::Budgeted;
use calib_engine::optim::powell::Powell;
use serde::Serialize;
use std::borrow::Borrow;
use std::sync::Mutex;

/// Objectives of full unit-box points, in order (a failed simulation: at least
/// [`Problem::failure`]).
pub type Batch<'a> = dyn Fn(&[Vec<f64>]) -> Result<Vec<f64>> + Sync + 'a;

/// A warm start whose rise is below this fraction of the threshold is kept without
/// re-optimising.
pub const ACCEPT: f64 = 0.1;

/// Re-optimisation stops when a sweep of Powell's method lowers the objective by less than
/// this fraction of the threshold.
pub const FTOL: f64 = 0.01;

/// The largest first step, as a fraction of the unit box (also the first step of a
/// parameter whose linearised deviation is unknown).
pub const FIRST_STEP_MAX: f64 = 1.0 / 16.0;

/// Extra points placed inside a bracket whose upper rise exceeds 2Δ.
pub const REFINEMENTS: usize = 3;

/// Default most steps per side.
pub const DEFAULT_MAX_STEPS: usize = 30;

/// How the other coordinates are re-optimised at a profile point.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reoptimisation {
    /// Smallest first step of Powell's line searches, in the unit box.
    pub min_step: f64,
    /// Evaluations of one re-optimisation: `fixed + per_coordinate · (n − 1)`.
    pub fixed: u64,
    pub per_coordinate: u64,
}

impl Default for Reoptimisation {
    /// Steps of the linearised deviations (down to 10⁻⁹ of the box), the default budget:
    /// what a smooth objective needs.
    fn default() -> Self {
        Reoptimisation {
            min_step: 1e-9,
            fixed: 60,
            per_coordinate: 40,
        }
    }
}

impl Reoptimisation {
    /// For objectives rough on small scales: line searches start at 1% of the box at least,
    /// with 100 more evaluations per coordinate re-optimised.
    pub fn rough() -> Self {
        Reoptimisation {
            min_step: 1e-2,
            fixed: 100,
            per_coordinate: 100,
        }
    }
}

/// What a walk needs.
pub struct Problem<'a> {
    pub batch: &'a Batch<'a>,
    /// The best point, unit box.
    pub best: Vec<f64>,
    pub best_objective: f64,
    /// Δ: the rise of the objective that bounds the confidence interval.
    pub threshold: f64,
    /// Linearised standard deviation of each coordinate in the unit box (infinite or NaN
    /// when unknown).
    pub std: Vec<f64>,
    /// `slopes[i][j]`: the linearised change of coordinate `j` along the conditional optimum
    /// per unit change of coordinate `i` (0 when unknown).
    pub slopes: Vec<Vec<f64>>,
    pub max_steps: usize,
    /// Objectives at or above this are failed simulations.
    pub failure: f64,
    pub reoptimisation: Reoptimisation,
}

/// One point of a profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Point {
    /// The whole point (unit box), the profiled coordinate included.
    pub unit: Vec<f64>,
    pub objective: f64,
    /// `objective − best objective`.
    pub rise: f64,
    /// Whether the others were re-optimised (else the warm start was kept).
    pub reoptimised: bool,
}

/// Why a side of a profile ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum End {
    /// The rise reached the threshold: the side is closed.
    Threshold,
    /// The bound was reached with the rise under the threshold: open.
    Bound,
    /// Simulations failed before the threshold: open.
    Failed,
    /// The most steps allowed were taken: open.
    Steps,
}

/// One side of a profile.
#[derive(Debug, Clone, PartialEq)]
pub struct Side {
    /// Points in order of distance from the best point (the best point excluded).
    pub points: Vec<Point>,
    pub end: End,
    /// Where the rise crosses the threshold (unit coordinate), on a closed side.
    pub crossing: Option<f64>,
    /// Objective evaluations asked for.
    pub evaluations: usize,
}

/// The profiled coordinate where `√rise` reaches `√Δ` on the segment from `lo` to `hi`.
fn interpolate(i: usize, lo: &Point, hi: &Point, threshold: f64) -> f64 {
    let (a, b) = (lo.rise.max(0.0).sqrt(), hi.rise.max(0.0).sqrt());
    let t = if b > a {
        ((threshold.sqrt() - a) / (b - a)).clamp(0.0, 1.0)
    } else {
        1.0
    };
    lo.unit[i] + t * (hi.unit[i] - lo.unit[i])
}

struct Walker<'a, 'b> {
    problem: &'b Problem<'a>,
    i: usize,
    evaluations: Mutex<usize>,
}

impl Walker<'_, '_> {
    fn evaluate(&self, points: &[Vec<f64>]) -> Result<Vec<f64>> {
        *self.evaluations.lock().expect("count lock") += points.len();
        (self.problem.batch)(points)
    }

    /// The warm start at coordinate `u`: extrapolated from the last two points of `path`
    /// (the best point first), or along the linearised slopes from the best point.
    fn warm_start(&self, path: &[&[f64]], u: f64) -> Vec<f64> {
        let i = self.i;
        let last = path[path.len() - 1];
        let mut x: Vec<f64> = if path.len() >= 2 {
            let before = path[path.len() - 2];
            let span = last[i] - before[i];
            (0..last.len())
                .map(|j| {
                    if span != 0.0 {
                        last[j] + (last[j] - before[j]) / span * (u - last[i])
                    } else {
                        last[j]
                    }
                })
                .collect()
        } else {
            let slopes = &self.problem.slopes[i];
            (0..last.len())
                .map(|j| {
                    let s = slopes.get(j).copied().unwrap_or(0.0);
                    let s = if s.is_finite() { s } else { 0.0 };
                    last[j] + s * (u - last[i])
                })
                .collect()
        };
        for v in &mut x {
            *v = v.clamp(0.0, 1.0);
        }
        x[i] = u;
        x
    }

    /// The profile point at `start[i]`, from the warm start `start`.
    fn point_at(&self, start: Vec<f64>) -> Result<Point> {
        let p = self.problem;
        let f = self.evaluate(std::slice::from_ref(&start))?[0];
        let keep = Point {
            rise: f - p.best_objective,
            objective: f,
            unit: start.clone(),
            reoptimised: false,
        };
        if start.len() == 1 || (f < p.failure && f - p.best_objective <= ACCEPT * p.threshold) {
            return Ok(keep);
        }
        let (unit, objective) = self.reoptimise(start, f)?;
        if objective >= keep.objective {
            return Ok(keep);
        }
        Ok(Point {
            rise: objective - p.best_objective,
            objective,
            unit,
            reoptimised: true,
        })
    }

    /// Powell's method over every coordinate but `i`, from `start` (objective `f`).
    fn reoptimise(&self, start: Vec<f64>, f: f64) -> Result<(Vec<f64>, f64)> {
        let p = self.problem;
        let i = self.i;
        let others: Vec<usize> = (0..start.len()).filter(|&j| j != i).collect();
        let finite: Vec<f64> = others
            .iter()
            .map(|&j| p.std[j])
            .filter(|s| s.is_finite() && *s > 0.0)
            .collect();
        let xtol = (1e-3 * finite.iter().copied().fold(f64::INFINITY, f64::min)).clamp(1e-12, 1e-6);
        let steps: Vec<f64> = others
            .iter()
            .map(|&j| {
                let s = p.std[j];
                if s.is_finite() && s > 0.0 {
                    s.clamp(p.reoptimisation.min_step.min(0.25), 0.25)
                } else {
                    0.05
                }
            })
            .collect();
        let reduced: Vec<f64> = others.iter().map(|&j| start[j]).collect();
        let cost = Reduced {
            walker: self,
            template: start,
            best: Mutex::new((f, None)),
        };
        let solver = Powell::new(reduced.clone())
            .with_initial_steps(steps)
            .and_then(|s| s.with_xtol(xtol))
            .and_then(|s| s.with_ftol(0.0, FTOL))
            .map_err(|e| Error::Optimiser(e.to_string()))?;
        let r = p.reoptimisation;
        let budget = r.fixed + r.per_coordinate * others.len() as u64;
        let result = Executor::new(cost, Budgeted::new(solver, budget, None))
            .configure(|state| state.param(reduced).max_iters(100_000).counting(true))
            .run();
        let mut result = result.map_err(|e| match e.downcast::<Error>() {
            Ok(e) => e,
            Err(e) => Error::Optimiser(e.to_string()),
        })?;
        let cost = result
            .problem
            .take_problem()
            .expect("the executor hands the problem back");
        let (objective, unit) = cost.best.into_inner().expect("best lock");
        Ok((unit.unwrap_or(cost.template), objective))
    }

    fn walk(&self, direction: f64) -> Result<Side> {
        let p = self.problem;
        let i = self.i;
        let u0 = p.best[i];
        let limit = if direction > 0.0 { 1.0 - u0 } else { u0 };
        let mut points: Vec<Point> = Vec::new();
        let done = |points: Vec<Point>, end, crossing| Side {
            points,
            end,
            crossing,
            evaluations: *self.evaluations.lock().expect("count lock"),
        };
        if limit <= 0.0 {
            return Ok(done(points, End::Bound, None));
        }
        let std = p.std[i];
        let mut d = if std.is_finite() && std > 0.0 {
            (0.5 * std).clamp(1e-12, FIRST_STEP_MAX)
        } else {
            FIRST_STEP_MAX
        };
        let origin = Point {
            unit: p.best.clone(),
            objective: p.best_objective,
            rise: 0.0,
            reoptimised: false,
        };
        for _ in 0..p.max_steps {
            let at_bound = d >= limit;
            let u = if at_bound {
                if direction > 0.0 {
                    1.0
                } else {
                    0.0
                }
            } else {
                u0 + direction * d
            };
            let path: Vec<&[f64]> = std::iter::once(&origin)
                .chain(points.iter())
                .map(|q| q.unit.as_slice())
                .collect();
            let start = self.warm_start(&path, u);
            let point = self.point_at(start)?;
            let failed = point.objective >= p.failure || !point.objective.is_finite();
            let rise = point.rise;
            points.push(point);
            if failed {
                return Ok(done(points, End::Failed, None));
            }
            if rise >= p.threshold {
                let crossing = self.cross(&origin, &mut points)?;
                return Ok(done(points, End::Threshold, Some(crossing)));
            }
            if at_bound {
                return Ok(done(points, End::Bound, None));
            }
            let growth = if rise > 0.0 {
                (1.2 * (p.threshold / rise).sqrt()).clamp(1.25, 4.0)
            } else {
                4.0
            };
            d = (d * growth).min(limit);
        }
        Ok(done(points, End::Steps, None))
    }

    /// The crossing between the last two points (the last at or above the threshold),
    /// refined while the upper rise is far above it.
    fn cross(&self, origin: &Point, points: &mut Vec<Point>) -> Result<f64> {
        let p = self.problem;
        let i = self.i;
        let mut hi = points.pop().expect("a point above the threshold");
        let mut lo = points.last().cloned().unwrap_or_else(|| origin.clone());
        let mut inside: Vec<Point> = Vec::new();
        for _ in 0..REFINEMENTS {
            if hi.rise <= 2.0 * p.threshold {
                break;
            }
            let u = interpolate(i, &lo, &hi, p.threshold);
            if u == lo.unit[i] || u == hi.unit[i] {
                break;
            }
            let path: Vec<&[f64]> = vec![origin.unit.as_slice(), lo.unit.as_slice()];
            let path = if lo.unit == origin.unit {
                &path[..1]
            } else {
                &path[..]
            };
            let q = self.point_at(self.warm_start(path, u))?;
            if q.objective >= p.failure || q.objective.is_nan() {
                break;
            }
            if q.rise >= p.threshold {
                inside.push(std::mem::replace(&mut hi, q));
            } else {
                inside.push(std::mem::replace(&mut lo, q));
            }
        }
        let crossing = interpolate(i, &lo, &hi, p.threshold);
        points.extend(inside);
        points.push(lo);
        points.push(hi);
        // Order by distance from the best point; the origin copy (when `lo` was it) goes.
        points.retain(|q| q.unit != origin.unit);
        points.sort_by(|a, b| {
            (a.unit[i] - origin.unit[i])
                .abs()
                .total_cmp(&(b.unit[i] - origin.unit[i]).abs())
        });
        points.dedup_by(|a, b| a.unit[i] == b.unit[i]);
        Ok(crossing)
    }
}

/// The cost Powell's method sees: the other coordinates in, `(f − f_best) / Δ` out.
struct Reduced<'w, 'a, 'b> {
    walker: &'w Walker<'a, 'b>,
    /// The full point, with the profiled coordinate at its value.
    template: Vec<f64>,
    /// Lowest objective seen and its full point.
    best: Mutex<(f64, Option<Vec<f64>>)>,
}

impl Reduced<'_, '_, '_> {
    fn expand(&self, reduced: &[f64]) -> Vec<f64> {
        let i = self.walker.i;
        let mut x = self.template.clone();
        let mut k = 0;
        for (j, v) in x.iter_mut().enumerate() {
            if j != i {
                *v = reduced[k].clamp(0.0, 1.0);
                k += 1;
            }
        }
        x
    }

    fn costs(&self, reduced: &[&Vec<f64>]) -> std::result::Result<Vec<f64>, argmin::core::Error> {
        let full: Vec<Vec<f64>> = reduced.iter().map(|r| self.expand(r)).collect();
        let values = self.walker.evaluate(&full)?;
        let p = self.walker.problem;
        let mut best = self.best.lock().expect("best lock");
        for (x, &f) in full.iter().zip(&values) {
            if f < best.0 {
                *best = (f, Some(x.clone()));
            }
        }
        Ok(values
            .iter()
            .map(|&f| {
                if f.is_nan() || f >= p.failure {
                    f64::MAX
                } else {
                    (f - p.best_objective) / p.threshold
                }
            })
            .collect())
    }
}

impl CostFunction for Reduced<'_, '_, '_> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, u: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        Ok(self.costs(&[u])?[0])
    }

    fn bulk_cost<P>(&self, params: &[P]) -> std::result::Result<Vec<f64>, argmin::core::Error>
    where
        P: Borrow<Vec<f64>> + SyncAlias,
        f64: argmin::core::SendAlias,
        Self: SyncAlias,
    {
        let units: Vec<&Vec<f64>> = params.iter().map(|p| p.borrow()).collect();
        self.costs(&units)
    }
}

/// Walk coordinate `i` of `problem` towards its upper (`direction` > 0) or lower bound.
pub fn walk(problem: &Problem, i: usize, direction: f64) -> Result<Side> {
    Walker {
        problem,
        i,
        evaluations: Mutex::new(0),
    }
    .walk(direction)
}

#[cfg(test)]
mod tests;
