//! Steps 4 to 7 of a diagnosis: refit the best candidates, first each alone and locally
//! (warm-started where the ranking left off, stopped when the objective stops moving); then
//! fair refits ([`super::fair`]) of those the local refits may have judged too soon; when no
//! single effect leaves nothing but noise, fair refits of pairs; then select and judge
//! ([`super::verdict`]).

use super::candidates::refit_campaign;
use super::fair::fair_refits;
use super::fit::fit_of;
use super::verdict::{self, Floor, Verdict};
use super::{Candidate, Fit};
use calib_engine::calibration::calibrate;
use calib_engine::campaign::{Campaign, FreeParameter, Method};
use calib_engine::error::Result;
use calib_engine::evaluator::{Evaluator, Simulator};
use calib_engine::measurement::Measurement;
use calib_engine::objective::Objective;
use calib_engine::optim::budget::Stall;
use calib_engine::optim::problem::Progress;

/// Calibrate each refit campaign concurrently; the fits in the same order.
fn refit_all<E: Evaluator + Simulator>(
    campaigns: &[Campaign],
    sets: &[Vec<&Candidate>],
    engine: &E,
    progress: &dyn Progress,
    holdout: &Objective,
) -> Result<Vec<Fit>> {
    std::thread::scope(|scope| {
        let handles: Vec<_> = campaigns
            .iter()
            .zip(sets)
            .map(|(c, set)| {
                scope.spawn(move || -> Result<Fit> {
                    let calibration = calibrate(c, engine, progress)?;
                    let names: Vec<String> = set.iter().map(|c| c.effect.clone()).collect();
                    fit_of(&calibration, &names, engine, holdout)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect::<Result<Vec<Fit>>>()
    })
}

/// Evaluations without a relative improvement of [`STALL_RELATIVE`] of the best objective
/// after which a local refit stops, per free parameter plus one (a few simplex moves).
pub const STALL_WINDOW_PER_PARAMETER: u64 = 10;
/// See [`STALL_WINDOW_PER_PARAMETER`]. A parameter one standard error from its optimum
/// raises the objective by about `1/n` of itself (`n` the samples of the fitted window, a few
/// hundred in the examples), so a move below 10⁻⁵ of it is far inside the confidence
/// intervals the report gives.
pub const STALL_RELATIVE: f64 = 1e-5;

/// The local refit of a refit campaign: one Nelder–Mead run from the campaign's best-informed
/// start (where the ranking's descent left the parameters and the effect, else the baseline
/// optimum with the effect at its estimate), stopping once the objective stops moving.
pub(super) fn local_refit(refit: &Campaign) -> Campaign {
    let mut c = refit.clone();
    if let Some(start) = c.search.extra_starts.first() {
        for (p, v) in c.free.iter_mut().zip(start) {
            p.nominal = *v;
        }
    }
    c.search.extra_starts.clear();
    c.search.methods = vec![Method::NelderMead];
    c.search.starts = 1;
    c.search.screening = Some(0);
    c.search.stall = Some(Stall {
        window: STALL_WINDOW_PER_PARAMETER * (c.free.len() as u64 + 1),
        relative: STALL_RELATIVE,
    });
    c
}

/// Which of the locally refitted candidates (in ranking order) get a fair refit: when none
/// of them `settles` (leaves nothing but noise), all of them; otherwise those ranked above
/// the first that settles and left short of it (the ranking believed in them more, so they
/// are not passed over on one local run). Those ranked below it need no more: a refit can
/// at best leave noise too.
pub(super) fn leading_unsettled(refits: &[Fit], settles: impl Fn(&Fit) -> bool) -> Vec<usize> {
    match refits.iter().position(&settles) {
        None => (0..refits.len()).collect(),
        Some(first) => (0..first).filter(|&i| !settles(&refits[i])).collect(),
    }
}

/// What steps 4 to 7 conclude.
pub(super) struct Judgement {
    pub refits: Vec<Fit>,
    pub selected: Vec<String>,
    pub final_fit: Fit,
    pub verdict: Verdict,
    pub explained_fraction: f64,
}

/// Steps 4 to 7: refit the best candidates alone and in pairs, select, and judge. The refits,
/// the selected effects, the final fit, the verdict and the share of the excess explained.
#[allow(clippy::too_many_arguments)]
pub(super) fn refit_and_select<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    measurement: &Measurement,
    engine: &E,
    progress: &dyn Progress,
    baseline: &Fit,
    candidates: &mut [Candidate],
    candidate_specs: &[FreeParameter],
    holdout_objective: &Objective,
    floor: &Floor,
) -> Result<Judgement> {
    // 4. Refit the best candidates alone and in pairs.
    let top: Vec<&Candidate> = candidates
        .iter()
        .filter(|c| c.score > 0.0)
        .take(fit_campaign.diagnosis.refit)
        .collect();
    let singles: Vec<Vec<&Candidate>> = top.iter().map(|c| vec![*c]).collect();
    let mut sets = singles.clone();
    let mut refit_campaigns: Vec<Campaign> = singles
        .iter()
        .map(|set| refit_campaign(fit_campaign, baseline, set, candidate_specs))
        .collect();
    let explains = |f: &Fit| verdict::explains(f, baseline, floor);
    // First the local refits, all candidates at once.
    let local: Vec<Campaign> = refit_campaigns.iter().map(local_refit).collect();
    let mut refits = refit_all(&local, &singles, engine, progress, holdout_objective)?;
    // Then fair refits of those the local refits may have judged too soon (see
    // [`leading_unsettled`]), each kept where it ends lower.
    let escalate = leading_unsettled(&refits, |f| verdict::improves(f, baseline) && explains(f));
    let setting = Setting {
        fit_campaign,
        baseline,
        candidate_specs,
        engine,
        progress,
        holdout_objective,
    };
    escalate_singles(&setting, &top, escalate, &mut refits)?;
    // Pairs only when no single effect brings the error down to the noise: a pair cannot
    // beat a single effect that already leaves nothing but noise.
    if !refits
        .iter()
        .any(|f| verdict::improves(f, baseline) && explains(f))
    {
        let pairs = pairs_of(&top);
        let pair_campaigns: Vec<Campaign> = pairs
            .iter()
            .map(|set| refit_campaign(fit_campaign, baseline, set, candidate_specs))
            .collect();
        refits.extend(fair_refits(
            fit_campaign,
            baseline,
            &pairs,
            candidate_specs,
            &[],
            engine,
            progress,
            holdout_objective,
        )?);
        refit_campaigns.extend(pair_campaigns);
        sets.extend(pairs);
        polish_singles_from_pairs(
            &mut refits,
            &refit_campaigns,
            measurement,
            engine,
            progress,
            holdout_objective,
        )?;
    }
    for c in candidates.iter_mut() {
        c.objective = refits
            .iter()
            .find(|f| f.effects.len() == 1 && f.effects[0] == c.effect)
            .map(|f| f.objective);
    }
    Ok(judged(baseline, refits, floor))
}

/// Steps 5 and 7: select among the refits, and judge the selection against the noise floor.
fn judged(baseline: &Fit, refits: Vec<Fit>, floor: &Floor) -> Judgement {
    let chosen = verdict::select(baseline, &refits);
    let (verdict, explained_fraction) = verdict::judge(baseline, chosen, floor);
    let (final_fit, selected) = match chosen {
        None => (baseline.clone(), Vec::new()),
        Some(fit) => (fit.clone(), fit.effects.clone()),
    };
    Judgement {
        refits,
        selected,
        final_fit,
        verdict,
        explained_fraction,
    }
}

/// What every refit of one diagnosis shares.
struct Setting<'a, E> {
    fit_campaign: &'a Campaign,
    baseline: &'a Fit,
    candidate_specs: &'a [FreeParameter],
    engine: &'a E,
    progress: &'a dyn Progress,
    holdout_objective: &'a Objective,
}

/// Fair refits of the singles `escalate` (indices into `top` and `refits`), each kept where
/// it ends lower than its local refit.
fn escalate_singles<E: Evaluator + Simulator>(
    setting: &Setting<'_, E>,
    top: &[&Candidate],
    escalate: Vec<usize>,
    refits: &mut [Fit],
) -> Result<()> {
    if escalate.is_empty() {
        return Ok(());
    }
    let sets: Vec<Vec<&Candidate>> = escalate.iter().map(|&i| vec![top[i]]).collect();
    let fair = fair_refits(
        setting.fit_campaign,
        setting.baseline,
        &sets,
        setting.candidate_specs,
        refits,
        setting.engine,
        setting.progress,
        setting.holdout_objective,
    )?;
    for (i, fit) in escalate.into_iter().zip(fair) {
        tracing::debug!(effect = %fit.effects[0], local = refits[i].objective, fair = fit.objective, "fair refit");
        if fit.objective < refits[i].objective {
            refits[i] = fit;
        }
    }
    Ok(())
}

/// Every pair of the top candidates, in order.
fn pairs_of<'c>(top: &[&'c Candidate]) -> Vec<Vec<&'c Candidate>> {
    let mut pairs: Vec<Vec<&Candidate>> = Vec::new();
    for i in 0..top.len() {
        for j in i + 1..top.len() {
            pairs.push(vec![top[i], top[j]]);
        }
    }
    pairs
}

