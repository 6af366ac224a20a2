//! Step 5b of a diagnosis, backward elimination: forward selection adds an effect when its
//! refit beats the set before it, but the set before it was fitted from the baseline's
//! optimum and may have stopped short, so a later effect can be credited with what a better
//! fit of the earlier ones removes (a two-effect record then gets three). Once a set of two
//! or more is selected, each of its effects is taken out in turn and the rest refitted from
//! the selected fit's own point (every other parameter where the richer fit left it, a
//! local Nelder–Mead run); an effect goes when the set without it is not decisively worse by
//! the same rule that selects ([`verdict::improves`]: the information criterion and the
//! held-out error), or when the set without it already leaves nothing but noise
//! ([`Floor::holds`], the test with a stated false-positive rate). The second rule matters on
//! long records: there the criterion calls a decrease of a percent or two decisive, and a
//! spurious effect that absorbs what a fit of the others stopped short of (or a small
//! difference between the model and the process that made the record) earns it, while the
//! record gives no reason to look past a set whose residual is noise. The weakest such
//! effect goes first, and the rest is pruned again.

use super::candidates::refit_campaign_from;
use super::fit::fit_of;
use super::refit::local_refit;
use super::verdict::{self, Floor};
use super::Fit;
use calib_engine::calibration::calibrate;
use calib_engine::campaign::Campaign;
use calib_engine::error::Result;
use calib_engine::evaluator::{Evaluator, Simulator};
use calib_engine::objective::Objective;
use calib_engine::optim::problem::Progress;

/// `chosen` without the effects it does not need, and the refits made to find out (the
/// report lists them beside the others).
pub(super) fn prune<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    chosen: Fit,
    engine: &E,
    progress: &dyn Progress,
    holdout: &Objective,
    floor: &Floor,
) -> Result<(Fit, Vec<Fit>)> {
    let mut chosen = chosen;
    let mut tried = Vec::new();
    while chosen.effects.len() >= 2 {
        let without = without_each(fit_campaign, &chosen, engine, progress, holdout)?;
        // The set whose loss matters least, if the richer one does not beat it or it leaves
        // nothing but noise itself.
        let weakest = without
            .iter()
            .filter(|f| !verdict::improves(&chosen, f) || floor.holds(f.objective))
            .min_by(|a, b| {
                a.objective
                    .total_cmp(&b.objective)
                    .then_with(|| a.effects.cmp(&b.effects))
            })
            .cloned();
        tried.extend(without);
        match weakest {
            Some(fit) => {
                tracing::debug!(kept = ?fit.effects, from = ?chosen.effects, "effect pruned");
                chosen = fit;
            }
            None => break,
        }
    }
    Ok((chosen, tried))
}

/// The refits of `chosen` with each of its effects taken out, concurrently.
fn without_each<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    chosen: &Fit,
    engine: &E,
    progress: &dyn Progress,
    holdout: &Objective,
) -> Result<Vec<Fit>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = chosen
            .effects
            .iter()
            .map(|out| {
                scope.spawn(move || -> Result<Fit> {
                    let kept: Vec<String> = chosen
                        .effects
                        .iter()
                        .filter(|e| *e != out)
                        .cloned()
                        .collect();
                    let campaign = local_refit(&refit_campaign_from(fit_campaign, chosen, out));
                    let calibration = calibrate(&campaign, engine, progress)?;
                    fit_of(&calibration, &kept, engine, holdout)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    })
}
