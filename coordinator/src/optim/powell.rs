//! # Powell's conjugate-direction method in the unit box
//!
//! Derivative-free local minimiser for smooth objectives on `[0, 1]^n`.
//!
//! ## Algorithm
//!
//! The method keeps a set of `n` search directions, initially the coordinate axes
//! (unit vectors, i.e. one full box width per axis). One solver iteration is one
//! *sweep*:
//!
//! 0. Before the first sweep, `f` is probed one trial step either side of the start along
//!    every axis, in one batch, and the axes are ordered by the decrease they promise.
//!    On a valley that runs diagonally across the axes, the order of the first line
//!    searches decides which basin the method settles in; the most promising axis first
//!    is the choice that follows the valley.
//! 1. Starting from `P0`, minimise successively along every direction, giving `PN`.
//!    The direction whose line minimisation decreased `f` most is remembered.
//! 2. If the sweep decreased `f` by no more than `ftol` (relative plus absolute),
//!    or moved the point less than `xtol`, the solver has converged and stops
//!    without further evaluations. Exception: if the point lies on a bound and the
//!    directions are no longer the coordinate axes, the directions are reset to the
//!    axes and another sweep is made. Along directions that leave the bound's face
//!    a point can be a line minimum for every direction without being a minimum in
//!    the box, whereas a point that is a line minimum along every axis is a
//!    constrained stationary point of a smooth function.
//! 3. Otherwise `f` is evaluated at the extrapolated point `PE = 2 PN - P0` (clamped
//!    into the box). Powell's discard rule in the form of Numerical Recipes §10.7
//!    decides whether the average direction `PE - PN` replaces the direction of
//!    largest decrease `Δ`: it is adopted only if `f(PE) < f(P0)` and
//!    `2 (f0 - 2 fN + fE) (f0 - fN - Δ)² < Δ (f0 - fE)²`. In that case `f` is
//!    minimised along the new direction, the direction of largest decrease is
//!    dropped and the new direction is appended. This rule keeps the directions
//!    from becoming linearly dependent; as an extra safeguard (needed because the
//!    extrapolated point may have been clamped) a replacement is also refused when
//!    the unit directions would span a volume below `1e-10`.
//!
//! ## Line minimisation
//!
//! Every line minimisation is restricted to the segment `[t_min, t_max]` of the line
//! inside the box, computed from the bounds, so no evaluated point ever leaves
//! `[0, 1]^n` (points are also clamped against rounding).
//!
//! * **Bracketing, in batches.** Each direction remembers a trial step `s` (the
//!   length of its last move, initially [`Powell::with_initial_step`]). The first
//!   batch holds `bracket_points` trial points, `±s, ±2s, …` on both sides of the
//!   current point, squeezed so that the outermost point on a short side sits on the
//!   boundary. All are evaluated with one [`Problem::bulk_cost`] call. If the best
//!   sample is the outermost one and not on the boundary, another batch of up to
//!   `bracket_points` points continues in that direction with roughly doubling
//!   steps, until a minimum is bracketed or the boundary is reached. The search
//!   along a new direction after a sweep starts from the samples it already knows
//!   (`f(P0)`, `f(PN)`, `f(PE)`) and needs no batch when they bracket a minimum.
//! * **Refinement, sequential.** Brent's method (parabolic interpolation safeguarded
//!   by golden sections) refines the bracket one evaluation at a time. It is seeded
//!   with the three best samples of the bracket, so its first step can already be
//!   parabolic. Its tolerance at distance `t` along the line is
//!   `0.01·|t| + xtol / 4`: line minima are located to 1% of the move, which is
//!   plenty far from the solution and becomes `xtol / 4` close to it. Brent's
//!   procedure stops when the bracket has shrunk to the tolerance, or, earlier,
//!   when a convex parabola through the three best points puts the minimum within
//!   the tolerance of the best point. Refinement is sequential because each step
//!   depends on the previous one; on smooth functions it takes a few evaluations
//!   per line.
//! * **Minimum on the boundary.** If the best sample is on the boundary of the
//!   segment, one probe a tolerance inside decides: if it is not better, the
//!   boundary point is the line minimum and Brent's method is skipped.
//!
//! Larger `bracket_points` make the first batch see more of the line (and need
//! fewer extension batches) at the price of more evaluations; the default of 2
//! needed the fewest evaluations on smooth test problems.
//!
//! Costs that are NaN or `+∞` are treated as `f64::MAX`; errors from the cost
//! function are propagated.
//!
//! ## References
//!
//! * M. J. D. Powell (1964): An efficient method for finding the minimum of a function
//!   of several variables without calculating derivatives. The Computer Journal 7(2),
//!   155–162.
//! * R. P. Brent (1973): Algorithms for Minimization without Derivatives.
//!   Prentice-Hall, chapter 5 (line minimisation) and chapter 7 (Powell's method).
//! * W. H. Press, S. A. Teukolsky, W. T. Vetterling, B. P. Flannery: Numerical
//!   Recipes, §10.7 "Direction Set (Powell's) Methods in Multidimensions" (the
//!   direction-replacement rule).

