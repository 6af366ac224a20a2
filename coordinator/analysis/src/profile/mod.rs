//! Profile likelihoods of the free parameters around a campaign's best point.
//!
//! For a grid of values of one parameter, the others are re-optimised (warm-started from
//! the neighbouring profile point), until the objective rises by the threshold `Δ` or the
//! parameter reaches a bound ([`walk`]). Where the rise crosses `Δ` is an end of the
//! parameter's 95% confidence interval; a side that reaches its bound (or where
//! simulations fail) under the threshold has no end: the parameter is not identifiable.
//!
//! ## The threshold
//!
//! The objective is `f(p) = Σ_i k_i Σ_t (y_i(p, t) − w_i(t))²` (see [`calib_engine::objective`]):
//! the weights `k_i` (the campaign's `weight`, `1/σ²`, and the division by the measured
//! variance for `scale = "variance"`) are folded in, so `f = ‖r‖²` with `r` the stacked
//! weighted residual, `N` entries (every sample of every output). If the weighted residual
//! of the right parameters were independent noise of one variance `σ²`, `−2 log L = f/σ² +
//! const`, and the profile likelihood ratio of one parameter fixed at `v`,
//! `(f_prof(v) − f(p̂)) / σ²`, is χ²-distributed with one degree of freedom (S. S. Wilks,
//! Ann. Math. Statist. 9 (1938) 60–62). `σ²` is estimated as the linearised intervals of
//! the diagnosis estimate it ([`crate::residuals::uncertainty`]): `s² = f(p̂) / (N − n)`,
//! and a residual whose lag-1 autocorrelation leaves `N_eff` independent samples
//! ([`crate::residuals::whiteness::effective_samples`]) carries `N_eff / N` of the
//! information its curvature suggests, so
//!
//! `Δ = χ²₁(0.95) · s² · N / N_eff`, with `χ²₁(0.95) = 3.841459 = 1.959964²`,
//!
//! in the objective's own units. Scaling every weight by `c` scales `f`, `s²` and `Δ` alike:
//! the intervals do not depend on the units of the weights. On a linear model,
//! `f_prof(v) − f(p̂) = (v − p̂_i)² / [(JᵀJ)⁻¹]_ii` (J weighted like `f`), so the crossing
//! is at `p̂_i ± 1.96 √(s² · N/N_eff · [(JᵀJ)⁻¹]_ii)`: exactly the linearised interval. On
//! a nonlinear model the two differ, and the profile is the one that follows the objective.
//!
//! ## Evaluations
//!
//! Every objective evaluation goes through the store-backed evaluator (the store first,
//! the workers or this process for the rest), under the campaign's own objective, so a
//! repeated profile simulates nothing and the calibration's points are reused. The sides
//! of all profiled parameters are walked concurrently, each asking for its points in
//! batches (Powell's bracketing), so they spread over the workers. The residual at the
//! best point and the Jacobian of the linearised intervals (`1 + 2n` trajectories) are
//! simulated, not stored, and counted apart.

pub mod report;
pub mod walk;

use crate::residuals::jacobian::parameter_jacobian;
use crate::residuals::uncertainty::{self, Interval};
use crate::residuals::whiteness::{autocorrelation, effective_samples};
use calib_engine::calibration::{
    calibrate_through, calibrate_with_store, load_measurement, Calibration,
};
use calib_engine::campaign::{Campaign, FreeParameter, Scale};
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::{CacheStats, Evaluator, Simulator};
use calib_engine::limits::{MAX_FREE_PARAMETERS, MAX_PROFILE_STEPS};
use calib_engine::objective::{Objective, FAILURE_PENALTY};
use calib_engine::optim::problem::Silent;
use calib_engine::optim::space::UnitBox;
use calib_engine::store::engine::{EngineStats, StoredEngine};
use calib_engine::store::{encoding, CampaignStatus, Store, Stored};
use serde::Serialize;
use std::time::{Duration, Instant};
use walk::{End, Side};

