//! The refit of a proposal: the campaign recalibrated with the discovered effect added, on a
//! window that grows, then the effect's parameters profiled.
//!
//! **Why the window grows.** An error `δτ` in a torque moves a lightly damped joint by about
//! `½·δτ/A·t²`: on the driven Furuta record (arm inertia `A` 4–6·10⁻³ kg m², 20 s, only
//! Coulomb friction) a cogging phase off by 1 mrad (6·10⁻⁶ N m) already leaves 12 times the
//! noise floor, 1% on its amplitude 2,000 times. Over the whole record the objective is a
//! valley far narrower than the proposal's intervals, which a local search started from the
//! regression's estimates rarely enters (it stopped at twice the floor). Over the first fifth
//! of the record the same errors have had little time to grow: the valley is wide, and a
//! local search from the proposal finds it; each longer window starts from the previous
//! one's optimum, already close to its narrower valley. [`STAGES`] windows
//! `[t0, t0 + k·T/STAGES]`, each searched by Nelder–Mead and Powell from the previous best
//! point (the campaign's own methods and starts are not used: the start is known).
//!
//! The effect is refitted in the form of [`super::polar`] (a harmonic as amplitude and
//! phase); terms that duplicate a free parameter of the campaign are folded into it first
//! ([`fold_duplicates`]). At the final point the effect's parameters are profiled
//! ([`super::profile`]); a profile point below the refit's objective (by more than a tenth
//! of the threshold) means the refit stopped short: the point moves there and the profiles
//! are drawn again, once.

use super::campaign::{fold_duplicates, with_discovered};
use super::polar::amplitude_phase;
use super::profile::{assess, EffectInterval, OutputResidual};
use super::DiscoveredEffect;
use crate::profile::walk::ACCEPT;
use crate::profile::Threshold;
use calib_engine::calibration::calibrate;
use calib_engine::campaign::{Campaign, Method};
use calib_engine::error::Result;
use calib_engine::evaluator::Evaluator;
use calib_engine::optim::problem::Progress;
use serde::Serialize;

/// Windows of the refit: the last is the campaign's own.
pub const STAGES: usize = 5;

/// Least evaluations of each run of a stage, per free parameter.
pub const EVALUATIONS_PER_PARAMETER: usize = 250;

/// A parameter of the refit.
#[derive(Debug, Clone, Serialize)]
pub struct RefitParameter {
    pub name: String,
    pub value: f64,
    pub min: f64,
    pub max: f64,
}

/// One window of the refit.
#[derive(Debug, Clone, Serialize)]
pub struct RefitStage {
    /// The fitted span `[start, stop]` (every experiment's window cut at the same share).
    pub window: (f64, f64),
    pub objective: f64,
    pub evaluations: usize,
    /// The method whose run ended lowest.
    pub method: String,
}

/// The calibration of a campaign with a discovered effect added.
#[derive(Debug, Clone, Default, Serialize)]
pub struct ProposalRefit {
    pub effect: String,
    /// The `[[effects]]` block refitted (empty when every term was folded): harmonics as
    /// amplitude and phase, the refitted values as nominal values (what a campaign takes to
    /// start where the refit ended), the bounds the refit had.
    pub toml: String,
    /// Terms folded into the campaign's own parameters (a Coulomb friction's error shows
    /// as `sign(<joint>.w)`) instead of refitted as part of the effect.
    pub folded: Vec<String>,
    pub objective_before: f64,
    pub objective_after: f64,
    pub noise_floor: f64,
    /// Every free parameter, the campaign's then the effect's.
    pub parameters: Vec<RefitParameter>,
    /// Evaluations of the refit and of the profiles.
    pub evaluations: usize,
    /// The growing windows, in order.
    pub stages: Vec<RefitStage>,
    /// The residual left after the refit, per output.
    pub residual: Vec<OutputResidual>,
    /// The rise of the objective that bounds a 95% profile interval.
    pub threshold: Option<Threshold>,
    /// Profile likelihood intervals of the effect's parameters.
    pub intervals: Vec<EffectInterval>,
}

impl ProposalRefit {
    pub fn ratio_before(&self) -> f64 {
        self.objective_before / self.noise_floor
    }
    pub fn ratio_after(&self) -> f64 {
        self.objective_after / self.noise_floor
    }
    /// The refitted value of the effect's parameter `name` (`amp1`, not `<effect>.amp1`).
    pub fn value(&self, name: &str) -> Option<f64> {
        let full = format!("{}.{name}", self.effect);
        self.parameters
            .iter()
            .find(|p| p.name == full)
            .map(|p| p.value)
    }
    /// The refit in words and symbols, as `calib diagnose --discover` prints it.
    pub fn summary(&self) -> String {
        super::words::refit_summary(self)
    }
    /// The profile interval of the effect's parameter `name`.
    pub fn interval(&self, name: &str) -> Option<&EffectInterval> {
        let full = format!("{}.{name}", self.effect);
        self.intervals.iter().find(|i| i.name == full)
    }
}