use super::{check_start, invalid, sanitize};
use argmin::core::{
    ArgminError, CostFunction, Error, IterState, Problem, Solver, SyncAlias, TerminationReason,
    TerminationStatus, KV,
};

/// The argmin state Powell's method works with.
pub type PowellState = IterState<Vec<f64>, (), (), (), (), f64>;

/// `(3 - sqrt(5)) / 2`, the golden-section fraction.
const GOLDEN: f64 = 0.381_966_011_250_105_1;
/// Relative part of the line-search tolerance: line minima are located to 1% of
/// the distance moved (Numerical Recipes uses 2e-4). Loose line searches save
/// evaluations far from the minimum; the absolute part `xtol / 4` takes over as
/// the steps shrink.
const LINE_REL_TOL: f64 = 1e-2;
/// Upper bound on Brent iterations per line (never reached on sane problems).
const MAX_BRENT_ITERS: usize = 100;
/// Upper bound on bracket-extension batches per line.
const MAX_EXTENSIONS: usize = 64;
/// Smallest accepted volume spanned by the unit search directions.
const MIN_DIRECTION_VOLUME: f64 = 1e-10;

/// Powell's conjugate-direction method on the unit box `[0, 1]^n`.
///
/// See the [module documentation](self) for the algorithm. Defaults:
///
/// * `xtol = 1e-8` (sweep step length in the unit box),
/// * `ftol = 1e-10` relative plus `1e-14` absolute (decrease of `f` over a sweep),
/// * `bracket_points = 2` (batch size when bracketing a line minimum),
/// * `initial_step = 0.25` (first trial step along every axis).
#[derive(Clone, Debug)]
pub struct Powell {
    start: Vec<f64>,
    xtol: f64,
    ftol_rel: f64,
    ftol_abs: f64,
    bracket_points: usize,
    initial_step: f64,
    /// Per-axis first trial steps, overriding `initial_step` when set.
    initial_steps: Option<Vec<f64>>,
    /// Current unit search directions.
    directions: Vec<Vec<f64>>,
    /// Trial step for each direction.
    steps: Vec<f64>,
    /// Whether the directions are the coordinate axes.
    axes: bool,
    converged: bool,
}

impl Powell {
    /// Creates the solver starting from `start`, which must lie in `[0, 1]^n`
    /// (checked when the solver is initialised).
    pub fn new(start: Vec<f64>) -> Self {
        Powell {
            start,
            xtol: 1e-8,
            ftol_rel: 1e-10,
            ftol_abs: 1e-14,
            bracket_points: 2,
            initial_step: 0.25,
            initial_steps: None,
            directions: Vec::new(),
            steps: Vec::new(),
            axes: true,
            converged: false,
        }
    }

    /// Converged when a sweep moves the point by less than `xtol` (Euclidean
    /// length in the unit box). Also sets the line-search resolution to `xtol / 4`.
    /// Must be finite and `> 0`; defaults to `1e-8`.
    pub fn with_xtol(mut self, xtol: f64) -> Result<Self, Error> {
        if !(xtol.is_finite() && xtol > 0.0) {
            return Err(invalid("`Powell`: xtol must be finite and > 0."));
        }
        self.xtol = xtol;
        Ok(self)
    }