/// The 95% quantile of χ² with one degree of freedom.
pub const CHI2_1_95: f64 = 3.841_458_820_694_124;

/// What to profile.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Settings {
    /// Names of the parameters to profile; empty: every free parameter.
    pub parameters: Vec<String>,
    /// Most steps on each side of a profile.
    pub max_steps: usize,
}

impl Settings {
    /// The settings held to their limits before anything is planned: the number of steps
    /// ([`MAX_PROFILE_STEPS`]) and of parameters named ([`MAX_FREE_PARAMETERS`], as a
    /// campaign may have no more free ones).
    pub fn check(&self) -> Result<()> {
        if self.max_steps == 0 || self.max_steps > MAX_PROFILE_STEPS {
            return Err(Error::InvalidRequest(format!(
                "max_steps: {} is not between 1 and {MAX_PROFILE_STEPS}",
                self.max_steps
            )));
        }
        if self.parameters.len() > MAX_FREE_PARAMETERS {
            return Err(Error::InvalidRequest(format!(
                "parameters: {} names, more than the {MAX_FREE_PARAMETERS} free parameters \
                 a campaign may have",
                self.parameters.len()
            )));
        }
        Ok(())
    }
}

impl Default for Settings {
    fn default() -> Self {
        Settings {
            parameters: Vec::new(),
            max_steps: walk::DEFAULT_MAX_STEPS,
        }
    }
}

/// Where the best point came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum BestFrom {
    /// The finished campaign's record in the store.
    Store,
    /// A calibration run first (its record is now in the store).
    Calibrated,
    /// A fit handed over by its caller (a diagnosis).
    Fit,
}

/// The rise of the objective that bounds a 95% interval, and what it is made of.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Threshold {
    pub chi_square: f64,
    /// `f(p̂) / (N − n)`.
    pub s2: f64,
    /// `N`: samples of every output.
    pub samples: usize,
    /// `n`: free parameters.
    pub parameters: usize,
    pub effective_samples: f64,
    /// `N / N_eff` (at least 1).
    pub inflation: f64,
    /// `Δ = χ² · s² · N / N_eff`.
    pub delta: f64,
}

impl Threshold {
    /// The threshold of a fit with objective `best_objective` over `samples` residual
    /// entries, `parameters` free, and `effective_samples` independent ones.
    pub fn new(
        best_objective: f64,
        samples: usize,
        parameters: usize,
        effective_samples: f64,
    ) -> Threshold {
        let dof = samples.saturating_sub(parameters).max(1) as f64;
        let s2 = best_objective.max(0.0) / dof;
        let inflation = (samples as f64 / effective_samples.max(1.0)).max(1.0);
        Threshold {
            chi_square: CHI2_1_95,
            s2,
            samples,
            parameters,
            effective_samples,
            inflation,
            delta: CHI2_1_95 * s2 * inflation,
        }
    }
}

/// One point of a profile, in physical units.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ProfilePoint {
    /// The profiled parameter's value.
    pub value: f64,
    pub objective: f64,
    /// `objective − best objective`.
    pub rise: f64,
    pub reoptimised: bool,
    /// Every free parameter at this point (the others as re-optimised).
    pub point: Vec<f64>,
}

/// One side of a profile.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SideProfile {
    pub end: End,
    /// The end of the interval on this side; `None` when the side stays open.
    pub ci: Option<f64>,
    /// Points outwards from the best point.
    pub points: Vec<ProfilePoint>,
    pub evaluations: usize,
}

/// The profile of one parameter.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ParameterProfile {
    pub name: String,
    pub scale: Scale,
    pub min: f64,
    pub max: f64,
    /// The best point's value.
    pub value: f64,
    /// The linearised interval at the best point, for comparison.
    pub linearised: Interval,
    pub low: SideProfile,
    pub high: SideProfile,
}

impl ParameterProfile {
    pub fn ci_low(&self) -> Option<f64> {
        self.low.ci
    }

