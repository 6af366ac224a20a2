//! The segment of a search line inside the box, and the batched bracketing of the
//! line's minimum on it (see the [parent module](super), "Line minimisation").

use super::brent::Bracket;
use super::{sanitize, Powell};
use argmin::core::{CostFunction, Error, Problem, SyncAlias};

/// How a line's samples end: the answer, or a bracket to refine.
enum Bracketed {
    Done((f64, f64)),
    Bracket(Bracket),
}

/// Upper bound on bracket-extension batches per line.
const MAX_EXTENSIONS: usize = 64;

impl Powell {
    /// Minimises `f(x + t d)` over the part of the line inside the box.
    ///
    /// `fx = f(x)`; `known` holds samples `(t, f)` already evaluated on this line.
    /// Returns the best `(t, f)` found (`t = 0` if nothing better than `x`).
    pub(super) fn line_search<O>(
        &self,
        problem: &mut Problem<O>,
        x: &[f64],
        fx: f64,
        d: &[f64],
        step: f64,
        known: &[(f64, f64)],
    ) -> Result<(f64, f64), Error>
    where
        O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
    {
        let (lo, hi) = feasible_interval(x, d);
        let tol0 = self.line_tol(0.0);
        if hi - lo <= tol0 {
            return Ok((0.0, fx));
        }

        let mut samples = vec![(0.0, fx)];
        for &(t, f) in known {
            if t >= lo - tol0 && t <= hi + tol0 {
                let t = t.clamp(lo, hi);
                if !is_near_any(&samples, t, tol0) {
                    samples.push((t, f));
                }
            }
        }
        sort_by_t(&mut samples);

        // First batch: trial points on both sides, unless the known samples
        // already bracket a minimum.
        if !has_interior_best(&samples) {
            let trial = self.first_trial(&samples, step, (lo, hi), tol0);
            evaluate_batch(problem, x, d, &trial, &mut samples)?;
        }

        // Extend the bracket while the best sample is the outermost one inside
        // the segment.
        for _ in 0..MAX_EXTENSIONS {
            let trial = self.extension_trial(&samples, step, (lo, hi));
            if trial.is_empty() {
                break;
            }
            evaluate_batch(problem, x, d, &trial, &mut samples)?;
        }

        match self.bracket(problem, x, d, &samples)? {
            Bracketed::Done(best) => Ok(best),
            Bracketed::Bracket(bracket) => self.brent(problem, x, d, bracket),
        }
    }

    /// The first batch's trial points, on both sides of 0 within `[lo, hi]`.
    fn first_trial(
        &self,
        samples: &[(f64, f64)],
        step: f64,
        (lo, hi): (f64, f64),
        tol0: f64,
    ) -> Vec<f64> {
        let s = step.max(2.0 * tol0);
        let forward = self.bracket_points.div_ceil(2);
        let backward = self.bracket_points / 2;
        let mut trial = Vec::with_capacity(self.bracket_points);
        let s_fwd = s.min(hi / forward as f64);
        for k in 1..=forward {
            push_trial(&mut trial, samples, (k as f64 * s_fwd).min(hi), tol0);
        }
        let s_bwd = s.min(-lo / backward as f64);
        for k in 1..=backward {
            push_trial(&mut trial, samples, (-(k as f64) * s_bwd).max(lo), tol0);
        }
        trial
    }

    /// The next extension's trial points, beyond the best sample when it is the outermost
    /// one inside the segment (growing steps); none when the minimum is bracketed or the
    /// segment's end is reached.
    fn extension_trial(&self, samples: &[(f64, f64)], step: f64, (lo, hi): (f64, f64)) -> Vec<f64> {
        let k = best_index(samples);
        let last = samples.len() - 1;
        let tk = samples[k].0;
        let mut trial = Vec::with_capacity(self.bracket_points);
        if k == last && tk < hi - self.line_tol(tk) {
            let g = if k > 0 { tk - samples[k - 1].0 } else { 0.0 }.max(step);
            let mut mult = 1.0;
            for _ in 0..self.bracket_points {
                let t = (tk + g * mult).min(hi);
                push_trial(&mut trial, samples, t, self.line_tol(t));
                if t >= hi {
                    break;
                }
                mult = 2.0 * mult + 1.0;
            }
        } else if k == 0 && tk > lo + self.line_tol(tk) {
            let g = if last > 0 { samples[1].0 - tk } else { 0.0 }.max(step);
            let mut mult = 1.0;
            for _ in 0..self.bracket_points {
                let t = (tk - g * mult).max(lo);
                push_trial(&mut trial, samples, t, self.line_tol(t));
                if t <= lo {
                    break;
                }
                mult = 2.0 * mult + 1.0;
            }
        }
        trial
    }

