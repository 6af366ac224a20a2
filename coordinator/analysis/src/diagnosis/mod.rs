//! Closing the loop: from the residual of a calibration to the physical effect the model
//! lacks.
//!
//! 1. **Baseline**: calibrate the campaign as given (multistart) on the fitted window; when
//!    that leaves more than noise and the campaign's runs do not agree on it, minimise again
//!    with the diagnosis's own search ([`fair`]) and keep that fit where it is lower.
//! 2. **Residual analysis** ([`residual`]): per output RMS, autocorrelation and a Ljung–Box
//!    whiteness test, against the noise level estimated from the measured data alone; the
//!    noise floor is what a perfect model would leave, `Σ_i k_i N σ_i²`.
//! 3. **Ranking without refitting** ([`sensitivity`], [`linear`]): the sensitivity of the
//!    outputs to each candidate effect switched on from 0, projected on the residual after
//!    removing what the already-free parameters can explain: the share of the residual's sum
//!    of squares it could remove in that linearisation (a score test, C. R. Rao 1948). The
//!    ranking score is then checked by simulation: one Gauss–Newton step on the free
//!    parameters and the candidate together (full or half), and the share of the objective
//!    it actually removes. Effects whose linearisations look alike (viscous friction and
//!    quadratic drag) separate there, still without refitting anything.
//! 4. **Refit** ([`candidates`], [`refit`], [`fair`]) the best candidates, each alone
//!    (locally, then with the diagnosis's own search where that is not conclusive) and in
//!    pairs, starting from the baseline optimum. Every search after the baseline is the
//!    diagnosis's own, whatever methods and starts the campaign asked for, so the verdict
//!    does not hang on them. When that leaves more than noise ([`escalation`]), the
//!    candidates are ranked again from the other minima the campaign's runs found, every
//!    candidate not yet refitted is refitted alone, and the selected effects get one more at
//!    a time (ranked from their refit), within a bound.
//! 5. **Select** ([`verdict`]) by the Bayesian information criterion computed with the effective number of
//!    independent samples of the residual (correlated residuals carry less information than
//!    their count suggests), requiring a decrease of at least 10 (very strong evidence,
//!    R. E. Kass, A. E. Raftery, JASA 90 (1995) 773–795) and a lower error on the held-out
//!    window, which guards against over-fitting. A selection of two effects or more is then
//!    pruned ([`prune`], backward elimination): each effect taken out in turn and the rest
//!    refitted from the selected fit's point; an effect goes when the rule above does not
//!    call its loss decisive, or when the rest already leaves nothing but noise.
//! 6. **Uncertainty** ([`uncertainty`], [`fit`]): confidence intervals from the Jacobian at the
//!    optimum, widened for correlated residuals, and parameter correlations.
//! 7. **Verdict**: the residual is explained when what is left is within
//!    [`NOISE_FACTOR`] of the noise floor; a selected effect that leaves more is partial; when
//!    no candidate passes, the report says so and adds nothing.
//! 8. **Equivalents** ([`equivalents`]): when the selection explains the record, each of its
//!    effects swapped for each other candidate at the same place and refitted; a swap that
//!    leaves nothing but noise too is named beside the selection (the record cannot tell
//!    them apart); one that fits better becomes the selection.
//!
//! The windows come from [`window`]; every evaluation goes through the store ([`stored`]).

pub mod benchmark;
pub mod candidates;
pub mod discovery;
pub mod equivalents;
pub mod escalation;
pub mod fair;
pub mod fit;
pub mod matrix;
pub mod outside;
pub mod prune;
pub mod ranking;
pub mod refit;
pub mod report;
pub mod verdict;
pub mod window;

#[cfg(test)]
mod testing;

pub use candidates::{candidate_effects, WELL_RANKED};
pub use verdict::{Floor, Verdict, MIN_BIC_DECREASE, NEAR_EXACT, NOISE_FACTOR, NOISE_TEST_LEVEL};
pub use window::{windows, HOLDOUT_FRACTION};

use calib_engine::calibration::{calibrate, load_measurement, Calibration};
use calib_engine::campaign::{Campaign, FreeParameter};
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::{Evaluator, Simulator};
use calib_engine::evidence::RunsAtBest;
use calib_engine::measurement::Measurement;
use calib_engine::objective::Objective;
use calib_engine::optim::problem::Progress;
use calib_engine::store::{MemoryStore, Store};