    /// Converged when a sweep decreases `f` by no more than
    /// `rel * (|f0| + |fN|) / 2 + abs / 2`. Both must be finite and `>= 0`;
    /// defaults to `rel = 1e-10`, `abs = 1e-14`.
    pub fn with_ftol(mut self, rel: f64, abs: f64) -> Result<Self, Error> {
        if !(rel.is_finite() && rel >= 0.0 && abs.is_finite() && abs >= 0.0) {
            return Err(invalid("`Powell`: ftol must be finite and >= 0."));
        }
        self.ftol_rel = rel;
        self.ftol_abs = abs;
        Ok(self)
    }

    /// Number of points evaluated in one batch when bracketing a line minimum
    /// (`ceil(m/2)` forwards, `floor(m/2)` backwards). Must be `>= 2`; defaults to 2.
    pub fn with_bracket_points(mut self, m: usize) -> Result<Self, Error> {
        if m < 2 {
            return Err(invalid("`Powell`: bracket_points must be >= 2."));
        }
        self.bracket_points = m;
        Ok(self)
    }

    /// First trial step along each axis, as a fraction of the box width. Must be in
    /// `(0, 1]`; defaults to `0.25`.
    pub fn with_initial_step(mut self, step: f64) -> Result<Self, Error> {
        if !(step > 0.0 && step <= 1.0) {
            return Err(invalid("`Powell`: initial_step must be in (0, 1]."));
        }
        self.initial_step = step;
        Ok(self)
    }

    /// First trial step along each axis separately (fractions of the box width, each in
    /// `(0, 1]`), for starts whose natural scale differs per parameter. Its length must
    /// match the start point's (checked when the solver is initialised).
    pub fn with_initial_steps(mut self, steps: Vec<f64>) -> Result<Self, Error> {
        if !steps.iter().all(|s| *s > 0.0 && *s <= 1.0) {
            return Err(invalid("`Powell`: initial steps must be in (0, 1]."));
        }
        self.initial_steps = Some(steps);
        Ok(self)
    }

    fn reset_directions(&mut self, n: usize) {
        self.directions = (0..n)
            .map(|i| {
                let mut e = vec![0.0; n];
                e[i] = 1.0;
                e
            })
            .collect();
        self.axes = true;
    }

    /// Line-search resolution at distance `t` from the line's origin.
    fn line_tol(&self, t: f64) -> f64 {
        LINE_REL_TOL * t.abs() + 0.25 * self.xtol
    }

    /// Trial step for the next search along a direction whose last move was `t`.
    fn next_step(&self, t: f64, previous: f64) -> f64 {
        let floor = 4.0 * self.line_tol(0.0);
        if t != 0.0 {
            t.abs().clamp(floor, 1.0)
        } else {
            (0.5 * previous).clamp(floor, 1.0)
        }
    }

    /// Minimises `f(x + t d)` over the part of the line inside the box.
    ///
    /// `fx = f(x)`; `known` holds samples `(t, f)` already evaluated on this line.
    /// Returns the best `(t, f)` found (`t = 0` if nothing better than `x`).
    fn line_search<O>(
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
            let s = step.max(2.0 * tol0);
            let forward = self.bracket_points.div_ceil(2);
            let backward = self.bracket_points / 2;
            let mut trial = Vec::with_capacity(self.bracket_points);
            let s_fwd = s.min(hi / forward as f64);
            for k in 1..=forward {
                push_trial(&mut trial, &samples, (k as f64 * s_fwd).min(hi), tol0);
            }
            let s_bwd = s.min(-lo / backward as f64);
            for k in 1..=backward {
                push_trial(&mut trial, &samples, (-(k as f64) * s_bwd).max(lo), tol0);
            }
            evaluate_batch(problem, x, d, &trial, &mut samples)?;
        }

