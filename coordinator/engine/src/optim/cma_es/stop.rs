//! When a descent ends (Hansen 2016, appendix B.3; Auger and Hansen 2005), in the unit box
//! and with the tolerances of the other solvers (relative to the objective at the nominal
//! point, which the run divides the objective by).

use super::strategy::Descent;

/// Why a descent ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reason {
    /// TolFun: the best costs of the recent generations and the costs of the last all lie
    /// within the cost tolerance.
    TolFun,
    /// TolX: every coordinate's standard deviation and evolution path below `XTOL`.
    TolX,
    /// The median of the recent best costs no better than that of the earlier ones.
    Stagnation,
    /// The covariance matrix's condition number above `MAX_CONDITION`.
    Condition,
}

impl Reason {
    pub fn words(self) -> &'static str {
        match self {
            Reason::TolFun => "tolfun",
            Reason::TolX => "tolx",
            Reason::Stagnation => "stagnation",
            Reason::Condition => "condition",
        }
    }
}

/// Extent (unit box) below which a descent has converged in `x`: the population extent at
/// which differential evolution stops.
pub const XTOL: f64 = 1e-6;
/// Relative and absolute cost tolerance, as differential evolution's.
pub const FTOL_REL: f64 = 1e-8;
pub const FTOL_ABS: f64 = 1e-12;
/// Largest condition number of the covariance matrix.
pub const MAX_CONDITION: f64 = 1e14;

/// The best cost of each generation of a descent, for TolFun and stagnation.
#[derive(Clone, Debug, Default)]
pub struct History {
    pub best: Vec<f64>,
}

/// Whether `descent`, whose last generation's costs are `costs`, should end, and why.
pub fn check(descent: &Descent, history: &History, costs: &[f64]) -> Option<Reason> {
    let n = descent.mean.len();
    let lambda = descent.p.lambda as f64;
    let generations = history.best.len();
    let best = history.best.iter().copied().fold(f64::INFINITY, f64::min);
    let tolerance = FTOL_REL * best.abs() + FTOL_ABS;
    // TolFun over the last 10 + ⌈30 n / λ⌉ generations and the last one's costs.
    let window = 10 + (30.0 * n as f64 / lambda).ceil() as usize;
    if generations >= window {
        let recent = &history.best[generations - window..];
        let lo = recent
            .iter()
            .chain(costs)
            .copied()
            .fold(f64::INFINITY, f64::min);
        let hi = recent
            .iter()
            .chain(costs)
            .copied()
            .fold(f64::NEG_INFINITY, f64::max);
        if hi - lo <= tolerance {
            return Some(Reason::TolFun);
        }
    }
    let tolx = (0..n).all(|i| {
        let sd = descent.sigma * descent.c[(i, i)].sqrt();
        sd < XTOL && descent.sigma * descent.pc[i].abs() < XTOL
    });
    if tolx {
        return Some(Reason::TolX);
    }
    if descent.condition() > MAX_CONDITION {
        return Some(Reason::Condition);
    }
    // Stagnation: over the last 120 + 30 n / λ generations or more (at most 20,000), the
    // median of the newest 30% of best costs no better than that of the oldest 30%.
    let span = 120 + (30.0 * n as f64 / lambda).ceil() as usize;
    let span = span.max(generations / 5).min(20_000);
    if generations >= span {
        let recent = &history.best[generations - span..];
        let part = (3 * span / 10).max(1);
        if median(&recent[span - part..]) >= median(&recent[..part]) {
            return Some(Reason::Stagnation);
        }
    }
    None
}

fn median(values: &[f64]) -> f64 {
    let mut sorted = values.to_vec();
    sorted.sort_by(f64::total_cmp);
    sorted[sorted.len() / 2]
}