    pub fn ci_high(&self) -> Option<f64> {
        self.high.ci
    }

    /// Both ends of the interval exist.
    pub fn identifiable(&self) -> bool {
        self.low.ci.is_some() && self.high.ci.is_some()
    }

    /// The sentence saying why the parameter is not identifiable, if it is not.
    pub fn conclusion(&self) -> Option<String> {
        if self.identifiable() {
            return None;
        }
        let phrase = |side: &SideProfile, low: bool| -> String {
            let (towards, bound_word, bound) = if low {
                ("down to", "lower", self.min)
            } else {
                ("up to", "upper", self.max)
            };
            let last = side.points.last().map_or(self.value, |p| p.value);
            match side.end {
                End::Bound => format!("{towards} its {bound_word} bound {bound}"),
                End::Failed => format!("{towards} {last:.6e}, where the simulations fail"),
                End::Steps => format!(
                    "{towards} {last:.6e}, where the walk stopped after {} steps",
                    side.points.len()
                ),
                End::Threshold => unreachable!("a closed side"),
            }
        };
        let open: Vec<String> = [(&self.low, true), (&self.high, false)]
            .into_iter()
            .filter(|(side, _)| side.ci.is_none())
            .map(|(side, low)| phrase(side, low))
            .collect();
        Some(format!(
            "{} is not identifiable: with the other parameters re-optimised, the objective \
             stays below the 95% threshold from its best value {:.6e} {}.",
            self.name,
            self.value,
            open.join(" and ")
        ))
    }
}

/// What a profile analysis found.
#[derive(Debug, Clone)]
pub struct Profiles {
    pub campaign: String,
    /// Every free parameter, in campaign order.
    pub names: Vec<String>,
    /// Their units as the model states them (empty when it states none).
    pub units: Vec<String>,
    pub best: Vec<f64>,
    pub best_objective: f64,
    pub best_from: BestFrom,
    pub threshold: Threshold,
    /// The profiled parameters, in campaign order.
    pub profiles: Vec<ParameterProfile>,
    /// The lowest objective any profile point reached (below the best one when the
    /// calibration had not quite converged).
    pub lowest: f64,
    /// The profile's own evaluations (and trajectories).
    pub stats: EngineStats,
    /// The calibration's evaluations, when it ran first.
    pub calibration: Option<CacheStats>,
    pub elapsed: Duration,
}

impl Profiles {
    /// One sentence per parameter that is not identifiable.
    pub fn conclusions(&self) -> Vec<String> {
        self.profiles
            .iter()
            .filter_map(|p| p.conclusion())
            .collect()
    }
}

/// The local picture a profile is drawn in: a fitted point, its objective, its linearised
/// intervals and correlations, and the threshold.
pub struct Around<'a> {
    pub objective: &'a Objective,
    pub free: &'a [FreeParameter],
    pub point: &'a [f64],
    pub best_objective: f64,
    pub threshold: f64,
    pub linearised: &'a [Interval],
    pub correlation: &'a [Vec<f64>],
}

/// `du/dx` of parameter `p` at `x`: how the unit box stretches its physical value.
fn unit_derivative(p: &FreeParameter, x: f64) -> f64 {
    match p.scale {
        Scale::Lin => 1.0 / (p.max - p.min),
        Scale::Log10 => 1.0 / (x * std::f64::consts::LN_10 * (p.max.log10() - p.min.log10())),
    }
}

/// Profile the parameters `which` (indices into `around.free`), every evaluation through
/// `evaluator`, at most `max_steps` per side.
pub fn profile_around(
    around: &Around,
    which: &[usize],
    evaluator: &dyn Evaluator,
    max_steps: usize,
) -> Result<Vec<ParameterProfile>> {
    profile_around_with(
        around,
        which,
        evaluator,
        max_steps,
        walk::Reoptimisation::default(),
    )
}