        // Extend the bracket while the best sample is the outermost one inside
        // the segment.
        for _ in 0..MAX_EXTENSIONS {
            let k = best_index(&samples);
            let last = samples.len() - 1;
            let tk = samples[k].0;
            let mut trial = Vec::with_capacity(self.bracket_points);
            if k == last && tk < hi - self.line_tol(tk) {
                let g = if k > 0 { tk - samples[k - 1].0 } else { 0.0 }.max(step);
                let mut mult = 1.0;
                for _ in 0..self.bracket_points {
                    let t = (tk + g * mult).min(hi);
                    push_trial(&mut trial, &samples, t, self.line_tol(t));
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
                    push_trial(&mut trial, &samples, t, self.line_tol(t));
                    if t <= lo {
                        break;
                    }
                    mult = 2.0 * mult + 1.0;
                }
            }
            if trial.is_empty() {
                break;
            }
            evaluate_batch(problem, x, d, &trial, &mut samples)?;
        }

        let k = best_index(&samples);
        let last = samples.len() - 1;
        if last == 0 {
            return Ok(samples[0]);
        }
        let best = samples[k];
        let bracket = if k == 0 || k == last {
            // Best sample on the segment boundary (or the extension budget ran
            // out): probe once just inside.
            let inner = if k == 0 {
                samples[1]
            } else {
                samples[last - 1]
            };
            let tol = self.line_tol(best.0);
            if (best.0 - inner.0).abs() <= 2.0 * tol {
                return Ok(best);
            }
            let probe_t = if k == 0 { best.0 + tol } else { best.0 - tol };
            let probe = (probe_t, self.evaluate_one(problem, x, d, probe_t)?);
            if probe.1 >= best.1 {
                return Ok(best);
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
        };
        self.brent(problem, x, d, bracket)
    }

    /// Brent's safeguarded parabolic minimisation inside a bracket.
    fn brent<O>(
        &self,
        problem: &mut Problem<O>,
        origin: &[f64],
        d: &[f64],
        bracket: Bracket,
    ) -> Result<(f64, f64), Error>
    where
        O: CostFunction<Param = Vec<f64>, Output = f64>,
    {
        let Bracket {
            mut a,
            mut b,
            x: (mut x, mut fx),
            w: (mut w, mut fw),
            v: (mut v, mut fv),
        } = bracket;
        // Steps of the last two iterations; seeded with the bracket width so the
        // first steps may already be parabolic.
        let mut step = b - a;
        let mut older_step = b - a;
        for _ in 0..MAX_BRENT_ITERS {
            let mid = 0.5 * (a + b);
            let tol1 = self.line_tol(x);
            let tol2 = 2.0 * tol1;
            if (x - mid).abs() <= tol2 - 0.5 * (b - a) {
                break;
            }
            let mut golden = true;
            if older_step.abs() > tol1 {
                // Vertex of the parabola through (x, fx), (w, fw), (v, fv) is x + p / q.
                let r = (x - w) * (fx - fv);
                let mut q = (x - v) * (fx - fw);
                let mut p = (x - v) * q - (x - w) * r;
                q = 2.0 * (q - r);
                if q > 0.0 {
                    p = -p;
                } else {
                    q = -q;
                }
                // Stop early when the (convex) parabola puts the minimum within the
                // tolerance of the best point: the remaining probes at x ± tol
                // would only confirm it.
                let curvature = ((fw - fx) / (w - x) - (fv - fx) / (v - x)) / (w - v);
                if curvature > 0.0 && p.abs() < tol1 * q {
                    break;
                }
                let limit = older_step;
                older_step = step;
                // Accept only a step that is less than half the step before last
                // and falls inside the bracket (NaN fails every test).
                if p.abs() < (0.5 * q * limit).abs() && p > q * (a - x) && p < q * (b - x) {
                    step = p / q;
                    let u = x + step;
                    if u - a < tol2 || b - u < tol2 {
                        step = tol1.copysign(mid - x);
                    }
                    golden = false;
                }
            }
            if golden {
                older_step = if x >= mid { a - x } else { b - x };
                step = GOLDEN * older_step;
            }
            let u = if step.abs() >= tol1 {
                x + step
            } else {
                x + tol1.copysign(step)
            };
            let fu = self.evaluate_one(problem, origin, d, u)?;
            if fu <= fx {
                if u >= x {
                    a = x;
                } else {
                    b = x;
                }
                (v, fv) = (w, fw);
                (w, fw) = (x, fx);
                (x, fx) = (u, fu);
            } else {
                if u < x {
                    a = u;
                } else {
                    b = u;
                }
                if fu <= fw || w == x {
                    (v, fv) = (w, fw);
                    (w, fw) = (u, fu);
                } else if fu <= fv || v == x || v == w {
                    (v, fv) = (u, fu);
                }
            }
        }
        Ok((x, fx))
    }