use crate::residuals::uncertainty::Interval;
use crate::residuals::whiteness::{holds_noise, noise_level, ResidualStats};
use calib_engine::store::engine::{EngineStats, StoredEngine};
use fit::fit_of;
use refit::{refit_and_select, Judgement};
use serde::Serialize;
use std::time::{Duration, Instant};
use window::with_window;

/// One calibration of the diagnosis: the baseline or a refit with effects added.
#[derive(Debug, Clone, Serialize)]
pub struct Fit {
    /// Effects added to the campaign (empty for the baseline).
    pub effects: Vec<String>,
    pub parameters: Vec<Interval>,
    /// Correlation matrix of the fitted parameters, in the order of `parameters`.
    pub correlation: Vec<Vec<f64>>,
    pub objective: f64,
    pub held_out_objective: f64,
    pub rms: Vec<f64>,
    pub held_out_rms: Vec<f64>,
    pub residual: Vec<ResidualStats>,
    /// Effective number of independent samples of the residual.
    pub effective_samples: f64,
    pub aic: f64,
    pub bic: f64,
    pub evaluations: usize,
    /// How many of the calibration's runs reached its best objective.
    pub runs_at_best: RunsAtBest,
    #[serde(skip)]
    pub point: Vec<f64>,
    #[serde(skip)]
    pub free: Vec<FreeParameter>,
    /// Residual series (measured − model) on the fitted window, per output.
    #[serde(skip)]
    pub residual_series: Vec<Vec<f64>>,
}

/// A candidate effect and what the ranking said of it.
#[derive(Debug, Clone, Serialize)]
pub struct Candidate {
    pub effect: String,
    /// Fraction of the residual sum of squares it removes after one Gauss–Newton step on
    /// the free parameters and this effect together (simulated, not refitted).
    pub score: f64,
    /// The same fraction predicted by the linearisation alone (a score test).
    pub linear_score: f64,
    /// Its value where the ranking's descent ended (the linear estimate without a descent).
    pub estimate: f64,
    /// Its value estimated from the linearisation alone (the score test's).
    pub linear_estimate: f64,
    /// The finite-difference step used.
    pub step: f64,
    /// Objective after refitting it alone, when it was refitted.
    pub objective: Option<f64>,
    /// Where the ranking's Gauss–Newton descent ended: the free parameters, then this effect.
    #[serde(skip)]
    pub point: Vec<f64>,
    /// The scale around which the ranking scanned the effect's size.
    #[serde(skip)]
    pub centre: f64,
}

pub struct Diagnosis {
    pub campaign: Campaign,
    pub measurement: Measurement,
    pub fit_window: (f64, f64),
    pub holdout_window: (f64, f64),
    /// Noise standard deviation per output, estimated from the measured data.
    pub noise: Vec<f64>,
    pub noise_floor: f64,
    /// The floor with the ratio noise alone stays under ([`Floor::limit`]).
    pub floor: Floor,
    pub baseline: Fit,
    pub candidates: Vec<Candidate>,
    pub refits: Vec<Fit>,
    pub selected: Vec<String>,
    /// The selected refit, or the baseline when nothing was selected.
    pub final_fit: Fit,
    /// Other sets the record cannot tell from the selection: one effect swapped for another
    /// at the same place, refitted, leaving nothing but noise too ([`equivalents`]).
    pub equivalents: Vec<Fit>,
    pub verdict: Verdict,
    /// Fraction of the baseline's excess over the noise floor that the final fit removes.
    pub explained_fraction: f64,
    /// Evaluations simulated and answered by the store, trajectories simulated.
    pub stats: EngineStats,
    pub elapsed: Duration,
    /// Profile likelihood intervals of the selected effects, when asked for
    /// ([`profile_selected`]).
    pub profiles: Vec<crate::profile::ParameterProfile>,
    /// The threshold those profiles used.
    pub profile_threshold: Option<crate::profile::Threshold>,
}

impl Diagnosis {
    pub fn explained(&self) -> bool {
        matches!(self.verdict, Verdict::Noise | Verdict::Explained)
    }

    /// The effects of each equivalent set, each sorted by name.
    pub fn equivalent_sets(&self) -> Vec<Vec<String>> {
        self.equivalents
            .iter()
            .map(|f| {
                let mut set = f.effects.clone();
                set.sort();
                set
            })
            .collect()
    }
}

