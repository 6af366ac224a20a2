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
//!
//! ## Modules
//!
//! * this module: the settings, the state and the sweeps of the solver;
//! * `line_search`: the segment of a line inside the box and the batched bracketing
//!   of its minimum;
//! * `brent`: Brent's refinement of a bracketed line minimum;
//! * `directions`: the direction set, its reset to the axes and Powell's replacement
//!   rule.

mod brent;
mod directions;
mod line_search;
#[cfg(test)]
mod tests;

use self::directions::Sweep;
use self::line_search::point_on_line;
use super::{check_start, invalid, sanitize};
use argmin::core::{
    ArgminError, CostFunction, Error, IterState, Problem, Solver, SyncAlias, TerminationReason,
    TerminationStatus, KV,
};

/// The argmin state Powell's method works with.
pub type PowellState = IterState<Vec<f64>, (), (), (), (), f64>;

/// Relative part of the line-search tolerance: line minima are located to 1% of
/// the distance moved (Numerical Recipes uses 2e-4). Loose line searches save
/// evaluations far from the minimum; the absolute part `xtol / 4` takes over as
/// the steps shrink.
const LINE_REL_TOL: f64 = 1e-2;

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

        let sweep = Sweep {
            x0: &x0,
            f0,
            biggest_drop,
            biggest_index,
        };
        let (x, fx, replaced) = self.replace_direction(problem, x, fx, &sweep)?;

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

fn distance(a: &[f64], b: &[f64]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(p, q)| (p - q) * (p - q))
        .sum::<f64>()
        .sqrt()
}