    fn evaluate_one<O>(
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

/// A bracket `[a, b]` with the best (`x`), second best (`w`) and third (`v`) samples.
struct Bracket {
    a: f64,
    b: f64,
    x: (f64, f64),
    w: (f64, f64),
    v: (f64, f64),
}

impl<O> Solver<O, PowellState> for Powell
where
    O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
{
    fn name(&self) -> &str {
        "Powell"
    }

    fn init(
        &mut self,
        problem: &mut Problem<O>,
        state: PowellState,
    ) -> Result<(PowellState, Option<KV>), Error> {
        check_start("Powell", &self.start)?;
        let n = self.start.len();
        self.reset_directions(n);
        self.steps = match &self.initial_steps {
            Some(steps) if steps.len() == n => steps.clone(),
            Some(_) => {
                return Err(invalid(
                    "`Powell`: one initial step per coordinate of the start point.",
                ))
            }
            None => vec![self.initial_step; n],
        };
        self.converged = false;
        // The start and a probe on each side along every axis, as one batch.
        let mut points = vec![self.start.clone()];
        for (i, step) in self.steps.iter().enumerate() {
            for sign in [1.0, -1.0] {
                let mut p = self.start.clone();
                p[i] = (p[i] + sign * step).clamp(0.0, 1.0);
                points.push(p);
            }
        }
        let costs: Vec<f64> = problem
            .bulk_cost(&points)?
            .into_iter()
            .map(sanitize)
            .collect();
        let cost = costs[0];
        // Minimise first along the axes that promise the largest decrease: on valleys that
        // run diagonally, the axis order decides which basin the first sweep falls into.
        let promise: Vec<f64> = (0..n)
            .map(|i| cost - costs[1 + 2 * i].min(costs[2 + 2 * i]))
            .collect();
        let mut order: Vec<usize> = (0..n).collect();
        order.sort_by(|&a, &b| promise[b].total_cmp(&promise[a]));
        self.directions = order.iter().map(|&i| self.directions[i].clone()).collect();
        self.steps = order.iter().map(|&i| self.steps[i]).collect();
        Ok((state.param(self.start.clone()).cost(cost), None))
    }

    fn next_iter(
        &mut self,
        problem: &mut Problem<O>,
        mut state: PowellState,
    ) -> Result<(PowellState, Option<KV>), Error> {
        let mut x = state.take_param().ok_or_else(|| {
            Error::from(ArgminError::PotentialBug {
                text: "`Powell`: no current parameter vector in state.".into(),
            })
        })?;
        let mut fx = state.get_cost();
        let n = x.len();
        let (x0, f0) = (x.clone(), fx);

        // Sweep over all directions.
        let mut biggest_drop = 0.0;
        let mut biggest_index = 0;
        for i in 0..n {
            let d = &self.directions[i];
            let (t, f) = self.line_search(problem, &x, fx, d, self.steps[i], &[])?;
            self.steps[i] = self.next_step(t, self.steps[i]);
            if t != 0.0 {
                x = point_on_line(&x, d, t);
            }
            if fx - f > biggest_drop {
                biggest_drop = fx - f;
                biggest_index = i;
            }
            fx = f;
        }

        let step_length = distance(&x, &x0);
        let f_converged = 2.0 * (f0 - fx) <= self.ftol_rel * (f0.abs() + fx.abs()) + self.ftol_abs;
        if f_converged || step_length <= self.xtol {
            let margin = self.line_tol(0.0);
            if !self.axes && x.iter().any(|&v| v <= margin || v >= 1.0 - margin) {
                // On a bound, line minima along directions that leave the face do
                // not prove a constrained minimum; coordinate axes do (for smooth
                // f), so sweep once more along them.
                let step = self.steps.iter().fold(0.0_f64, |a, &b| a.max(b));
                self.reset_directions(n);
                self.steps = vec![step; n];
            } else {
                self.converged = true;
            }
            let kv = argmin::kv!(
                "f_decrease" => f0 - fx;
                "step" => step_length;
                "direction_replaced" => false;
                "restarted" => !self.converged;
            );
            return Ok((state.param(x).cost(fx), Some(kv)));
        }

        // Extrapolate along the sweep's average direction and decide whether it
        // replaces the direction of largest decrease.
        let extrapolated: Vec<f64> = x
            .iter()
            .zip(&x0)
            .map(|(&xn, &xs)| (2.0 * xn - xs).clamp(0.0, 1.0))
            .collect();
        let clamped = x
            .iter()
            .zip(&x0)
            .zip(&extrapolated)
            .any(|((&xn, &xs), &xe)| xe != 2.0 * xn - xs);
        let mut new_direction: Vec<f64> = extrapolated.iter().zip(&x).map(|(e, p)| e - p).collect();
        let length = norm(&new_direction);
        let mut replaced = false;
        if length > self.line_tol(0.0) {
            let fe = sanitize(problem.cost(&extrapolated)?);
            let keep_average_direction = fe < f0 && {
                let curvature = 2.0 * (f0 - 2.0 * fx + fe) * (f0 - fx - biggest_drop).powi(2);
                curvature - biggest_drop * (f0 - fe).powi(2) < 0.0
            };
            if keep_average_direction {
                new_direction.iter_mut().for_each(|c| *c /= length);
                let mut known = vec![(length, fe)];
                if !clamped {
                    known.push((-length, f0));
                }
                let (t, f) = self.line_search(problem, &x, fx, &new_direction, length, &known)?;
                if t != 0.0 {
                    x = point_on_line(&x, &new_direction, t);
                }
                fx = f;

                let mut candidate = self.directions.clone();
                candidate[biggest_index] = candidate[n - 1].clone();
                candidate[n - 1] = new_direction;
                if direction_volume(&candidate) >= MIN_DIRECTION_VOLUME {
                    self.directions = candidate;
                    self.axes = false;
                    self.steps[biggest_index] = self.steps[n - 1];
                    self.steps[n - 1] = self.next_step(t, length);
                    replaced = true;
                }
            }
        }

        let kv = argmin::kv!(
            "f_decrease" => f0 - fx;
            "step" => distance(&x, &x0);
            "direction_replaced" => replaced;
        );
        Ok((state.param(x).cost(fx), Some(kv)))
    }

    fn terminate(&mut self, _state: &PowellState) -> TerminationStatus {
        if self.converged {
            TerminationStatus::Terminated(TerminationReason::SolverConverged)
        } else {
            TerminationStatus::NotTerminated
        }
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
fn point_on_line(x: &[f64], d: &[f64], t: f64) -> Vec<f64> {
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

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|c| c * c).sum::<f64>().sqrt()
}

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f64>()
        .sqrt()
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::test_problems::{Recorder, Rosenbrock, Sphere};
    use argmin::core::{Executor, State};

    fn run<O>(problem: O, solver: Powell, max_iters: u64) -> (Vec<f64>, f64, u64, u64)
    where
        O: CostFunction<Param = Vec<f64>, Output = f64> + SyncAlias,
    {
        let res = Executor::new(problem, solver)
            .configure(|s| s.max_iters(max_iters))
            .run()
            .unwrap();
        let evals = res.problem.counts["cost_count"];
        let state = res.state();
        assert_eq!(
            state.get_termination_reason(),
            Some(&TerminationReason::SolverConverged)
        );
        (
            state.get_best_param().unwrap().clone(),
            state.get_best_cost(),
            state.get_iter(),
            evals,
        )
    }

    fn assert_close(x: &[f64], expected: &[f64], tol: f64) {
        for (a, b) in x.iter().zip(expected) {
            assert!((a - b).abs() < tol, "{x:?} vs {expected:?}");
        }
    }

    #[test]
    fn sphere_2d_converges() {
        let centre = vec![0.3, 0.65];
        let problem = Sphere {
            centre: centre.clone(),
        };
        let (x, f, sweeps, evals) = run(problem, Powell::new(vec![0.9, 0.1]), 100);
        println!("Powell sphere 2-D: {evals} evaluations, {sweeps} sweeps, f = {f:e}, x = {x:?}");
        assert_close(&x, &centre, 1e-6);
        assert!(evals <= 100, "{evals} evaluations");
    }

    #[test]
    fn sphere_5d_converges() {
        let centre = vec![0.1, 0.2, 0.5, 0.7, 0.95];
        let problem = Sphere {
            centre: centre.clone(),
        };
        let (x, f, sweeps, evals) = run(problem, Powell::new(vec![0.5; 5]), 100);
        println!("Powell sphere 5-D: {evals} evaluations, {sweeps} sweeps, f = {f:e}");
        assert_close(&x, &centre, 1e-6);
    }

    #[test]
    fn rosenbrock_2d_converges() {
        // Start at (-1.2, 1) in the original coordinates.
        let (x, f, sweeps, evals) = run(Rosenbrock, Powell::new(vec![0.2, 0.75]), 500);
        println!(
            "Powell Rosenbrock 2-D: {evals} evaluations, {sweeps} sweeps, f = {f:e}, x = {x:?}"
        );
        assert_close(&x, &[0.75, 0.75], 1e-6);
    }

    #[test]
    fn minimum_on_bounds() {
        // Unconstrained minimum at (1.3, -0.2, 0.4); in the box (1, 0, 0.4).
        let problem = Sphere {
            centre: vec![1.3, -0.2, 0.4],
        };
        let (x, _, _, evals) = run(problem, Powell::new(vec![0.5, 0.5, 0.5]), 100);
        println!("Powell minimum on bounds: {evals} evaluations, x = {x:?}");
        assert_eq!(x[0], 1.0);
        assert_eq!(x[1], 0.0);
        assert!((x[2] - 0.4).abs() < 1e-6);
    }

    #[test]
    fn tilted_valley_into_a_corner() {
        // Correlated quadratic whose unconstrained minimum lies outside the box;
        // the constrained minimum is on the face x0 = 1.
        struct Tilted;
        impl CostFunction for Tilted {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
                let (a, b) = (x[0] - 1.5, x[1] - 0.2);
                Ok(a * a + 1.8 * a * b + b * b)
            }
        }
        let (x, _, _, _) = run(Tilted, Powell::new(vec![0.1, 0.9]), 200);
        // On x0 = 1: d/dx1 = 1.8 a + 2 b = 0 with a = -0.5 gives x1 = 0.65.
        assert_eq!(x[0], 1.0);
        assert!((x[1] - 0.65).abs() < 1e-6, "{x:?}");
    }

    #[test]
    fn deterministic() {
        let a = run(Rosenbrock, Powell::new(vec![0.2, 0.75]), 500);
        let b = run(Rosenbrock, Powell::new(vec![0.2, 0.75]), 500);
        assert_eq!(a.0, b.0);
        assert_eq!(a.1.to_bits(), b.1.to_bits());
        assert_eq!(a.3, b.3);
    }

    #[test]
    fn stays_in_box_and_batches() {
        let problem = Recorder::new(Rosenbrock);
        let res = Executor::new(problem, Powell::new(vec![0.05, 0.95]))
            .configure(|s| s.max_iters(500))
            .run()
            .unwrap();
        let evals = res.problem.counts["cost_count"] as usize;
        let recorder = res.problem.problem.as_ref().unwrap();
        let points = recorder.points.lock().unwrap();
        let batches = recorder.batch_sizes.lock().unwrap();
        let singles = *recorder.single_calls.lock().unwrap();
        assert_eq!(points.len(), evals);
        assert!(points
            .iter()
            .all(|p| p.iter().all(|v| (0.0..=1.0).contains(v))));
        let batched: usize = batches.iter().sum();
        assert_eq!(batched + singles, evals);
        println!(
            "Powell batching: {evals} evaluations, {batched} in {} batches, {singles} single",
            batches.len()
        );
        assert!(!batches.is_empty());
        assert!(batches.iter().all(|&b| b >= 1));
        assert!(batched * 3 >= evals, "too few batched evaluations");
    }

    #[test]
    fn nan_costs_are_avoided() {
        // NaN outside a disc around the start: the solver must stay inside it.
        struct Holey;
        impl CostFunction for Holey {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
                if (x[0] - 0.5).powi(2) + (x[1] - 0.5).powi(2) > 0.16 {
                    Ok(f64::NAN)
                } else {
                    Ok((x[0] - 0.6).powi(2) + (x[1] - 0.45).powi(2))
                }
            }
        }
        let (x, _, _, _) = run(Holey, Powell::new(vec![0.5, 0.5]), 100);
        assert_close(&x, &[0.6, 0.45], 1e-6);
    }

