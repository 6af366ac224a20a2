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
}
