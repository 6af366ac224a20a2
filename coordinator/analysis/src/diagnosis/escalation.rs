//! When the refits of the leading candidates leave more than noise: look further, within a
//! bounded budget, so that the verdict does not hang on which basin the campaign's search
//! happened to settle in, nor on which three candidates the first ranking put ahead.
//!
//! 1. **Other basins** ([`other_basins`]): the campaign's own runs may have found minima the
//!    baseline left behind, where the model behaves differently (a joint held stuck in the
//!    baseline's, moving in another). An effect that acts only on a moving joint (a spring)
//!    has no influence at the baseline and ranks 0 there. The candidates are ranked again
//!    from up to [`OTHER_BASINS`] minima whose predictions differ from the baseline's and from
//!    each other's by more than [`SAME_BASIN`] of their objective; each candidate keeps its
//!    better ranking (as a share of the baseline in use), and where that changes which
//!    candidates lead, they are refitted as the first ones were.
//! 2. **Every candidate** ([`every_single`]): while the selection leaves more than noise,
//!    each candidate not yet refitted is refitted alone with the diagnosis's own search. The
//!    ranking is a first-order estimate at the baseline; it orders the work, and decides what
//!    is tried only when its leaders settle the record.
//! 3. **Forward steps** ([`forward`]): while the selected refit still leaves more than noise,
//!    the candidates not in it are ranked from its optimum, and the leading
//!    [`FORWARD_CANDIDATES`] of them are refitted together with it (one effect more), at most
//!    [`FORWARD_STEPS`] times. A second effect the first ranking put fourth (the real rig's
//!    pendulum friction, once the arm's is in) is found that way.
//!
//! None runs when the first refits already leave nothing but noise, so a diagnosis that
//! the first refits settle costs what it did.

use super::fair::fair_refits;
use super::ranking;
use super::refit::{refit_and_select, Judgement};
use super::verdict::{self, Floor};
use super::{Candidate, Fit};
use crate::residuals::jacobian::stack;
use calib_engine::calibration::Calibration;
use calib_engine::campaign::{Campaign, FreeParameter};
use calib_engine::error::Result;
use calib_engine::evaluator::{Evaluator, Simulator};
use calib_engine::measurement::Measurement;
use calib_engine::objective::Objective;
use calib_engine::optim::multistart::Stop;
use calib_engine::optim::problem::Progress;

/// Other minima of the campaign's runs the candidates are ranked from, at most.
pub const OTHER_BASINS: usize = 3;
/// Two minima whose predictions differ (weighted sum of squares, as the objective) by less
/// than this share of the smaller objective are one basin: ranking from both would say the
/// same.
pub const SAME_BASIN: f64 = 0.1;
/// Forward steps (one effect more each) at most.
pub const FORWARD_STEPS: usize = 2;
/// Candidates refitted together with the selected effects at each forward step.
pub const FORWARD_CANDIDATES: usize = 2;

/// What every step of the escalation works with.
pub(super) struct Setting<'a, E> {
    pub fit_campaign: &'a Campaign,
    pub measurement: &'a Measurement,
    pub engine: &'a E,
    pub progress: &'a dyn Progress,
    pub baseline: &'a Fit,
    pub specs: &'a [FreeParameter],
    pub holdout: &'a Objective,
    pub floor: Floor,
}

impl<E: Evaluator + Simulator> Setting<'_, E> {
    fn explains(&self, fit: &Fit) -> bool {
        verdict::explains(fit, self.baseline, &self.floor)
    }
}

/// Escalate `first` (the judgement of the first refits) when it leaves more than noise:
/// other basins, then forward steps. The judgement to keep.
pub(super) fn escalate<E: Evaluator + Simulator>(
    s: &Setting<E>,
    first: Judgement,
    calibration: &Calibration,
    candidates: &mut [Candidate],
) -> Result<Judgement> {
    if matches!(
        first.verdict,
        verdict::Verdict::Explained | verdict::Verdict::Noise
    ) {
        return Ok(first);
    }
    let mut refits = first.refits;
    from_other_basins(s, calibration, candidates, &mut refits)?;
    every_single(s, candidates, &mut refits)?;
    forward_steps(s, &mut refits)?;
    for c in candidates.iter_mut() {
        if let Some(f) = refits
            .iter()
            .find(|f| f.effects.len() == 1 && f.effects[0] == c.effect)
        {
            c.objective = Some(f.objective);
        }
    }
    let chosen = verdict::select(s.baseline, &refits);
    let (verdict, explained_fraction) = verdict::judge(s.baseline, chosen, &s.floor);
    let (final_fit, selected) = match chosen {
        None => (s.baseline.clone(), Vec::new()),
        Some(fit) => (fit.clone(), fit.effects.clone()),
    };
    Ok(Judgement {
        refits,
        selected,
        final_fit,
        verdict,
        explained_fraction,
    })
}

