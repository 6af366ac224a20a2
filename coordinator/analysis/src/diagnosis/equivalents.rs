//! Step 8 of a diagnosis: which other explanations the record cannot tell from the selected
//! one. Two effects at one place can leave signatures that differ by less than the noise (a
//! sensor's dead time and its first-order lag of the same size; a constant torque and a
//! spring on a joint that holds nearly one angle). A verdict that names one of them alone
//! claims more than the record says.
//!
//! For every selected effect and every other candidate acting at the same place (the same
//! joint, or the same output), the selection with the one swapped for the other is refitted
//! locally from the selected fit's point. A swap whose refit also leaves nothing but noise
//! ([`Floor::holds`], the test with a stated false-positive rate) is an equivalent: the report
//! names it beside the selection, and where it fits better it becomes the selection (the
//! swap's refit starts from the selected fit, so it can end below it). Runs only when the
//! selection explains the record.
//!
//! A swap whose set was refitted already (a single selection's swaps are the other singles)
//! and left more than [`SETTLED_FAR`] times the noise limit is not refitted again: that
//! refit is its answer. A second local refit from another start that removes nine tenths of
//! what the first left is not what either search does; the hx lag example's two such swaps
//! ended within 0.01% of their first refits, at 33× and 175× the floor, for 314 simulations.

use super::candidates::{refit_campaign_from, scaled};
use super::fit::fit_of;
use super::refit::local_refit;
use super::verdict::Floor;
use super::{Candidate, Fit};
use calib_engine::calibration::calibrate;
use calib_engine::campaign::{Campaign, FreeParameter};
use calib_engine::error::Result;
use calib_engine::evaluator::{Evaluator, Simulator};
use calib_engine::objective::Objective;
use calib_engine::optim::problem::Progress;

/// A swap whose set's earlier refit left more than this many times the noise limit is
/// answered by that refit.
pub const SETTLED_FAR: f64 = 10.0;

/// Where an effect acts: the output inside its parentheses (`lag(armJoint.phi)`), else the
/// joint after its last dot (`torque_bias.arm`), else its whole name.
pub fn place(effect: &str) -> &str {
    if let (Some(open), Some(close)) = (effect.find('('), effect.rfind(')')) {
        if open < close {
            return &effect[open + 1..close];
        }
    }
    effect.rsplit_once('.').map_or(effect, |(_, p)| p)
}

/// The swaps of `chosen`'s effects for candidates at the same place whose refits also
/// leave nothing but noise (lowest objective first), and every refit made to find out.
/// `earlier`: the refits made so far, which answer the swaps they settled far from noise
/// (those are not refitted, nor among the refits returned).
#[allow(clippy::too_many_arguments)]
pub(super) fn equivalents<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    chosen: &Fit,
    candidates: &[Candidate],
    specs: &[FreeParameter],
    engine: &E,
    progress: &dyn Progress,
    holdout: &Objective,
    floor: &Floor,
    earlier: &[Fit],
) -> Result<(Vec<Fit>, Vec<Fit>)> {
    let swaps: Vec<(&str, &Candidate)> = chosen
        .effects
        .iter()
        .flat_map(|out| {
            candidates
                .iter()
                .filter(move |c| {
                    !chosen.effects.contains(&c.effect) && place(&c.effect) == place(out)
                })
                .map(move |c| (out.as_str(), c))
        })
        .collect();
    let (answered, swaps): (Vec<_>, Vec<_>) = swaps
        .into_iter()
        .partition(|&(out, with)| settled_far(chosen, out, with, earlier, floor).is_some());
    for (out, with) in &answered {
        tracing::debug!(out, with = %with.effect, "swap answered by its earlier refit");
    }
    let tried: Vec<Fit> = std::thread::scope(|scope| {
        let handles: Vec<_> = swaps
            .iter()
            .map(|&(out, with)| {
                scope.spawn(move || -> Result<Fit> {
                    let campaign = swap_campaign(fit_campaign, chosen, out, with, specs);
                    let calibration = calibrate(&local_refit(&campaign), engine, progress)?;
                    let effects: Vec<String> = chosen
                        .effects
                        .iter()
                        .map(|e| {
                            if e == out {
                                with.effect.clone()
                            } else {
                                e.clone()
                            }
                        })
                        .collect();
                    fit_of(&calibration, &effects, engine, holdout)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect::<Result<Vec<Fit>>>()
    })?;
    let mut equivalent: Vec<Fit> = tried
        .iter()
        .filter(|f| floor.holds(f.objective))
        .cloned()
        .collect();
    equivalent.sort_by(|a, b| a.objective.total_cmp(&b.objective));
    Ok((equivalent, tried))
}

/// The refit among `earlier` of `chosen`'s set with `out` swapped for `with`, where it left
/// more than [`SETTLED_FAR`] times the noise limit.
fn settled_far<'e>(
    chosen: &Fit,
    out: &str,
    with: &Candidate,
    earlier: &'e [Fit],
    floor: &Floor,
) -> Option<&'e Fit> {
    let mut set: Vec<&str> = chosen
        .effects
        .iter()
        .map(|e| {
            if e == out {
                with.effect.as_str()
            } else {
                e.as_str()
            }
        })
        .collect();
    set.sort_unstable();
    earlier.iter().find(|f| {
        let mut effects: Vec<&str> = f.effects.iter().map(String::as_str).collect();
        effects.sort_unstable();
        effects == set && f.objective > SETTLED_FAR * floor.limit * floor.value
    })
}

/// `chosen`'s refit with `out` held off and `with` free, every other parameter starting where
/// `chosen` left it and `with` at its ranking's estimate.
fn swap_campaign(
    fit_campaign: &Campaign,
    chosen: &Fit,
    out: &str,
    with: &Candidate,
    specs: &[FreeParameter],
) -> Campaign {
    let mut c = refit_campaign_from(fit_campaign, chosen, out);
    let free = scaled(with, specs);
    c.free.push(FreeParameter {
        nominal: with.estimate.clamp(free.min, free.max),
        ..free
    });
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_effect_acts_at_its_output_or_its_joint() {
        assert_eq!(place("lag(armJoint.phi)"), "armJoint.phi");
        assert_eq!(place("delay(armJoint.phi)"), place("lag(armJoint.phi)"));
        assert_eq!(place("torque_bias.arm"), "arm");
        assert_eq!(place("stiffness.arm"), place("torque_bias.arm"));
        assert_ne!(place("stiffness.pendulum"), place("stiffness.arm"));
        assert_ne!(place("offset(armJoint.phi)"), place("torque_bias.arm"));
        assert_eq!(place("ambient_loss"), "ambient_loss");
    }
}