    #[test]
    fn errors_propagate() {
        struct Failing;
        impl CostFunction for Failing {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, x: &Vec<f64>) -> Result<f64, Error> {
                if x[0] > 0.6 {
                    Err(Error::msg("simulation failed"))
                } else {
                    Ok(x[0])
                }
            }
        }
        let res = Executor::new(Failing, Powell::new(vec![0.5]))
            .configure(|s| s.max_iters(10))
            .run();
        assert!(res.is_err());
    }

    #[test]
    fn invalid_settings_are_rejected() {
        assert!(Powell::new(vec![0.5]).with_xtol(0.0).is_err());
        assert!(Powell::new(vec![0.5]).with_xtol(f64::NAN).is_err());
        assert!(Powell::new(vec![0.5]).with_ftol(-1.0, 0.0).is_err());
        assert!(Powell::new(vec![0.5]).with_bracket_points(1).is_err());
        assert!(Powell::new(vec![0.5]).with_initial_step(0.0).is_err());
        assert!(Powell::new(vec![0.5]).with_initial_step(1.5).is_err());
        assert!(Powell::new(vec![0.5])
            .with_xtol(1e-6)
            .and_then(|p| p.with_ftol(1e-8, 0.0))
            .and_then(|p| p.with_bracket_points(6))
            .and_then(|p| p.with_initial_step(0.1))
            .is_ok());
        let outside = Executor::new(
            Sphere {
                centre: vec![0.5, 0.5],
            },
            Powell::new(vec![0.5, 1.2]),
        )
        .configure(|s| s.max_iters(10))
        .run();
        assert!(outside.is_err());
    }

    #[test]
    fn rosenbrock_2d_from_many_starts() {
        let mut total = 0;
        for i in 0..7 {
            for j in 0..7 {
                let start = vec![0.05 + 0.15 * i as f64, 0.05 + 0.15 * j as f64];
                let (x, _, _, evals) = run(Rosenbrock, Powell::new(start), 1000);
                assert_close(&x, &[0.75, 0.75], 1e-6);
                total += evals;
            }
        }
        println!(
            "Powell Rosenbrock 2-D, 49 starts: {} evaluations on average",
            total / 49
        );
    }

    #[test]
    fn ill_conditioned_quadratic_6d() {
        // Eigenvalues spread over four decades; many starts run into bounds on
        // the way to the interior minimum.
        struct IllConditioned;
        impl CostFunction for IllConditioned {
            type Param = Vec<f64>;
            type Output = f64;
            fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
                let n = u.len();
                Ok((0..n)
                    .map(|k| {
                        let s: f64 = (0..n)
                            .map(|j| {
                                let a =
                                    ((k * k * 7 + j * j * 3 + k * j * 5 + j) as f64 * 0.61).sin();
                                a * (u[j] - 0.3 - 0.05 * j as f64)
                            })
                            .sum();
                        10f64.powf(0.8 * k as f64) * s * s
                    })
                    .sum())
            }
        }
        let mut total = 0;
        for i in 0..10 {
            let start: Vec<f64> = (0..6)
                .map(|j| ((i * 7 + j * 3) % 10) as f64 / 10.0 + 0.05)
                .collect();
            let (x, _, _, evals) = run(IllConditioned, Powell::new(start), 3000);
            let expected: Vec<f64> = (0..6).map(|j| 0.3 + 0.05 * j as f64).collect();
            assert_close(&x, &expected, 1e-6);
            total += evals;
        }
        println!(
            "Powell ill-conditioned 6-D quadratic: {} evaluations on average",
            total / 10
        );
    }
}