/// A pair's refit may find, with one of its effects near 0, a better minimum than the refit
/// of its other effect alone (the pair had different starts). Restart such singles from the
/// pair's point with that effect dropped, so that a single effect is never passed over for
/// a pair that needs only one of its two.
fn polish_singles_from_pairs<E: Evaluator + Simulator>(
    refits: &mut [Fit],
    campaigns: &[Campaign],
    measurement: &Measurement,
    engine: &E,
    progress: &dyn Progress,
    holdout: &Objective,
) -> Result<()> {
    for s in 0..refits.len() {
        if refits[s].effects.len() != 1 {
            continue;
        }
        let effect = refits[s].effects[0].clone();
        let single = &campaigns[s];
        let objective = Objective::new(single, measurement)?;
        let mut starts = Vec::new();
        for pair in refits
            .iter()
            .filter(|f| f.effects.len() == 2 && f.effects.contains(&effect))
        {
            let start: Vec<f64> = single
                .free
                .iter()
                .map(|p| {
                    pair.free
                        .iter()
                        .position(|q| q.name == p.name)
                        .map_or(p.nominal, |i| pair.point[i])
                        .clamp(p.min, p.max)
                })
                .collect();
            starts.push(start);
        }
        if starts.is_empty() {
            continue;
        }
        let scores = engine.evaluate(&objective, &starts)?;
        let Some((k, best)) = scores
            .iter()
            .enumerate()
            .min_by(|a, b| a.1.objective.total_cmp(&b.1.objective))
        else {
            continue;
        };
        if best.objective >= 0.99 * refits[s].objective {
            continue;
        }
        let mut polish = single.clone();
        for (p, v) in polish.free.iter_mut().zip(&starts[k]) {
            p.nominal = *v;
        }
        polish.search.extra_starts.clear();
        polish.search.starts = 1;
        polish.search.methods = vec![Method::NelderMead, Method::Powell];
        let calibration = calibrate(&polish, engine, progress)?;
        let fit = fit_of(&calibration, &refits[s].effects, engine, holdout)?;
        if fit.objective < refits[s].objective {
            tracing::debug!(effect = %effect, from = refits[s].objective, to = fit.objective, "single refit improved from a pair");
            refits[s] = fit;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::testing::scored;

    fn refits(objectives: &[f64]) -> Vec<Fit> {
        objectives
            .iter()
            .enumerate()
            .map(|(i, &o)| scored(&[["a", "b", "c"][i]], 3, o, o, 1000.0))
            .collect()
    }

    #[test]
    fn fair_refits_go_to_every_leading_candidate_when_none_settles() {
        let settles = |f: &Fit| f.objective <= 1.0;
        assert_eq!(
            leading_unsettled(&refits(&[5.0, 3.0, 9.0]), settles),
            [0, 1, 2]
        );
    }

    #[test]
    fn fair_refits_go_only_to_candidates_ranked_above_the_first_that_settles() {
        let settles = |f: &Fit| f.objective <= 1.0;
        // The second settles: the first, ranked above it, gets a fair refit; the third not.
        assert_eq!(leading_unsettled(&refits(&[5.0, 0.9, 9.0]), settles), [0]);
        // The first settles: nobody else needs one.
        assert!(leading_unsettled(&refits(&[0.9, 5.0, 9.0]), settles).is_empty());
    }
}