/// Recalibrate `campaign` (free parameters starting at `start`, whose objective is
/// `objective_before`) with `effect` added, on growing windows, evaluating with `evaluator`;
/// then profile the effect's parameters at the final point.
pub fn refit_discovered<E: Evaluator>(
    campaign: &Campaign,
    start: &[f64],
    objective_before: f64,
    noise_floor: f64,
    effect: &DiscoveredEffect,
    evaluator: E,
    progress: &dyn Progress,
) -> Result<ProposalRefit> {
    let (kept, start, folded) = fold_duplicates(campaign, start, effect);
    let kept = kept.map(|k| amplitude_phase(&k));
    let mut c = match &kept {
        Some(effect) => with_discovered(campaign, start.as_slice(), effect)?,
        None => {
            let mut c = campaign.clone();
            start_at(&mut c, &start);
            c
        }
    };
    c.search.extra_starts.clear();
    let (mut point, mut objective, stages) = staged(&c, &evaluator, progress)?;
    let effect_parameters: Vec<usize> = (campaign.free.len()..c.free.len()).collect();
    let mut assessment = assess(&c, &point, objective, &effect_parameters, &evaluator)?;
    let mut evaluations = assessment.evaluations;
    // A profile point below the refit's: the refit had stopped short of the minimum, and
    // the intervals are drawn again around the lower point.
    let (lowest, at) = assessment.lowest.clone();
    if lowest < objective - ACCEPT * assessment.threshold.delta {
        (point, objective) = (at, lowest);
        assessment = assess(&c, &point, objective, &effect_parameters, &evaluator)?;
        evaluations += assessment.evaluations;
    }
    let parameters = c
        .free
        .iter()
        .zip(&point)
        .map(|(p, v)| RefitParameter {
            name: p.name.clone(),
            value: *v,
            min: p.min,
            max: p.max,
        })
        .collect();
    let toml = kept.as_ref().map_or_else(String::new, |k| {
        let mut k = k.clone();
        for p in &mut k.parameters {
            let full = format!("{}.{}", k.name, p.name);
            if let Some(i) = c.free.iter().position(|f| f.name == full) {
                p.nominal = point[i];
            }
        }
        k.to_toml()
    });
    Ok(ProposalRefit {
        effect: effect.name.clone(),
        toml,
        folded,
        objective_before,
        objective_after: objective,
        noise_floor,
        parameters,
        evaluations: stages.iter().map(|s| s.evaluations).sum::<usize>() + evaluations,
        stages,
        residual: assessment.residual,
        threshold: Some(assessment.threshold),
        intervals: assessment.intervals,
    })
}

/// The free parameters of `c` started at `point` (clamped to their bounds).
fn start_at(c: &mut Campaign, point: &[f64]) {
    for (p, v) in c.free.iter_mut().zip(point) {
        p.nominal = v.clamp(p.min, p.max);
        c.base[p.index] = p.nominal;
    }
}

/// `c` with every experiment's fitted intervals cut at `share` of its window.
fn first_share(c: &Campaign, share: f64) -> Campaign {
    let cut = |window: &mut (f64, f64), windows: &mut Vec<(f64, f64)>| {
        let stop = window.0 + share * (window.1 - window.0);
        windows.retain(|w| w.0 < stop);
        for w in windows.iter_mut() {
            w.1 = w.1.min(stop);
        }
        window.1 = stop;
    };
    let mut c = c.clone();
    if share < 1.0 {
        cut(&mut c.window, &mut c.windows);
        for e in &mut c.more {
            cut(&mut e.window, &mut e.windows);
        }
    }
    c
}

/// The refit on [`STAGES`] growing windows: the final point, its objective on the whole
/// window, and each stage.
fn staged<E: Evaluator>(
    c: &Campaign,
    evaluator: &E,
    progress: &dyn Progress,
) -> Result<(Vec<f64>, f64, Vec<RefitStage>)> {
    let mut point = c.nominal();
    let mut objective = f64::INFINITY;
    let mut stages = Vec::with_capacity(STAGES);
    let budget = c
        .search
        .max_evaluations
        .max(EVALUATIONS_PER_PARAMETER * c.free.len());
    for k in 1..=STAGES {
        let mut stage = first_share(c, k as f64 / STAGES as f64);
        start_at(&mut stage, &point);
        stage.search.methods = vec![Method::NelderMead, Method::Powell];
        stage.search.starts = 1;
        stage.search.max_evaluations = budget;
        let calibration = calibrate(&stage, evaluator, progress)?;
        let best = calibration.best_run();
        point = best.point.clone();
        objective = best.objective;
        stages.push(RefitStage {
            window: stage.window,
            objective,
            evaluations: calibration.runs.iter().map(|r| r.evaluations).sum(),
            method: best.method.to_string(),
        });
    }
    Ok((point, objective, stages))
}