/// Step (a): rank the candidates again from the other basins of the campaign's runs
/// ([`other_basins`]), each keeping its better score; where that changes which candidates
/// lead, refit them as the first ones were, into `refits`.
fn from_other_basins<E: Evaluator + Simulator>(
    s: &Setting<E>,
    calibration: &Calibration,
    candidates: &mut [Candidate],
    refits: &mut Vec<Fit>,
) -> Result<()> {
    let basins = other_basins(s, calibration)?;
    if basins.is_empty() {
        return Ok(());
    }
    let leading = |c: &[Candidate]| -> Vec<String> {
        c.iter()
            .filter(|c| c.score > 0.0)
            .take(s.fit_campaign.diagnosis.refit)
            .map(|c| c.effect.clone())
            .collect()
    };
    let before = leading(candidates);
    for basin in &basins {
        let again = ranking::rank(s.fit_campaign, s.measurement, s.engine, basin, s.specs)?;
        adopt_better(candidates, again, basin.objective, s.baseline.objective);
    }
    candidates.sort_by(|a, b| b.score.total_cmp(&a.score));
    let after = leading(candidates);
    tracing::info!(
        basins = basins.len(),
        ?before,
        ?after,
        "ranked from other basins"
    );
    if after != before {
        let again = refit_and_select(
            s.fit_campaign,
            s.measurement,
            s.engine,
            s.progress,
            s.baseline,
            candidates,
            s.specs,
            s.holdout,
            &s.floor,
        )?;
        merge(refits, again.refits);
    }
    Ok(())
}

/// Step (b): while the selection leaves more than noise, every candidate not yet refitted
/// is refitted alone, with the diagnosis's own search ([`fair_refits`]), into `refits`. The ranking is a first-order estimate
/// made at the baseline; an effect that changes the kind of motion (a Coulomb friction that
/// holds a joint the baseline lets swing) shows at first order only once the other
/// parameters move too, and ranks near 0 there. The ranking decides the order of the work,
/// not what is tried, whenever its leaders have not settled the record.
fn every_single<E: Evaluator + Simulator>(
    s: &Setting<E>,
    candidates: &[Candidate],
    refits: &mut Vec<Fit>,
) -> Result<()> {
    if verdict::select(s.baseline, refits).is_some_and(|f| s.explains(f)) {
        return Ok(());
    }
    let sets: Vec<Vec<&Candidate>> = candidates
        .iter()
        .filter(|c| !refits.iter().any(|f| f.effects == [c.effect.clone()]))
        .map(|c| vec![c])
        .collect();
    if sets.is_empty() {
        return Ok(());
    }
    let fits = fair_refits(
        s.fit_campaign,
        s.baseline,
        &sets,
        s.specs,
        &[],
        s.engine,
        s.progress,
        s.holdout,
    )?;
    tracing::info!(
        refitted = fits.len(),
        best = ?fits
            .iter()
            .min_by(|a, b| a.objective.total_cmp(&b.objective))
            .map(|f| (&f.effects, f.objective)),
        "every other candidate refitted alone"
    );
    merge(refits, fits);
    Ok(())
}

/// Step (c): while the selected refit leaves more than noise, one effect more ([`forward`]),
/// at most [`FORWARD_STEPS`] times; stops as soon as a step changes nothing.
fn forward_steps<E: Evaluator + Simulator>(s: &Setting<E>, refits: &mut Vec<Fit>) -> Result<()> {
    for _ in 0..FORWARD_STEPS {
        let Some(chosen) = verdict::select(s.baseline, refits).cloned() else {
            break;
        };
        if s.explains(&chosen) {
            break;
        }
        let more = forward(s, &chosen, refits)?;
        if more.is_empty() {
            break;
        }
        merge(refits, more);
        let now = verdict::select(s.baseline, refits).map(|f| f.effects.clone());
        if now.as_ref() == Some(&chosen.effects) {
            break;
        }
    }
    Ok(())
}