/// [`profile_around`], re-optimising the other parameters at each profile point as
/// `reoptimisation` says.
pub fn profile_around_with(
    around: &Around,
    which: &[usize],
    evaluator: &dyn Evaluator,
    max_steps: usize,
    reoptimisation: walk::Reoptimisation,
) -> Result<Vec<ParameterProfile>> {
    let space = UnitBox::new(around.free);
    let best = space.to_unit(around.point);
    let (std, slopes) = unit_steps(around);
    let batch = |units: &[Vec<f64>]| -> Result<Vec<f64>> {
        let physical: Vec<Vec<f64>> = units.iter().map(|u| space.to_physical(u)).collect();
        Ok(evaluator
            .evaluate(around.objective, &physical)?
            .iter()
            .map(|e| {
                if e.failure.is_some() || !e.objective.is_finite() {
                    FAILURE_PENALTY
                } else {
                    e.objective
                }
            })
            .collect())
    };
    let problem = walk::Problem {
        batch: &batch,
        best,
        best_objective: around.best_objective,
        threshold: around.threshold,
        std,
        slopes,
        max_steps,
        failure: FAILURE_PENALTY,
        reoptimisation,
    };
    let sides: Vec<Result<Side>> = std::thread::scope(|scope| {
        let handles: Vec<_> = which
            .iter()
            .flat_map(|&i| [(i, -1.0), (i, 1.0)])
            .map(|(i, direction)| {
                let problem = &problem;
                scope.spawn(move || walk::walk(problem, i, direction))
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p)))
            .collect()
    });
    let mut sides = sides.into_iter();
    let physical_side = |i: usize, side: Side| physical_side(&space, &problem.best, i, side);
    let mut profiles = Vec::with_capacity(which.len());
    for &i in which {
        let low = sides.next().expect("two sides per parameter")?;
        let high = sides.next().expect("two sides per parameter")?;
        let p = &around.free[i];
        profiles.push(ParameterProfile {
            name: p.name.clone(),
            scale: p.scale,
            min: p.min,
            max: p.max,
            value: around.point[i],
            linearised: around.linearised[i].clone(),
            low: physical_side(i, low),
            high: physical_side(i, high),
        });
    }
    Ok(profiles)
}

