//! Discovery: when no effect of the library explains a residual, estimate the generalized
//! torque the calibrated model misses on each joint and find, by sparse regression, the few
//! functions of the states and inputs it is made of; propose them as a user-defined effect.
//!
//! 1. [`residual`]: inverse dynamics on the smoothed record (Savitzky–Golay, [`savgol`]):
//!    the rate of the generalized momentum minus every modelled force, per joint;
//! 2. [`library`]: candidate functions (polynomials, drag, sign, inputs, harmonics of the
//!    angles), filtered exactly as the residual was;
//! 3. [`stlsq`]: sequentially thresholded least squares, the threshold by blocked
//!    cross-validation and the one-standard-error rule; least squares on the support with
//!    intervals widened for correlated residuals; terms not significant at 95% dropped;
//! 4. [`proposal`]: the terms as an `[[effects]]` block, parameters bounded by their widened
//!    intervals. Nothing is added to a campaign: it is a proposal to refit;
//! 5. on a campaign ([`campaign`]): the record from its measurement mapping, and [`refit`]:
//!    the campaign recalibrated with the proposal (harmonics as amplitude and phase,
//!    [`polar`]) on growing windows, then its parameters' profile intervals ([`profile`]);
//! 6. [`scan`]: where the library leaves more than noise, a harmonic torque of each multiple
//!    of each joint's angle looked for in the outputs (a score test), which needs neither a
//!    freely moving joint nor a baseline near the truth.

pub mod campaign;
pub mod furuta;
pub mod library;
pub mod polar;
pub mod profile;
pub mod proposal;
pub mod refit;
pub mod residual;
pub mod savgol;
pub mod scan;
pub mod stlsq;
pub mod words;

pub use campaign::{fold_duplicates, joint_model, record_of, with_discovered};
pub use furuta::FurutaJoints;
pub use polar::amplitude_phase;
pub use profile::{EffectInterval, OutputResidual};
pub use proposal::{DiscoveredEffect, EffectParameter, FoundHarmonic, FoundTerm};
pub use refit::{refit_discovered, ProposalRefit, RefitParameter, RefitStage};
pub use residual::{JointModel, Record, ResidualOptions};

use library::{Candidate, Kind, LibraryOptions};
use nalgebra::{DMatrix, DVector};
use serde::Serialize;
use stlsq::{CvPoint, Problem};

/// The 95% two-sided normal quantile.
const Z95: f64 = 1.959_963_984_540_054;

/// 95% quantiles of χ² with 1 and 2 degrees of freedom (a term, a harmonic pair).
const CHI2_95: [f64; 2] = [3.841_458_820_694_124, 5.991_464_547_107_979];

#[derive(Debug, Clone, Copy)]
pub struct DiscoveryOptions {
    pub residual: ResidualOptions,
    pub library: LibraryOptions,
    /// Blocked cross-validation folds.
    pub folds: usize,
    /// The ridge inside STLSQ, relative ([`stlsq::RIDGE`]).
    pub ridge: f64,
}

impl Default for DiscoveryOptions {
    fn default() -> Self {
        Self {
            residual: ResidualOptions::default(),
            library: LibraryOptions::default(),
            folds: 5,
            ridge: stlsq::RIDGE,
        }
    }
}

/// What discovery found on one joint.
#[derive(Debug, Clone, Serialize)]
pub struct JointDiscovery {
    pub joint: String,
    /// Samples used (valid rows) and their effective count (correlated residuals).
    pub samples: usize,
    pub effective_samples: f64,
    /// Candidate functions the record can show, of those in the library.
    pub candidates: usize,
    pub library: usize,
    pub threshold: f64,
    pub cross_validation: Vec<CvPoint>,
    /// RMS of the residual torque [N m] before and after the terms found.
    pub residual_rms: f64,
    pub remaining_rms: f64,
    pub terms: Vec<FoundTerm>,
    pub harmonics: Vec<FoundHarmonic>,
    pub proposal: Option<DiscoveredEffect>,
    /// Why no regression ran on this joint (too few usable samples), when none did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub unseen: Option<String>,
}