/// Each candidate keeps the better of its ranking and `again`'s (made from a minimum of
/// objective `from`), the latter scored as a share of the baseline in use (`baseline`): what
/// its descent left there.
pub(super) fn adopt_better(
    candidates: &mut [Candidate],
    again: Vec<Candidate>,
    from: f64,
    baseline: f64,
) {
    for mut other in again {
        let Some(c) = candidates.iter_mut().find(|c| c.effect == other.effect) else {
            continue;
        };
        let left = (1.0 - other.score) * from;
        other.score = (1.0 - left / baseline.max(f64::MIN_POSITIVE)).max(0.0);
        if other.score > c.score {
            *c = other;
        }
    }
}

/// Add `more` to `refits`: a set of effects refitted again keeps its lower objective.
fn merge(refits: &mut Vec<Fit>, more: Vec<Fit>) {
    for fit in more {
        match refits
            .iter_mut()
            .find(|f| same_set(&f.effects, &fit.effects))
        {
            Some(old) if fit.objective < old.objective => *old = fit,
            Some(_) => {}
            None => refits.push(fit),
        }
    }
}

fn same_set(a: &[String], b: &[String]) -> bool {
    a.len() == b.len() && a.iter().all(|e| b.contains(e))
}

/// The minima of the campaign's own runs (in order of objective) whose predictions differ
/// from the baseline's and from each other's by more than [`SAME_BASIN`] of the smaller
/// objective, at most [`OTHER_BASINS`], each as a fit of the campaign's parameters there.
pub(super) fn other_basins<E: Evaluator + Simulator>(
    s: &Setting<E>,
    calibration: &Calibration,
) -> Result<Vec<Fit>> {
    let minima: Vec<(f64, Vec<f64>)> = calibration
        .clusters
        .iter()
        .filter(|k| k.kind == Stop::Minimum && k.objective.is_finite())
        .filter(|k| k.point.len() == s.baseline.point.len() && k.point != s.baseline.point)
        .map(|k| (k.objective, k.point.clone()))
        .collect();
    if minima.is_empty() {
        return Ok(Vec::new());
    }
    let objective = &calibration.objective;
    let mut points = vec![s.baseline.point.clone()];
    points.extend(minima.iter().map(|(_, p)| p.clone()));
    let simulated: Vec<Option<Vec<Vec<f64>>>> = s
        .engine
        .simulate(objective, &points)?
        .into_iter()
        .map(|r| r.ok())
        .collect();
    let stacked = |series: &[Vec<f64>]| stack(series, &objective.weights);
    let Some(at_baseline) = simulated[0].as_deref().map(stacked) else {
        return Ok(Vec::new());
    };
    // (objective, predictions) of the basins kept so far, the baseline's first.
    let mut kept: Vec<(f64, Vec<f64>)> = vec![(s.baseline.objective, at_baseline)];
    let mut basins = Vec::new();
    for ((value, point), series) in minima.iter().zip(&simulated[1..]) {
        if basins.len() == OTHER_BASINS {
            break;
        }
        let Some(series) = series else {
            continue;
        };
        let prediction = stacked(series);
        let distinct = kept.iter().all(|(o, p)| {
            let d: f64 = p
                .iter()
                .zip(&prediction)
                .map(|(a, b)| (a - b).powi(2))
                .sum();
            d > SAME_BASIN * o.min(*value)
        });
        tracing::debug!(
            objective = value,
            ?point,
            distinct,
            "another minimum of the baseline's runs"
        );
        if !distinct {
            continue;
        }
        kept.push((*value, prediction));
        let residual_series = objective
            .measured
            .iter()
            .zip(series)
            .map(|(m, y)| m.iter().zip(y).map(|(a, b)| a - b).collect())
            .collect();
        basins.push(Fit {
            effects: Vec::new(),
            objective: *value,
            point: point.clone(),
            residual_series,
            ..s.baseline.clone()
        });
    }
    Ok(basins)
}

