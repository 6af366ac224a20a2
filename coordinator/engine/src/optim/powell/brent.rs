//! Brent's safeguarded parabolic minimisation of a bracketed line minimum (Brent 1973,
//! chapter 5), with the early stop described in the [parent module](super).

use super::Powell;
use argmin::core::{CostFunction, Error, Problem};

/// `(3 - sqrt(5)) / 2`, the golden-section fraction.
const GOLDEN: f64 = 0.381_966_011_250_105_1;
/// Upper bound on Brent iterations per line (never reached on sane problems).
const MAX_BRENT_ITERS: usize = 100;

/// A bracket `[a, b]` with the best (`x`), second best (`w`) and third (`v`) samples.
pub(super) struct Bracket {
    pub a: f64,
    pub b: f64,
    pub x: (f64, f64),
    pub w: (f64, f64),
    pub v: (f64, f64),
}

impl Powell {
    /// Brent's safeguarded parabolic minimisation inside a bracket.
    pub(super) fn brent<O>(
        &self,
        problem: &mut Problem<O>,
        origin: &[f64],
        d: &[f64],
        bracket: Bracket,
    ) -> Result<(f64, f64), Error>
    where
        O: CostFunction<Param = Vec<f64>, Output = f64>,
    {
        let mut state = BrentState::new(bracket);
        for _ in 0..MAX_BRENT_ITERS {
            let mid = 0.5 * (state.a + state.b);
            let tol1 = self.line_tol(state.x);
            let tol2 = 2.0 * tol1;
            if (state.x - mid).abs() <= tol2 - 0.5 * (state.b - state.a) {
                break;
            }
            let Some(u) = state.next_probe(mid, tol1, tol2) else {
                break;
            };
            let fu = self.evaluate_one(problem, origin, d, u)?;
            state.update(u, fu);
        }
        Ok((state.x, state.fx))
    }
}

/// What the parabolic step through the three best samples proposes.
enum Parabola {
    /// The (convex) parabola puts the minimum within the tolerance of the best point.
    Converged,
    /// The parabolic step was accepted and stored as the next step.
    Accepted,
    /// The parabolic step was unusable: a golden-section step is taken instead.
    Rejected,
}

/// The state Brent's iterations share: the bracket, its three best samples and the
/// lengths of the last two steps.
struct BrentState {
    a: f64,
    b: f64,
    x: f64,
    fx: f64,
    w: f64,
    fw: f64,
    v: f64,
    fv: f64,
    /// Step of the last iteration.
    step: f64,
    /// Step of the iteration before the last.
    older_step: f64,
}

impl BrentState {
    /// Unpacks `bracket` and seeds the step history from its width.
    fn new(bracket: Bracket) -> Self {
        let Bracket {
            a,
            b,
            x: (x, fx),
            w: (w, fw),
            v: (v, fv),
        } = bracket;
        // Steps of the last two iterations; seeded with the bracket width so the
        // first steps may already be parabolic.
        let step = b - a;
        let older_step = b - a;
        BrentState {
            a,
            b,
            x,
            fx,
            w,
            fw,
            v,
            fv,
            step,
            older_step,
        }
    }

    /// The next point to evaluate: parabolic when the parabola is trusted, golden
    /// section otherwise, never closer than `tol1` to `x`; `None` stops early.
    fn next_probe(&mut self, mid: f64, tol1: f64, tol2: f64) -> Option<f64> {
        let mut golden = true;
        if self.older_step.abs() > tol1 {
            match self.parabolic_step(mid, tol1, tol2) {
                Parabola::Converged => return None,
                Parabola::Accepted => golden = false,
                Parabola::Rejected => {}
            }
        }
        if golden {
            self.golden_step(mid);
        }
        let (x, step) = (self.x, self.step);
        let u = if step.abs() >= tol1 {
            x + step
        } else {
            x + tol1.copysign(step)
        };
        Some(u)
    }

    /// Tries the step to the vertex of the parabola through the three best samples,
    /// storing it as `step` when it is safe (the step history shifts whether it is taken or
    /// not; a converged parabola leaves it).
    fn parabolic_step(&mut self, mid: f64, tol1: f64, tol2: f64) -> Parabola {
        let BrentState {
            a,
            b,
            x,
            fx,
            w,
            fw,
            v,
            fv,
            ..
        } = *self;
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
            return Parabola::Converged;
        }
        let limit = self.older_step;
        self.older_step = self.step;
        // Accept only a step that is less than half the step before last
        // and falls inside the bracket (NaN fails every test).
        if p.abs() < (0.5 * q * limit).abs() && p > q * (a - x) && p < q * (b - x) {
            self.step = p / q;
            let u = x + self.step;
            if u - a < tol2 || b - u < tol2 {
                self.step = tol1.copysign(mid - x);
            }
            return Parabola::Accepted;
        }
        Parabola::Rejected
    }

    /// A golden-section step into the larger part of the bracket.
    fn golden_step(&mut self, mid: f64) {
        let (a, b, x) = (self.a, self.b, self.x);
        self.older_step = if x >= mid { a - x } else { b - x };
        self.step = GOLDEN * self.older_step;
    }

    /// Shrinks the bracket around the best point and reranks the samples after
    /// evaluating `fu` at `u`.
    fn update(&mut self, u: f64, fu: f64) {
        let x = self.x;
        if fu <= self.fx {
            if u >= x {
                self.a = x;
            } else {
                self.b = x;
            }
            (self.v, self.fv) = (self.w, self.fw);
            (self.w, self.fw) = (self.x, self.fx);
            (self.x, self.fx) = (u, fu);
        } else {
            if u < x {
                self.a = u;
            } else {
                self.b = u;
            }
            if fu <= self.fw || self.w == x {
                (self.v, self.fv) = (self.w, self.fw);
                (self.w, self.fw) = (u, fu);
            } else if fu <= self.fv || self.v == x || self.v == self.w {
                (self.v, self.fv) = (u, fu);
            }
        }
    }
}