#[derive(Debug, Clone, Serialize)]
pub struct Discovery {
    pub joints: Vec<JointDiscovery>,
}

impl Discovery {
    pub fn proposals(&self) -> Vec<&DiscoveredEffect> {
        self.joints
            .iter()
            .filter_map(|j| j.proposal.as_ref())
            .collect()
    }
}

/// Discover the torques `model` misses on `record`.
pub fn discover(
    model: &dyn JointModel,
    record: &Record,
    options: &DiscoveryOptions,
) -> Result<Discovery, String> {
    let residual = residual::torque_residual(model, record, &options.residual)?;
    let (angle_names, speed_names) = model.state_names();
    let named = |names: &[String], series: &[Vec<f64>]| -> Vec<(String, Vec<f64>)> {
        names.iter().cloned().zip(series.iter().cloned()).collect()
    };
    let library = library::candidates(
        &named(&angle_names, &residual.angles),
        &named(&speed_names, &residual.speeds),
        &named(&model.input_names(), &record.inputs),
        &options.library,
    );
    let filtered: Vec<Vec<f64>> = library
        .iter()
        .map(|c| residual::filtered_column(&residual, &c.values))
        .collect();
    let joints = model
        .joints()
        .iter()
        .enumerate()
        .map(|(j, joint)| {
            discover_joint(
                joint,
                &residual.torque[j],
                &residual.valid[j],
                &library,
                &filtered,
                &residual,
                options,
            )
        })
        .collect();
    Ok(Discovery { joints })
}

fn rms(values: impl Iterator<Item = f64>) -> f64 {
    let (sum, count) = values.fold((0.0, 0usize), |(s, c), v| (s + v * v, c + 1));
    (sum / count.max(1) as f64).sqrt()
}

/// The candidates the record shows on rows `rows`: (index, filtered RMS).
/// A harmonic `m` of an angle is visible when, at the median speed of that angle over the
/// rows, the filter passes at least half of it.
fn visible(
    library: &[Candidate],
    filtered: &[Vec<f64>],
    rows: &[usize],
    residual: &residual::TorqueResidual,
    min_passed: f64,
) -> Vec<(usize, f64)> {
    let median_speed: Vec<f64> = residual
        .speeds
        .iter()
        .map(|w| {
            let mut s: Vec<f64> = rows.iter().map(|&i| w[i].abs()).collect();
            s.sort_by(f64::total_cmp);
            s.get(s.len() / 2).copied().unwrap_or(0.0)
        })
        .collect();
    library
        .iter()
        .zip(filtered)
        .enumerate()
        .filter_map(|(k, (c, f))| {
            if let Kind::Harmonic { angle, m, .. } = c.kind {
                let omega = m as f64 * median_speed[angle] * residual.dt;
                if residual.filter.integral_slope_gain(omega) < 0.5 {
                    return None;
                }
            }
            let raw = rms(rows.iter().map(|&i| c.values[i]));
            let passed = rms(rows.iter().map(|&i| f[i]));
            let finite = rows.iter().all(|&i| f[i].is_finite());
            (finite && raw > 0.0 && passed >= min_passed * raw).then_some((k, passed))
        })
        .collect()
}

/// Group ids: a harmonic's sine and cosine share one; every other column has its own.
fn groups(library: &[Candidate], kept: &[(usize, f64)]) -> Vec<usize> {
    let mut ids: Vec<(Kind, usize)> = Vec::new();
    kept.iter()
        .map(|&(k, _)| {
            let key = match library[k].kind {
                Kind::Harmonic { angle, m, .. } => Kind::Harmonic {
                    angle,
                    m,
                    sine: true,
                },
                other => other,
            };
            let key = (
                key,
                if matches!(key, Kind::Harmonic { .. }) {
                    0
                } else {
                    k
                },
            );
            match ids.iter().position(|i| *i == key) {
                Some(g) => g,
                None => {
                    ids.push(key);
                    ids.len() - 1
                }
            }
        })
        .collect()
}

