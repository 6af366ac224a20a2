//! Fair refits: a candidate is judged after a refit that reaches its own minimum, whatever
//! search settings the campaign gave for its baseline.
//!
//! The local refits ([`super::refit::local_refit`]) are one Nelder–Mead run each from where
//! the ranking left off. Where that is not enough (no candidate leaves only noise, or one does
//! while a candidate the ranking put above it did not), the leading candidates are refitted
//! again with the diagnosis's own search, the same for every campaign:
//!
//! 1. Nelder–Mead from every informed start (the baseline optimum with the candidate at its
//!    linear estimate and at its ranking estimate, where the ranking's descent ended, where
//!    the local refit ended, larger sizes) and from screened starts of the whole box, each
//!    stopped when its objective stops moving ([`FAIR_BUDGET`] evaluations at most);
//! 2. from the best of them, Nelder–Mead and Powell again, repeated while a round lowers the
//!    objective by more than [`POLISH_RELATIVE`] of itself ([`POLISH_ROUNDS`] at most).
//!
//! The same search refits the baseline when it is above the noise floor and the campaign's
//! own runs do not corroborate it ([`corroborated`]): a baseline left short of its own
//! minimum by the campaign's search would let any effect "explain" what a better fit of the
//! same model removes.

use super::candidates::refit_campaign;
use super::fit::fit_of;
use super::refit::{STALL_RELATIVE, STALL_WINDOW_PER_PARAMETER};
use super::{Candidate, Fit};
use crate::report::evidence::best_threshold;
use calib_engine::calibration::{calibrate, Calibration};
use calib_engine::campaign::{Campaign, FreeParameter, Method};
use calib_engine::error::Result;
use calib_engine::evaluator::{Evaluator, Simulator};
use calib_engine::objective::Objective;
use calib_engine::optim::budget::Stall;
use calib_engine::optim::problem::Progress;

/// Evaluations at most of each run of a fair refit.
pub const FAIR_BUDGET: usize = 400;
/// Screened starts of the whole box a fair refit adds to its informed starts.
pub const FAIR_STARTS: usize = 4;
/// Most polishing rounds (Nelder–Mead and Powell from the best point so far).
pub const POLISH_ROUNDS: usize = 3;
/// A polishing round that lowers the objective by less than this share of it is the last.
pub const POLISH_RELATIVE: f64 = 1e-4;
/// Candidates refitted fairly at most: the leading few.
pub const LEADING: usize = 3;

/// The diagnosis's own search on `c`: Nelder–Mead from every start, stopped when the
/// objective stops moving.
fn first_stage(mut c: Campaign) -> Campaign {
    c.search.methods = vec![Method::NelderMead];
    c.search.starts = FAIR_STARTS;
    c.search.screening = None;
    c.search.max_evaluations = FAIR_BUDGET;
    c.search.stall = Some(Stall {
        window: STALL_WINDOW_PER_PARAMETER * (c.free.len() as u64 + 1),
        relative: STALL_RELATIVE,
    });
    c
}

/// Nelder–Mead and Powell from `point` alone.
fn polish_stage(c: &Campaign, point: &[f64]) -> Campaign {
    let mut c = c.clone();
    for (p, v) in c.free.iter_mut().zip(point) {
        p.nominal = v.clamp(p.min, p.max);
    }
    c.search.extra_starts.clear();
    c.search.methods = vec![Method::NelderMead, Method::Powell];
    c.search.starts = 1;
    c.search.screening = Some(0);
    c
}

/// Minimise `c` with the diagnosis's own search (module documentation): the calibration of
/// the last round and the evaluations of all of them.
fn minimise<E: Evaluator>(
    c: Campaign,
    engine: &E,
    progress: &dyn Progress,
) -> Result<(Calibration, usize)> {
    let first = first_stage(c);
    let mut best = calibrate(&first, engine, progress)?;
    let mut evaluations = best.evaluations();
    for _ in 0..POLISH_ROUNDS {
        let before = best.best_run().objective;
        let round = calibrate(
            &polish_stage(&first, &best.best_run().point),
            engine,
            progress,
        )?;
        evaluations += round.evaluations();
        let after = round.best_run().objective;
        if after < before {
            best = round;
        }
        if after >= before * (1.0 - POLISH_RELATIVE) || after.is_nan() {
            break;
        }
    }
    Ok((best, evaluations))
}

/// The fair refit of the effects of `set` (the baseline's parameters alone when empty),
/// also started from where `previous` refits of the same set ended.
#[allow(clippy::too_many_arguments)]
pub(super) fn fair_refit<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    baseline: &Fit,
    set: &[&Candidate],
    specs: &[FreeParameter],
    previous: &[&Fit],
    engine: &E,
    progress: &dyn Progress,
    holdout: &Objective,
) -> Result<Fit> {
    let mut c = refit_campaign(fit_campaign, baseline, set, specs);
    // The baseline optimum with each effect at the score test's own estimate.
    let mut linear = baseline.point.clone();
    linear.extend(set.iter().map(|c| c.linear_estimate));
    c.search.extra_starts.push(linear);
    for fit in previous {
        if fit.point.len() == c.free.len() {
            c.search.extra_starts.push(fit.point.clone());
        }
    }
    let free = c.free.clone();
    for start in c.search.extra_starts.iter_mut() {
        for (v, p) in start.iter_mut().zip(&free) {
            *v = v.clamp(p.min, p.max);
        }
    }
    c.search.extra_starts.dedup();
    let (calibration, evaluations) = minimise(c, engine, progress)?;
    let names: Vec<String> = set.iter().map(|c| c.effect.clone()).collect();
    let mut fit = fit_of(&calibration, &names, engine, holdout)?;
    fit.evaluations = evaluations;
    Ok(fit)
}

/// Fair refits of several sets at once, in the order given.
#[allow(clippy::too_many_arguments)]
pub(super) fn fair_refits<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    baseline: &Fit,
    sets: &[Vec<&Candidate>],
    specs: &[FreeParameter],
    previous: &[Fit],
    engine: &E,
    progress: &dyn Progress,
    holdout: &Objective,
) -> Result<Vec<Fit>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = sets
            .iter()
            .map(|set| {
                let names: Vec<&str> = set.iter().map(|c| c.effect.as_str()).collect();
                let before: Vec<&Fit> = previous
                    .iter()
                    .filter(|f| {
                        f.effects
                            .iter()
                            .map(String::as_str)
                            .eq(names.iter().copied())
                    })
                    .collect();
                scope.spawn(move || {
                    fair_refit(
                        fit_campaign,
                        baseline,
                        set,
                        specs,
                        &before,
                        engine,
                        progress,
                        holdout,
                    )
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    })
}

/// Whether the campaign's own search corroborates its optimum: runs from at least two
/// different starts reached its best objective (within the tolerance the report counts
/// "runs at best" with). A baseline that is not corroborated gets a fair refit.
pub fn corroborated(calibration: &Calibration) -> bool {
    let threshold = best_threshold(calibration.best_run().objective);
    let mut starts: Vec<usize> = calibration
        .runs
        .iter()
        .filter(|r| r.objective <= threshold)
        .map(|r| r.start)
        .collect();
    starts.sort_unstable();
    starts.dedup();
    starts.len() >= 2
}