    /// The bracket Brent's method refines, from the samples of the line; or the line's
    /// answer already, when the best sample is on the segment's boundary and a probe just
    /// inside does not improve on it.
    fn bracket<O>(
        &self,
        problem: &mut Problem<O>,
        x: &[f64],
        d: &[f64],
        samples: &[(f64, f64)],
    ) -> Result<Bracketed, Error>
    where
        O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
    {
        let k = best_index(samples);
        let last = samples.len() - 1;
        if last == 0 {
            return Ok(Bracketed::Done(samples[0]));
        }
        let best = samples[k];
        Ok(Bracketed::Bracket(if k == 0 || k == last {
            // Best sample on the segment boundary (or the extension budget ran
            // out): probe once just inside.
            let inner = if k == 0 {
                samples[1]
            } else {
                samples[last - 1]
            };
            let tol = self.line_tol(best.0);
            if (best.0 - inner.0).abs() <= 2.0 * tol {
                return Ok(Bracketed::Done(best));
            }
            let probe_t = if k == 0 { best.0 + tol } else { best.0 - tol };
            let probe = (probe_t, self.evaluate_one(problem, x, d, probe_t)?);
            if probe.1 >= best.1 {
                return Ok(Bracketed::Done(best));
            }
            let (a, b) = if k == 0 {
                (best.0, inner.0)
            } else {
                (inner.0, best.0)
            };
            Bracket {
                a,
                b,
                x: probe,
                w: best,
                v: inner,
            }
        } else {
            let (left, right) = (samples[k - 1], samples[k + 1]);
            let (w, v) = if left.1 <= right.1 {
                (left, right)
            } else {
                (right, left)
            };
            Bracket {
                a: left.0,
                b: right.0,
                x: best,
                w,
                v,
            }
        }))
    }

    pub(super) fn evaluate_one<O>(
        &self,
        problem: &mut Problem<O>,
        x: &[f64],
        d: &[f64],
        t: f64,
    ) -> Result<f64, Error>
    where
        O: CostFunction<Param = Vec<f64>, Output = f64>,
    {
        Ok(sanitize(problem.cost(&point_on_line(x, d, t))?))
    }
}

/// The interval `[t_min, t_max]` (containing 0) of `t` with `x + t d` in the box.
fn feasible_interval(x: &[f64], d: &[f64]) -> (f64, f64) {
    let mut lo = f64::NEG_INFINITY;
    let mut hi = f64::INFINITY;
    for (&xi, &di) in x.iter().zip(d) {
        if di > 0.0 {
            lo = lo.max(-xi / di);
            hi = hi.min((1.0 - xi) / di);
        } else if di < 0.0 {
            lo = lo.max((1.0 - xi) / di);
            hi = hi.min(-xi / di);
        }
    }
    (lo.min(0.0), hi.max(0.0))
}

/// `x + t d`, clamped into the box against rounding.
pub(super) fn point_on_line(x: &[f64], d: &[f64], t: f64) -> Vec<f64> {
    x.iter()
        .zip(d)
        .map(|(&xi, &di)| (xi + t * di).clamp(0.0, 1.0))
        .collect()
}

fn evaluate_batch<O>(
    problem: &mut Problem<O>,
    x: &[f64],
    d: &[f64],
    trial: &[f64],
    samples: &mut Vec<(f64, f64)>,
) -> Result<(), Error>
where
    O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
{
    if trial.is_empty() {
        return Ok(());
    }
    let points: Vec<Vec<f64>> = trial.iter().map(|&t| point_on_line(x, d, t)).collect();
    let costs = problem.bulk_cost(&points)?;
    samples.extend(trial.iter().zip(costs).map(|(&t, f)| (t, sanitize(f))));
    sort_by_t(samples);
    Ok(())
}

fn sort_by_t(samples: &mut [(f64, f64)]) {
    samples.sort_by(|p, q| p.0.total_cmp(&q.0));
}

fn is_near_any(samples: &[(f64, f64)], t: f64, tol: f64) -> bool {
    samples.iter().any(|&(s, _)| (s - t).abs() <= tol)
}

fn push_trial(trial: &mut Vec<f64>, samples: &[(f64, f64)], t: f64, tol: f64) {
    if !is_near_any(samples, t, tol) && !trial.iter().any(|&s| (s - t).abs() <= tol) {
        trial.push(t);
    }
}

/// Index of the lowest cost; ties go to the sample nearest the line's origin.
fn best_index(samples: &[(f64, f64)]) -> usize {
    let mut best = 0;
    for (i, &(t, f)) in samples.iter().enumerate().skip(1) {
        let (bt, bf) = samples[best];
        if f < bf || (f == bf && t.abs() < bt.abs()) {
            best = i;
        }
    }
    best
}

/// Whether the best of the (sorted) samples has a neighbour on each side.
fn has_interior_best(samples: &[(f64, f64)]) -> bool {
    let k = best_index(samples);
    k > 0 && k + 1 < samples.len()
}