#[allow(clippy::too_many_arguments)]
fn discover_joint(
    joint: &str,
    torque: &[f64],
    valid: &[bool],
    library: &[Candidate],
    filtered: &[Vec<f64>],
    residual: &residual::TorqueResidual,
    options: &DiscoveryOptions,
) -> JointDiscovery {
    let rows: Vec<usize> = (0..torque.len()).filter(|&i| valid[i]).collect();
    let kept = visible(
        library,
        filtered,
        &rows,
        residual,
        options.library.min_passed,
    );
    let y = DVector::from_iterator(rows.len(), rows.iter().map(|&i| torque[i]));
    let residual_rms = rms(y.iter().copied());
    let mut found = JointDiscovery {
        joint: joint.to_string(),
        samples: rows.len(),
        effective_samples: rows.len() as f64,
        candidates: kept.len(),
        library: library.len(),
        threshold: f64::INFINITY,
        cross_validation: Vec::new(),
        residual_rms,
        remaining_rms: residual_rms,
        terms: Vec::new(),
        harmonics: Vec::new(),
        proposal: None,
        unseen: None,
    };
    if rows.len() < 3 * (kept.len() + 1) || rows.len() < 2 * options.folds {
        // Said, not passed over: a joint that moves for a few seconds of the record (at rest
        // or reversing, its torque is not known) leaves too few samples for the functions.
        found.unseen = Some(format!(
            "too few usable samples: {} where the joint moves (of {}), for {} candidate \
             functions the record can show (at least 3 per function needed); a record where \
             it moves longer, or a shorter library, would let discovery look",
            rows.len(),
            torque.len(),
            kept.len()
        ));
        return found;
    }
    let x = DMatrix::from_fn(rows.len(), kept.len(), |r, c| {
        let (k, scale) = kept[c];
        filtered[k][rows[r]] / scale
    });
    let problem = Problem {
        x,
        y,
        groups: groups(library, &kept),
        rows: rows.clone(),
        ridge: options.ridge,
    };
    let gap = 2 * residual.filter.half + 1;
    found.cross_validation = stlsq::cross_validate(&problem, options.folds, gap);
    found.threshold = stlsq::choose_threshold(&found.cross_validation);
    let c = stlsq::stlsq(&problem, found.threshold);
    let support: Vec<usize> = (0..c.len()).filter(|&j| c[j] != 0.0).collect();
    let Some((support, fit)) = significant(&problem, support, 4 * gap) else {
        return found;
    };
    found.effective_samples = rows.len() as f64 / fit.inflation;
    found.remaining_rms = rms(fit.residual.iter().copied());
    let columns: Vec<(&Candidate, f64)> = support
        .iter()
        .map(|&j| (&library[kept[j].0], kept[j].1))
        .collect();
    describe(&mut found, &columns, &fit);
    found
}

/// Least squares on `support`, dropping the least significant group (Wald test at 95%, with
/// the correlation-widened covariance) until every group left is significant.
fn significant(
    problem: &Problem,
    mut support: Vec<usize>,
    max_lag: usize,
) -> Option<(Vec<usize>, stlsq::Ols)> {
    loop {
        if support.is_empty() {
            return None;
        }
        let x = problem.x.select_columns(&support);
        let fit = stlsq::ols(&x, &problem.y, max_lag)?;
        let mut ids: Vec<usize> = support.iter().map(|&j| problem.groups[j]).collect();
        ids.dedup();
        let weakest = ids
            .iter()
            .map(|&g| {
                let members: Vec<usize> = (0..support.len())
                    .filter(|&k| problem.groups[support[k]] == g)
                    .collect();
                let c = fit.coefficients.select_rows(&members);
                let cov = fit
                    .covariance
                    .select_rows(&members)
                    .select_columns(&members);
                let wald = cov
                    .try_inverse()
                    .map_or(0.0, |inv| (c.transpose() * inv * &c)[(0, 0)]);
                (g, wald / CHI2_95[members.len().min(2) - 1])
            })
            .min_by(|a, b| a.1.total_cmp(&b.1))?;
        if weakest.1 >= 1.0 {
            return Some((support, fit));
        }
        support.retain(|&j| problem.groups[j] != weakest.0);
    }
}