/// The linearised standard deviation of each parameter in the unit box (infinite where
/// unknown), and the slopes along which the others follow each when it is walked (the
/// linearised correlations; 0 where unknown).
fn unit_steps(around: &Around) -> (Vec<f64>, Vec<Vec<f64>>) {
    let n = around.free.len();
    let std: Vec<f64> = (0..n)
        .map(|i| {
            let s = around.linearised[i].std * unit_derivative(&around.free[i], around.point[i]);
            if s.is_finite() {
                s.abs()
            } else {
                f64::INFINITY
            }
        })
        .collect();
    let slopes: Vec<Vec<f64>> = (0..n)
        .map(|i| {
            (0..n)
                .map(|j| {
                    let s = around.correlation[i][j] * std[j] / std[i];
                    if s.is_finite() {
                        s
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect();
    (std, slopes)
}

/// A walked side in physical values: where it ended, its interval's end, its points.
fn physical_side(space: &UnitBox, best: &[f64], i: usize, side: Side) -> SideProfile {
    let value_of = |u: f64| {
        let mut unit = best.to_vec();
        unit[i] = u;
        space.to_physical(&unit)[i]
    };
    SideProfile {
        end: side.end,
        ci: side.crossing.map(value_of),
        points: side
            .points
            .iter()
            .map(|p| {
                let point = space.to_physical(&p.unit);
                ProfilePoint {
                    value: point[i],
                    objective: p.objective,
                    rise: p.rise,
                    reoptimised: p.reoptimised,
                    point,
                }
            })
            .collect(),
        evaluations: side.evaluations,
    }
}

/// The best point of `campaign` kept in the store, if the campaign finished there: the
/// point and objective of its best run (the lowest objective, the first on a tie, as the
/// calibration picks it).
pub fn stored_best(
    campaign: &Campaign,
    dataset: &[u8; 32],
    store: &dyn Store,
) -> Result<Option<(Vec<f64>, f64)>> {
    let Some(record) = store.campaign(&campaign.identity(dataset))? else {
        return Ok(None);
    };
    if record.status != CampaignStatus::Finished {
        return Ok(None);
    }
    let mut runs: Vec<_> = record
        .runs
        .iter()
        .filter(|r| r.point.len() == campaign.free.len())
        .collect();
    runs.sort_by(|a, b| a.objective.total_cmp(&b.objective));
    Ok(runs.first().map(|r| (r.point.clone(), r.objective)))
}

/// The names in `wanted` as indices into `free` (every parameter when empty).
fn resolve(free: &[FreeParameter], wanted: &[String]) -> Result<Vec<usize>> {
    if wanted.is_empty() {
        return Ok((0..free.len()).collect());
    }
    let mut which = Vec::new();
    for name in wanted {
        let i = free.iter().position(|p| &p.name == name).ok_or_else(|| {
            Error::InvalidRequest(format!(
                "`{name}` is not a free parameter of the campaign (free: {})",
                free.iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
        })?;
        if !which.contains(&i) {
            which.push(i);
        }
    }
    which.sort_unstable();
    Ok(which)
}

/// Linearised intervals, correlations and the threshold at `point`: the residual there and
/// the Jacobian, simulated through `engine`.
pub fn local_statistics(
    engine: &dyn Simulator,
    objective: &Objective,
    free: &[FreeParameter],
    point: &[f64],
    best_objective: f64,
) -> Result<(Vec<Interval>, Vec<Vec<f64>>, Threshold)> {
    let simulated = engine
        .simulate(objective, &[point.to_vec()])?
        .remove(0)
        .map_err(|e| Error::Optimiser(format!("simulation at the best point failed: {e}")))?;
    // Every series of every experiment, in the order `simulate` returns them.
    let residual: Vec<Vec<f64>> = objective
        .experiments()
        .flat_map(|e| &e.measured)
        .zip(&simulated)
        .map(|(w, y)| w.iter().zip(y).map(|(a, b)| a - b).collect())
        .collect();
    let rho1 = residual
        .iter()
        .map(|r| autocorrelation(r, 1)[0])
        .fold(0.0, f64::max);
    let samples: usize = residual.iter().map(Vec::len).sum();
    let n_eff = effective_samples(samples, rho1);
    let jacobian = parameter_jacobian(engine, objective, free, point)?;
    let (intervals, correlation) = uncertainty::intervals(
        free,
        point,
        &jacobian.columns,
        best_objective.max(f64::MIN_POSITIVE),
        samples,
        n_eff,
    );
    let threshold = Threshold::new(best_objective, samples, free.len(), n_eff);
    Ok((intervals, correlation, threshold))
}

/// The point to profile around, its objective, where it came from and, when a calibration
/// had to find it first (the store holds no finished one), that calibration's statistics.
fn best_point(
    campaign: &Campaign,
    store: &dyn Store,
    dataset: &[u8; 32],
    calibrate: Calibrate<'_>,
) -> Result<(Vec<f64>, f64, BestFrom, Option<CacheStats>)> {
    Ok(match stored_best(campaign, dataset, store)? {
        Some((point, objective)) => (point, objective, BestFrom::Store, None),
        None => {
            let c = calibrate()?;
            let best = c.best_run();
            (
                best.point.clone(),
                best.objective,
                BestFrom::Calibrated,
                Some(c.stats),
            )
        }
    })
}

/// The unit of each free parameter, as the model declares it (empty when it does not), for
/// the report's axes.
fn units(campaign: &Campaign) -> Vec<String> {
    campaign
        .free
        .iter()
        .map(|p| {
            campaign
                .model
                .info()
                .parameters
                .get(p.index)
                .map(|s| s.unit.clone())
                .unwrap_or_default()
        })
        .collect()
}

/// Profile `campaign`'s free parameters (those `settings` names) around its best point:
/// the store's when the campaign has finished there, else a calibration's, run first
/// through the same store.
pub fn profile<E: Evaluator + Simulator>(
    campaign: &Campaign,
    engine: &E,
    store: &dyn Store,
    settings: &Settings,
) -> Result<Profiles> {
    let through = |f: &mut dyn FnMut(&StoredEngine<'_, E>)| {
        StoredEngine::with(engine, store, |stored| f(stored))
    };
    let calibrate = || calibrate_with_store(campaign, engine, store, &Silent);
    profile_with(campaign, store, settings, &through, &calibrate)
}

/// [`profile`], every evaluation through `evaluator`: one of a dispatcher over `store` that
/// others share (a coordinator's), the calibration of a best point the store lacks too.
pub fn profile_through<E: Evaluator + Simulator>(
    campaign: &Campaign,
    engine: &E,
    evaluator: &dyn Stored,
    store: &dyn Store,
    settings: &Settings,
) -> Result<Profiles> {
    let through = |f: &mut dyn FnMut(&StoredEngine<'_, E>)| {
        f(&StoredEngine::over(evaluator, engine));
    };
    let calibrate = || calibrate_through(campaign, &evaluator, store, &Silent);
    profile_with(campaign, store, settings, &through, &calibrate)
}

/// Runs a closure with the engine a profile's own evaluations go through.
type Through<'r, E> = &'r dyn Fn(&mut dyn FnMut(&StoredEngine<'_, E>));

/// Calibrates the campaign whose best point the store lacks.
type Calibrate<'r> = &'r dyn Fn() -> Result<Calibration>;

fn profile_with<E: Evaluator + Simulator>(
    campaign: &Campaign,
    store: &dyn Store,
    settings: &Settings,
    through: Through<'_, E>,
    calibrate: Calibrate<'_>,
) -> Result<Profiles> {
    let started = Instant::now();
    settings.check()?;
    if campaign.free.is_empty() {
        return Err(Error::InvalidRequest(
            "the campaign has no free parameter to profile".into(),
        ));
    }
    let which = resolve(&campaign.free, &settings.parameters)?;
    let measurement = load_measurement(campaign)?;
    let dataset = measurement.content_hash();
    if store.dataset(&dataset)?.is_none() {
        store.put_dataset(&dataset, &encoding::encode_measurement(&measurement))?;
    }
    let objective = Objective::new(campaign, &measurement)?;
    let (point, best_objective, best_from, calibration) =
        best_point(campaign, store, &dataset, calibrate)?;
    let mut ran = None;
    through(&mut |stored| {
        let outcome = (|| {
            let (linearised, correlation, threshold) =
                local_statistics(stored, &objective, &campaign.free, &point, best_objective)?;
            let around = Around {
                objective: &objective,
                free: &campaign.free,
                point: &point,
                best_objective,
                threshold: threshold.delta,
                linearised: &linearised,
                correlation: &correlation,
            };
            let profiles = profile_around(&around, &which, stored, settings.max_steps)?;
            Ok::<_, Error>((threshold, profiles))
        })();
        ran = Some((outcome, stored.error(), stored.stats()));
    });
    let (outcome, error, stored_stats) = ran.expect("the profile's engine ran");
    if let Some(e) = error {
        return Err(e.into());
    }
    let (threshold, profiles) = outcome?;
    let lowest = profiles
        .iter()
        .flat_map(|p| p.low.points.iter().chain(&p.high.points))
        .map(|p| p.objective)
        .fold(best_objective, f64::min);
    Ok(Profiles {
        campaign: campaign.name.clone(),
        names: campaign.free.iter().map(|p| p.name.clone()).collect(),
        units: units(campaign),
        best: point,
        best_objective,
        best_from,
        threshold,
        profiles,
        lowest,
        stats: stored_stats,
        calibration,
        elapsed: started.elapsed(),
    })
}
