//! Closing the loop: from the residual of a calibration to the physical effect the model
//! lacks.
//!
//! 1. **Baseline**: calibrate the campaign as given (multistart) on the fitted window.
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
//! 4. **Refit** the best candidates, each alone and in pairs, with the multistart, starting
//!    from the baseline optimum with the effect absent.
//! 5. **Select** by the Bayesian information criterion computed with the effective number of
//!    independent samples of the residual (correlated residuals carry less information than
//!    their count suggests), requiring a decrease of at least 10 (very strong evidence,
//!    R. E. Kass, A. E. Raftery, JASA 90 (1995) 773–795) and a lower error on the held-out
//!    window, which guards against over-fitting.
//! 6. **Uncertainty** ([`uncertainty`]): confidence intervals from the Jacobian at the
//!    optimum, widened for correlated residuals, and parameter correlations.
//! 7. **Verdict**: the residual is explained when what is left is within
//!    [`NOISE_FACTOR`] of the noise floor; a selected effect that leaves more is partial; when
//!    no candidate passes, the report says so and adds nothing.

pub mod linear;
pub mod ranking;
pub mod report;
pub mod residual;
pub mod sensitivity;
pub mod uncertainty;

use crate::calibration::{calibrate, load_measurement, Calibration};
use crate::campaign::{Campaign, FreeParameter, Method};
use crate::error::{Error, Result};
use crate::evaluator::{Evaluator, Simulator};
use crate::measurement::Measurement;
use crate::objective::Objective;
use crate::optim::problem::Progress;

use residual::{effective_samples, noise_level, ResidualStats};
use serde::Serialize;
use std::time::{Duration, Instant};
use uncertainty::Interval;

/// An objective within this factor of the noise floor counts as explained by noise.
pub const NOISE_FACTOR: f64 = 1.5;

/// Share of the baseline objective removed above which a fit counts as explaining the data
/// even where the noise floor is too small to compare with (noise-free synthetic records).
pub const NEAR_EXACT: f64 = 0.9999;

/// Decrease of the information criterion that selects a richer model.
pub const MIN_BIC_DECREASE: f64 = 10.0;

/// A candidate whose ranking descent already removed this share of the residual starts its
/// refit from there; below it, larger sizes of the effect are tried as starts too.
pub const WELL_RANKED: f64 = 0.9;

/// Share of the window held out when the data does not extend beyond it.
pub const HOLDOUT_FRACTION: f64 = 0.2;

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
    /// Its value estimated from the linearisation.
    pub estimate: f64,
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

/// What the diagnosis concluded.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Verdict {
    /// The baseline leaves only noise: nothing is missing.
    Noise,
    /// The selected effects bring the error down to the noise.
    Explained,
    /// The selected effects remove part of the residual; something else is missing too.
    Partial,
    /// No candidate removes enough of the residual.
    Unexplained,
}

pub struct Diagnosis {
    pub campaign: Campaign,
    pub measurement: Measurement,
    pub fit_window: (f64, f64),
    pub holdout_window: (f64, f64),
    /// Noise standard deviation per output, estimated from the measured data.
    pub noise: Vec<f64>,
    pub noise_floor: f64,
    pub baseline: Fit,
    pub candidates: Vec<Candidate>,
    pub refits: Vec<Fit>,
    pub selected: Vec<String>,
    /// The selected refit, or the baseline when nothing was selected.
    pub final_fit: Fit,
    pub verdict: Verdict,
    /// Fraction of the baseline's excess over the noise floor that the final fit removes.
    pub explained_fraction: f64,
    pub elapsed: Duration,
}

impl Diagnosis {
    pub fn explained(&self) -> bool {
        matches!(self.verdict, Verdict::Noise | Verdict::Explained)
    }
}

/// The fitted and held-out windows of a campaign on its data.
pub fn windows(campaign: &Campaign, measurement: &Measurement) -> Result<((f64, f64), (f64, f64))> {
    let (start, stop) = campaign.window;
    if let Some(holdout) = campaign.diagnosis.holdout {
        return Ok(((start, stop), holdout));
    }
    let last = *measurement.time.last().unwrap_or(&stop);
    let after: Vec<f64> = measurement
        .time
        .iter()
        .copied()
        .filter(|t| *t > stop)
        .collect();
    if last - stop >= HOLDOUT_FRACTION * 0.5 * (stop - start) && after.len() >= 2 {
        return Ok(((start, stop), (after[0], last)));
    }
    let split = start + (1.0 - HOLDOUT_FRACTION) * (stop - start);
    let first_after = measurement
        .time
        .iter()
        .copied()
        .find(|t| *t > split)
        .ok_or_else(|| {
            Error::InvalidRequest("the window is too short to hold part of it out".into())
        })?;
    Ok(((start, split), (first_after, stop)))
}