/// Diagnose `campaign`: calibrate, analyse the residual, rank the candidate effects, refit
/// the best, select, and judge.
pub fn diagnose<E>(campaign: &Campaign, engine: &E, progress: &dyn Progress) -> Result<Diagnosis>
where
    E: Evaluator + Simulator,
{
    diagnose_with_store(campaign, engine, &MemoryStore::new(), progress)
}

/// [`diagnose`], answering every evaluation the store holds from it and storing every new
/// one, so that a repeated or interrupted diagnosis of the same campaign simulates only
/// what the store lacks.
pub fn diagnose_with_store<E>(
    campaign: &Campaign,
    engine: &E,
    store: &dyn Store,
    progress: &dyn Progress,
) -> Result<Diagnosis>
where
    E: Evaluator + Simulator,
{
    StoredEngine::with(engine, store, |stored| {
        diagnose_through(campaign, stored, progress)
    })
}

/// [`diagnose_with_store`] through `stored`: an engine over an evaluator of a dispatcher
/// others share (a coordinator's).
pub fn diagnose_through<E>(
    campaign: &Campaign,
    stored: &StoredEngine<'_, E>,
    progress: &dyn Progress,
) -> Result<Diagnosis>
where
    E: Evaluator + Simulator,
{
    if !campaign.more.is_empty() {
        return Err(Error::InvalidRequest(format!(
            "the diagnosis takes one record: this campaign fits {} experiments together; \
             diagnose each experiment's record in a campaign of its own",
            1 + campaign.more.len()
        )));
    }
    let outcome = diagnose_on(campaign, stored, progress);
    let (error, stats) = (stored.error(), stored.stats());
    if let Some(e) = error {
        return Err(e.into());
    }
    let mut diagnosis = outcome?;
    diagnosis.stats = stats;
    Ok(diagnosis)
}

fn diagnose_on<E>(campaign: &Campaign, engine: &E, progress: &dyn Progress) -> Result<Diagnosis>
where
    E: Evaluator + Simulator,
{
    let started = Instant::now();
    let measurement = load_measurement(campaign)?;
    let (fit_window, holdout_window) = windows(campaign, &measurement)?;
    let mut fit_campaign = with_window(campaign, fit_window);
    fit_campaign.stop_time = campaign.stop_time.max(holdout_window.1);
    let holdout_objective =
        Objective::new(&with_window(&fit_campaign, holdout_window), &measurement)?;

    // Noise level of each output from the measured data in the fitted window.
    let fit_objective = Objective::new(&fit_campaign, &measurement)?;
    let (noise, floor) = noise_floor(&fit_objective);

    // 1. Baseline.
    let (calibration, baseline, replaced) =
        baseline_fit(&fit_campaign, engine, progress, &holdout_objective, &floor)?;
    // 2–3. Rank the candidates.
    let (mut candidates, candidate_specs) = ranked(
        &fit_campaign,
        &measurement,
        engine,
        &baseline,
        replaced.as_ref(),
    )?;
    // 4–7. Refit, select and judge.
    let setting = escalation::Setting {
        fit_campaign: &fit_campaign,
        measurement: &measurement,
        engine,
        progress,
        baseline: &baseline,
        specs: &candidate_specs,
        holdout: &holdout_objective,
        floor,
    };
    let judged = judge(&setting, &calibration, &mut candidates)?;
    // 8. What the record cannot tell from the selection.
    let (
        Judgement {
            refits,
            selected,
            final_fit,
            verdict,
            explained_fraction,
        },
        equivalent,
    ) = with_equivalents(&setting, judged, &candidates)?;
    Ok(Diagnosis {
        campaign: fit_campaign,
        measurement,
        fit_window,
        holdout_window,
        noise,
        noise_floor: floor.value,
        floor,
        baseline,
        candidates,
        refits,
        selected,
        final_fit,
        equivalents: equivalent,
        verdict,
        explained_fraction,
        stats: EngineStats::default(),
        elapsed: started.elapsed(),
        profiles: Vec::new(),
        profile_threshold: None,
    })
}