/// Terms, harmonics and the proposed effect from the fit on normalised `columns`.
fn describe(found: &mut JointDiscovery, columns: &[(&Candidate, f64)], fit: &stlsq::Ols) {
    let mut parameters = Vec::new();
    let mut formula = Vec::new();
    let (mut pairs, mut singles) = (0, 0);
    let mut k = 0;
    while k < columns.len() {
        let (c, _) = columns[k];
        let pair = matches!(c.kind, Kind::Harmonic { sine: true, .. })
            && columns
                .get(k + 1)
                .is_some_and(|(d, _)| matches!(d.kind, Kind::Harmonic { sine: false, .. }));
        let span = if pair { 2 } else { 1 };
        let names: Vec<String> = if pair {
            pairs += 1;
            vec![format!("a{pairs}"), format!("b{pairs}")]
        } else {
            singles += 1;
            vec![format!("c{singles}")]
        };
        for (o, name) in names.iter().enumerate() {
            let (cand, scale) = columns[k + o];
            let estimate = fit.coefficients[k + o] / scale;
            let half = Z95 * fit.covariance[(k + o, k + o)].sqrt() / scale;
            found.terms.push(FoundTerm {
                function: cand.formula.clone(),
                parameter: name.clone(),
                estimate,
                ci_low: estimate - half,
                ci_high: estimate + half,
            });
            parameters.push(EffectParameter {
                name: name.clone(),
                nominal: estimate,
                min: estimate - proposal::BOUND_WIDENING * half,
                max: estimate + proposal::BOUND_WIDENING * half,
            });
            formula.push(if cand.formula == "1" {
                name.clone()
            } else {
                format!("{name} * {}", cand.formula)
            });
        }
        if pair {
            found.harmonics.push(harmonic(columns, fit, k));
        }
        k += span;
    }
    found.proposal = Some(DiscoveredEffect {
        name: format!("discovered.{}", found.joint),
        place: found.joint.clone(),
        formula: formula.join(" + "),
        parameters,
        terms: found.terms.clone(),
        harmonics: found.harmonics.clone(),
    });
}

/// The amplitude, interval and phase of the sine–cosine pair at `k`, `k + 1`.
fn harmonic(columns: &[(&Candidate, f64)], fit: &stlsq::Ols, k: usize) -> FoundHarmonic {
    let (s, ss) = columns[k];
    let cs = columns[k + 1].1;
    let (a, b) = (fit.coefficients[k] / ss, fit.coefficients[k + 1] / cs);
    let amplitude = a.hypot(b);
    let g = [a / amplitude / ss, b / amplitude / cs];
    let cov = |i: usize, j: usize| fit.covariance[(k + i, k + j)];
    let var = g[0] * g[0] * cov(0, 0) + 2.0 * g[0] * g[1] * cov(0, 1) + g[1] * g[1] * cov(1, 1);
    let half = Z95 * var.max(0.0).sqrt();
    let Kind::Harmonic { m, .. } = s.kind else {
        unreachable!("a pair starts with a sine")
    };
    let angle = s.formula.trim_start_matches("sin(").trim_end_matches(')');
    let angle = angle.rsplit(" * ").next().unwrap_or(angle).to_string();
    FoundHarmonic {
        angle,
        multiple: m,
        amplitude,
        ci_low: (amplitude - half).max(0.0),
        ci_high: amplitude + half,
        phase: b.atan2(a),
    }
}