fn with_window(campaign: &Campaign, window: (f64, f64)) -> Campaign {
    let mut c = campaign.clone();
    c.window = window;
    c
}

/// Diagnose `campaign`: calibrate, analyse the residual, rank the candidate effects, refit
/// the best, select, and judge.
pub fn diagnose<E>(campaign: &Campaign, engine: &E, progress: &dyn Progress) -> Result<Diagnosis>
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
    let noise: Vec<f64> = fit_objective
        .measured
        .iter()
        .map(|m| noise_level(m))
        .collect();
    let samples = fit_objective.grid.len() as f64;
    let noise_floor: f64 = noise
        .iter()
        .zip(&fit_objective.weights)
        .map(|(s, k)| k * samples * s * s)
        .sum();

    // 1. Baseline.
    let calibration = calibrate(&fit_campaign, engine, progress)?;
    let baseline = fit_of(&calibration, &[], engine, &holdout_objective)?;
    tracing::info!(
        campaign = %campaign.name,
        objective = baseline.objective,
        noise_floor,
        "baseline fitted"
    );

    // 2–3. Rank the candidates.
    let candidate_specs = candidate_effects(&fit_campaign);
    let mut candidates = ranking::rank(
        &fit_campaign,
        &measurement,
        engine,
        &baseline,
        &candidate_specs,
    )?;
    candidates.sort_by(|a, b| b.score.total_cmp(&a.score));

    let Judgement {
        refits,
        selected,
        final_fit,
        verdict,
        explained_fraction,
    } = if baseline.objective <= NOISE_FACTOR * noise_floor {
        Judgement {
            refits: Vec::new(),
            selected: Vec::new(),
            final_fit: baseline.clone(),
            verdict: Verdict::Noise,
            explained_fraction: 1.0,
        }
    } else {
        refit_and_select(
            &fit_campaign,
            &measurement,
            engine,
            progress,
            &baseline,
            &mut candidates,
            &candidate_specs,
            &holdout_objective,
            noise_floor,
        )?
    };
    Ok(Diagnosis {
        campaign: fit_campaign,
        measurement,
        fit_window,
        holdout_window,
        noise,
        noise_floor,
        baseline,
        candidates,
        refits,
        selected,
        final_fit,
        verdict,
        explained_fraction,
        elapsed: started.elapsed(),
    })
}

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

/// What steps 4 to 7 conclude.
struct Judgement {
    refits: Vec<Fit>,
    selected: Vec<String>,
    final_fit: Fit,
    verdict: Verdict,
    explained_fraction: f64,
}