/// Step 8: the sets the record cannot tell from an explaining selection
/// ([`equivalents`]), their refits added to the judgement's; one that fits better becomes
/// the selection, and the selection its equivalent.
fn with_equivalents<E: Evaluator + Simulator>(
    setting: &escalation::Setting<'_, E>,
    mut judged: Judgement,
    candidates: &[Candidate],
) -> Result<(Judgement, Vec<Fit>)> {
    if judged.verdict != Verdict::Explained || judged.selected.is_empty() {
        return Ok((judged, Vec::new()));
    }
    let (mut equivalent, tried) = equivalents::equivalents(
        setting.fit_campaign,
        &judged.final_fit,
        candidates,
        setting.specs,
        setting.engine,
        setting.progress,
        setting.holdout,
        &setting.floor,
        &judged.refits,
    )?;
    judged.refits.extend(tried);
    if equivalent
        .first()
        .is_some_and(|best| best.objective < judged.final_fit.objective)
    {
        let best = equivalent.remove(0);
        let (verdict, explained_fraction) =
            verdict::judge(setting.baseline, Some(&best), &setting.floor);
        judged.selected = best.effects.clone();
        equivalent.push(std::mem::replace(&mut judged.final_fit, best));
        equivalent.sort_by(|a, b| a.objective.total_cmp(&b.objective));
        judged.verdict = verdict;
        judged.explained_fraction = explained_fraction;
    }
    Ok((judged, equivalent))
}

/// Steps 4–7: a baseline already within the noise floor is judged noise as it is; otherwise
/// the best candidates are refitted and selected, then escalated where that leaves more.
fn judge<E: Evaluator + Simulator>(
    setting: &escalation::Setting<'_, E>,
    calibration: &Calibration,
    candidates: &mut [Candidate],
) -> Result<Judgement> {
    let baseline = setting.baseline;
    let floor = setting.floor;
    Ok(if floor.holds(baseline.objective) {
        Judgement {
            refits: Vec::new(),
            selected: Vec::new(),
            final_fit: baseline.clone(),
            verdict: Verdict::Noise,
            explained_fraction: 1.0,
        }
    } else {
        let first = refit_and_select(
            setting.fit_campaign,
            setting.measurement,
            setting.engine,
            setting.progress,
            baseline,
            candidates,
            setting.specs,
            setting.holdout,
            &floor,
        )?;
        let mut judged = escalation::escalate(setting, first, calibration, candidates)?;
        if judged.selected.len() >= 2 {
            let (fit, tried) = prune::prune(
                setting.fit_campaign,
                judged.final_fit.clone(),
                setting.engine,
                setting.progress,
                setting.holdout,
                &floor,
            )?;
            let (verdict, explained_fraction) = verdict::judge(baseline, Some(&fit), &floor);
            judged.refits.extend(tried);
            judged.selected = fit.effects.clone();
            judged.final_fit = fit;
            judged.verdict = verdict;
            judged.explained_fraction = explained_fraction;
        }
        judged
    })
}

/// Step 1, the baseline: the campaign calibrated on the fitted window. Above the noise floor and
/// not corroborated by the campaign's own runs, the baseline too gets the diagnosis's own
/// search, so that no effect is credited with what a better fit of the campaign's own
/// parameters removes. Returns the calibration, the baseline and, where the fair refit
/// replaced it, the campaign's own baseline.
fn baseline_fit<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    engine: &E,
    progress: &dyn Progress,
    holdout_objective: &Objective,
    floor: &Floor,
) -> Result<(Calibration, Fit, Option<Fit>)> {
    let calibration = calibrate(fit_campaign, engine, progress)?;
    let mut baseline = fit_of(&calibration, &[], engine, holdout_objective)?;
    // The campaign's own baseline where the fair refit replaced it.
    let mut replaced: Option<Fit> = None;
    // Above the noise floor and not corroborated by the campaign's own runs, the baseline
    // too gets the diagnosis's own search, so that no effect is credited with what a better
    // fit of the campaign's own parameters removes.
    if !floor.holds(baseline.objective)
        && !fit_campaign.free.is_empty()
        && !fair::corroborated(&calibration)
    {
        let fair = fair::fair_refit(
            fit_campaign,
            &baseline,
            &[],
            &[],
            &[],
            engine,
            progress,
            holdout_objective,
        )?;
        tracing::info!(
            campaign = %fit_campaign.name,
            from = baseline.objective,
            to = fair.objective,
            "baseline refitted with the diagnosis's search"
        );
        // The same model, so a lower minimum is simply the better fit of it.
        if fair.objective < baseline.objective * (1.0 - fair::POLISH_RELATIVE) {
            replaced = Some(baseline.clone());
            baseline = Fit {
                evaluations: baseline.evaluations + fair.evaluations,
                ..fair
            };
        }
    }
    tracing::info!(
        campaign = %fit_campaign.name,
        objective = baseline.objective,
        noise_floor = floor.value,
        "baseline fitted"
    );

    Ok((calibration, baseline, replaced))
}