/// One forward step from `chosen` (a refit that leaves more than noise): rank the other
/// candidates from its optimum, and refit the leading [`FORWARD_CANDIDATES`] (those not
/// already `tried` with it) each together with its effects.
fn forward<E: Evaluator + Simulator>(
    s: &Setting<E>,
    chosen: &Fit,
    tried: &[Fit],
) -> Result<Vec<Fit>> {
    let mut campaign = s.fit_campaign.clone();
    campaign.free = chosen.free.clone();
    for (p, v) in campaign.free.iter_mut().zip(&chosen.point) {
        p.nominal = v.clamp(p.min, p.max);
    }
    let specs: Vec<FreeParameter> = s
        .specs
        .iter()
        .filter(|p| !chosen.effects.contains(&p.name))
        .cloned()
        .collect();
    let mut ranked = ranking::rank(&campaign, s.measurement, s.engine, chosen, &specs)?;
    ranked.sort_by(|a, b| b.score.total_cmp(&a.score));
    let with = |c: &Candidate| {
        let mut effects = chosen.effects.clone();
        effects.push(c.effect.clone());
        effects
    };
    let next: Vec<&Candidate> = ranked
        .iter()
        .filter(|c| c.score > 0.0)
        .filter(|c| !tried.iter().any(|f| same_set(&f.effects, &with(c))))
        .take(FORWARD_CANDIDATES)
        .collect();
    tracing::info!(
        from = ?chosen.effects,
        objective = chosen.objective,
        next = ?next.iter().map(|c| (&c.effect, c.score)).collect::<Vec<_>>(),
        "forward step"
    );
    if next.is_empty() {
        return Ok(Vec::new());
    }
    let sets: Vec<Vec<&Candidate>> = next.iter().map(|c| vec![*c]).collect();
    let fits = fair_refits(
        &campaign,
        chosen,
        &sets,
        &specs,
        &[],
        s.engine,
        s.progress,
        s.holdout,
    )?;
    Ok(fits
        .into_iter()
        .zip(&next)
        .map(|(mut fit, c)| {
            fit.effects = with(c);
            fit
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::testing::scored;

    fn candidate(effect: &str, score: f64) -> Candidate {
        Candidate {
            effect: effect.into(),
            score,
            linear_score: score,
            estimate: 0.0,
            linear_estimate: 0.0,
            step: 1e-3,
            objective: None,
            point: Vec::new(),
            centre: 0.0,
        }
    }

    #[test]
    fn a_candidate_ranked_from_another_basin_counts_what_it_leaves_against_the_baseline() {
        // The baseline in use is at 100; another basin at 150, where the spring leaves 1
        // (score 1 − 1/150) and the offset 75 (score 0.5).
        let mut candidates = vec![candidate("offset", 0.2), candidate("spring", 0.0)];
        let again = vec![
            candidate("spring", 1.0 - 1.0 / 150.0),
            candidate("offset", 0.5),
        ];
        adopt_better(&mut candidates, again, 150.0, 100.0);
        // The spring leaves 1 of the baseline's 100: 0.99.
        assert!(
            (candidates[1].score - 0.99).abs() < 1e-12,
            "{}",
            candidates[1].score
        );
        // The offset leaves 75 there, less than the 80 it leaves from the baseline: 0.25.
        assert!(
            (candidates[0].score - 0.25).abs() < 1e-12,
            "{}",
            candidates[0].score
        );
        // Where an effect leaves more than the baseline's objective it scores 0 (135 of
        // 100), and the better ranking stays.
        let again = vec![candidate("offset", 0.1)];
        adopt_better(&mut candidates, again, 150.0, 100.0);
        assert!((candidates[0].score - 0.25).abs() < 1e-12);
    }

    #[test]
    fn a_set_refitted_again_keeps_its_lower_objective_in_any_order() {
        let mut refits = vec![scored(&["a", "b"], 4, 3.0, 2.0, 1e3)];
        merge(
            &mut refits,
            vec![
                scored(&["b", "a"], 4, 2.0, 2.0, 1e3),
                scored(&["a", "c"], 4, 5.0, 2.0, 1e3),
            ],
        );
        assert_eq!(refits.len(), 2);
        assert_eq!(refits[0].objective, 2.0);
        merge(&mut refits, vec![scored(&["a", "c"], 4, 6.0, 2.0, 1e3)]);
        assert_eq!(refits[1].objective, 5.0);
    }
}