/// Steps 4 to 7: refit the best candidates alone and in pairs, select, and judge. The refits,
/// the selected effects, the final fit, the verdict and the share of the excess explained.
#[allow(clippy::too_many_arguments)]
fn refit_and_select<E: Evaluator + Simulator>(
    fit_campaign: &Campaign,
    measurement: &Measurement,
    engine: &E,
    progress: &dyn Progress,
    baseline: &Fit,
    candidates: &mut [Candidate],
    candidate_specs: &[FreeParameter],
    holdout_objective: &Objective,
    noise_floor: f64,
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
    let mut refits = refit_all(
        &refit_campaigns,
        &singles,
        engine,
        progress,
        holdout_objective,
    )?;
    // Pairs only when no single effect brings the error down to the noise: a pair cannot
    // beat a single effect that already leaves nothing but noise.
    let explains = |f: &Fit| {
        f.objective <= NOISE_FACTOR * noise_floor
            || (baseline.objective - f.objective) >= NEAR_EXACT * baseline.objective
    };
    if !refits.iter().any(|f| improves(f, baseline) && explains(f)) {
        let mut pairs: Vec<Vec<&Candidate>> = Vec::new();
        for i in 0..top.len() {
            for j in i + 1..top.len() {
                pairs.push(vec![top[i], top[j]]);
            }
        }
        let pair_campaigns: Vec<Campaign> = pairs
            .iter()
            .map(|set| refit_campaign(fit_campaign, baseline, set, candidate_specs))
            .collect();
        refits.extend(refit_all(
            &pair_campaigns,
            &pairs,
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

    // 5. Select.
    let mut chosen: Option<&Fit> = None;
    for fit in refits.iter().filter(|f| f.effects.len() == 1) {
        if improves(fit, baseline) && chosen.is_none_or(|c| fit.objective < c.objective) {
            chosen = Some(fit);
        }
    }
    if let Some(single) = chosen {
        for pair in refits.iter().filter(|f| f.effects.len() == 2) {
            let best_so_far = chosen.unwrap_or(single);
            if pair.effects.contains(&single.effects[0]) && improves(pair, best_so_far) {
                chosen = Some(pair);
            }
        }
    } else {
        // A pair may succeed where each effect alone falls short.
        for pair in refits.iter().filter(|f| f.effects.len() == 2) {
            if improves(pair, baseline) && chosen.is_none_or(|c| pair.objective < c.objective) {
                chosen = Some(pair);
            }
        }
    }

    // 7. Verdict.
    let (final_fit, selected, verdict) = match chosen {
        None => (baseline.clone(), Vec::new(), Verdict::Unexplained),
        Some(fit) => {
            let removed =
                (baseline.objective - fit.objective) / baseline.objective.max(f64::MIN_POSITIVE);
            let verdict = if fit.objective <= NOISE_FACTOR * noise_floor || removed >= NEAR_EXACT {
                Verdict::Explained
            } else {
                Verdict::Partial
            };
            (fit.clone(), fit.effects.clone(), verdict)
        }
    };
    let excess = (baseline.objective - noise_floor).max(f64::MIN_POSITIVE);
    let explained_fraction = ((baseline.objective - final_fit.objective) / excess).clamp(0.0, 1.0);
    Ok(Judgement {
        refits,
        selected,
        final_fit,
        verdict,
        explained_fraction,
    })
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

/// Whether `richer` beats `simpler`: a decisive drop of the information criterion and a
/// lower held-out error.
fn improves(richer: &Fit, simpler: &Fit) -> bool {
    // Both criteria with the richer model's effective sample count, so the difference is a
    // likelihood ratio plus the penalty of the extra parameters.
    let n = richer.effective_samples;
    let extra = (richer.parameters.len() as f64 - simpler.parameters.len() as f64).max(0.0);
    let delta_bic = n
        * (richer.objective.max(f64::MIN_POSITIVE) / simpler.objective.max(f64::MIN_POSITIVE)).ln()
        + extra * n.ln();
    delta_bic <= -MIN_BIC_DECREASE && richer.held_out_objective < simpler.held_out_objective
}

/// The candidate effects of a campaign: every effect of its model that the campaign does not
/// already calibrate or fix, restricted to its mapped outputs and to the campaign's list if it
/// has one. A base parameter that is also an effect is a candidate only when held at 0.
pub fn candidate_effects(campaign: &Campaign) -> Vec<FreeParameter> {
    let info = campaign.model.info();
    let mapped: Vec<&str> = campaign.outputs.iter().map(|o| o.model.as_str()).collect();
    info.effects
        .iter()
        .filter(|e| {
            campaign
                .diagnosis
                .candidates
                .as_ref()
                .is_none_or(|list| list.contains(&e.name))
        })
        .filter(|e| match e.name.split_once('(') {
            Some((_, rest)) => mapped.contains(&rest.trim_end_matches(')')),
            None => true,
        })
        .filter_map(|e| {
            let index = info.parameter_index(&e.name)?;
            let free = campaign.free.iter().any(|p| p.index == index);
            (!free && campaign.base[index] == 0.0).then(|| FreeParameter {
                name: e.name.clone(),
                index,
                nominal: 0.0,
                min: e.min,
                max: e.max,
                effect: true,
            })
        })
        .collect()
}

/// The campaign of a refit: the baseline's free parameters (starting at the baseline optimum)
/// plus the effects of `set`, in bounds scaled to their estimated size.
fn refit_campaign(
    campaign: &Campaign,
    baseline: &Fit,
    set: &[&Candidate],
    specs: &[FreeParameter],
) -> Campaign {
    let mut c = campaign.clone();
    for (p, v) in c.free.iter_mut().zip(&baseline.point) {
        p.nominal = v.clamp(p.min, p.max);
    }
    for candidate in set {
        let spec = specs
            .iter()
            .find(|s| s.name == candidate.effect)
            .expect("candidates come from the specs");
        let reach = (20.0 * candidate.estimate.abs())
            .max(100.0 * candidate.step.abs())
            .max(100.0 * candidate.centre);
        let (min, max) = if spec.min >= 0.0 {
            (0.0, reach.min(spec.max))
        } else {
            ((-reach).max(spec.min), reach.min(spec.max))
        };
        c.free.push(FreeParameter {
            min,
            max: if max > min { max } else { spec.max },
            ..spec.clone()
        });
    }
    // Informed starts: each effect at its estimate with the other parameters where the
    // ranking's descent left them (or at the baseline optimum).
    let estimates: Vec<f64> = set.iter().map(|c| c.estimate).collect();
    for candidate in set {
        if candidate.point.len() == baseline.point.len() + 1 {
            let mut start = candidate.point[..baseline.point.len()].to_vec();
            start.extend(&estimates);
            c.search.extra_starts.push(start);
        }
    }
    let mut at_baseline = baseline.point.clone();
    at_baseline.extend(&estimates);
    c.search.extra_starts.push(at_baseline);
    if let [single] = set {
        // Larger sizes too (unless the ranking's descent already found the effect): the baseline's parameters compensate for the missing effect, so
        // the effect's best size with them held is often far below its true size.
        let sign = if single.estimate < 0.0 { -1.0 } else { 1.0 };
        for m in [10.0, 100.0].iter().filter(|_| single.score < WELL_RANKED) {
            let mut start = baseline.point.clone();
            start.push(sign * m * single.centre);
            c.search.extra_starts.push(start);
        }
    }
    let free = c.free.clone();
    for start in c.search.extra_starts.iter_mut() {
        for (v, p) in start.iter_mut().zip(&free) {
            *v = v.clamp(p.min, p.max);
        }
    }
    if !c.search.methods.contains(&Method::NelderMead) {
        c.search.methods.push(Method::NelderMead);
    }
    c.search.starts = c.search.starts.max(4);
    c
}

/// Everything the report needs about one calibration.
fn fit_of<E: Simulator>(
    calibration: &Calibration,
    effects: &[String],
    engine: &E,
    holdout: &Objective,
) -> Result<Fit> {
    let campaign = &calibration.campaign;
    let objective = &calibration.objective;
    let best = calibration.best_run();
    let point = best.point.clone();
    let simulated = engine
        .simulate(objective, std::slice::from_ref(&point))?
        .remove(0)
        .map_err(|e| Error::Optimiser(format!("simulation at the optimum failed: {e}")))?;
    let residual_series: Vec<Vec<f64>> = objective
        .measured
        .iter()
        .zip(&simulated)
        .map(|(w, y)| w.iter().zip(y).map(|(a, b)| a - b).collect())
        .collect();
    let residual: Vec<ResidualStats> = residual_series
        .iter()
        .map(|r| ResidualStats::of(r))
        .collect();

    // The held-out window, with the same free parameters.
    let held = holdout.fixed_at(objective.full_parameters(&point));
    let held_out = engine.simulate(&held, &[Vec::new()])?.remove(0);
    let (held_out_objective, held_out_rms) = match held_out {
        Ok(values) => {
            let e = held.score(&values);
            let n = held.grid.len() as f64;
            (e.objective, e.sse.iter().map(|s| (s / n).sqrt()).collect())
        }
        Err(_) => (
            crate::objective::FAILURE_PENALTY,
            vec![f64::NAN; objective.outputs.len()],
        ),
    };

    let samples = objective.grid.len();
    let pooled: Vec<f64> = residual_series.iter().flatten().copied().collect();
    let rho1 = residual_series
        .iter()
        .map(|r| residual::autocorrelation(r, 1)[0])
        .fold(0.0, f64::max);
    let total_samples = pooled.len();
    let n_eff = effective_samples(total_samples, rho1);
    let k = point.len() as f64;
    let sse = best.objective.max(f64::MIN_POSITIVE);
    let log_likelihood_term = n_eff * (sse / total_samples as f64).ln();
    let jacobian = sensitivity::parameter_jacobian(engine, objective, &campaign.free, &point)?;
    let (parameters, correlation) = uncertainty::intervals(
        &campaign.free,
        &point,
        &jacobian.columns,
        sse,
        total_samples,
        n_eff,
    );
    Ok(Fit {
        effects: effects.to_vec(),
        parameters,
        correlation,
        objective: best.objective,
        held_out_objective,
        rms: calibration
            .best_evaluation
            .sse
            .iter()
            .map(|s| (s / samples as f64).sqrt())
            .collect(),
        held_out_rms,
        residual,
        effective_samples: n_eff,
        aic: log_likelihood_term + 2.0 * k,
        bic: log_likelihood_term + k * n_eff.ln(),
        evaluations: calibration.evaluations(),
        point,
        free: campaign.free.clone(),
        residual_series,
    })
}