/// Steps 2 and 3: the candidate effects ranked, best first (each scored at the baseline and, where the
/// fair refit moved it, at the campaign's own baseline too), and their specifications.
fn ranked<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    measurement: &Measurement,
    engine: &E,
    baseline: &Fit,
    replaced: Option<&Fit>,
) -> Result<(Vec<Candidate>, Vec<FreeParameter>)> {
    let candidate_specs = candidate_effects(fit_campaign);
    let mut candidates = ranking::rank(
        fit_campaign,
        measurement,
        engine,
        baseline,
        &candidate_specs,
    )?;
    // Where the fair refit moved the baseline, the campaign's own optimum may lie in another
    // basin (a joint held stuck in one, moving in the other) where an effect acts that has no
    // influence at the new one: each candidate keeps the better of its two rankings, with
    // the point its descent reached there as a start of its refits.
    if let Some(own) = replaced {
        let again = ranking::rank(fit_campaign, measurement, engine, own, &candidate_specs)?;
        escalation::adopt_better(&mut candidates, again, own.objective, baseline.objective);
    }
    candidates.sort_by(|a, b| b.score.total_cmp(&a.score));

    Ok((candidates, candidate_specs))
}

/// The noise level of each output, estimated from the measured data on `objective`'s grid,
/// and the noise floor, what a perfect model would leave: `Σ_i k_i N σ_i²`, with the ratio
/// to it that noise alone stays under ([`Floor`]).
pub fn noise_floor(objective: &Objective) -> (Vec<f64>, Floor) {
    let noise: Vec<f64> = objective.measured.iter().map(|m| noise_level(m)).collect();
    let noisy = objective.measured.iter().all(|m| holds_noise(m));
    let floor = Floor::new(&noise, &objective.weights, objective.grid.len(), noisy);
    (noise, floor)
}

/// Profile likelihood intervals of the effects the diagnosis selected, around its final
/// fit (see [`crate::profile`]): the noise level and the linearised intervals are the
/// fit's own, so nothing but the profiles' points is evaluated, through the store.
pub fn profile_selected<E>(d: &mut Diagnosis, engine: &E, store: &dyn Store) -> Result<()>
where
    E: Evaluator + Simulator,
{
    use crate::profile::{profile_around, walk::DEFAULT_MAX_STEPS, Around, Threshold};
    let fit = &d.final_fit;
    let which: Vec<usize> = fit
        .free
        .iter()
        .enumerate()
        .filter(|(_, p)| p.effect && d.selected.contains(&p.name))
        .map(|(i, _)| i)
        .collect();
    if which.is_empty() {
        return Ok(());
    }
    let mut campaign = d.campaign.clone();
    campaign.free = fit.free.clone();
    let objective = Objective::new(&campaign, &d.measurement)?;
    let samples = objective.grid.len() * objective.outputs.len();
    let threshold = Threshold::new(
        fit.objective,
        samples,
        fit.free.len(),
        fit.effective_samples,
    );
    let around = Around {
        objective: &objective,
        free: &fit.free,
        point: &fit.point,
        best_objective: fit.objective,
        threshold: threshold.delta,
        linearised: &fit.parameters,
        correlation: &fit.correlation,
    };
    let (outcome, error, added) = StoredEngine::with(engine, store, |stored| {
        let outcome = profile_around(&around, &which, stored, DEFAULT_MAX_STEPS);
        (outcome, stored.error(), stored.stats())
    });
    if let Some(e) = error {
        return Err(e.into());
    }
    d.profiles = outcome?;
    d.profile_threshold = Some(threshold);
    let e = &mut d.stats.evaluations;
    e.requested += added.evaluations.requested;
    e.simulated += added.evaluations.simulated;
    e.cached += added.evaluations.cached;
    e.failed += added.evaluations.failed;
    d.stats.trajectories += added.trajectories;
    Ok(())
}
