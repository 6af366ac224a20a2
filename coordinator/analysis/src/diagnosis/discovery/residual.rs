//! The generalized torque a calibrated model misses on each joint, estimated from a measured
//! trajectory (inverse dynamics).
//!
//! With mass matrix `M(q)`, every modelled force but bearing friction `h(q, q̇, u)` and Coulomb
//! friction `−F·sign(q̇)` while sliding, the model says `M·q̈ = h − F·sign(q̇) + τ` where `τ` is
//! what is missing. Rather than differentiate the angles twice, the discovery works on the
//! generalized momentum `p = M(q)·q̇`, whose rate is
//!
//! ```text
//! ṗ = M·q̈ + Ṁ·q̇ = h + Ṁ·q̇ − F·sign(q̇) + τ
//! ```
//!
//! so `e(t) = p(t) − ∫₀ᵗ (h + Ṁ·q̇ − F·sign(q̇)) dt` has the rate `τ`. The angles are smoothed
//! and differentiated once by a Savitzky–Golay filter (a local cubic over 0.21 s at 100 Hz:
//! it reproduces cubic motion exactly and needs no boundary conditions, where a smoothing
//! spline needs a smoothing weight chosen per record); the same filter's slope then takes the
//! rate of `e`, and the discovery applies that very slope to the running integral of every
//! candidate function, so both sides of the regression see the same linear filter and
//! a term faster than the filter passes is attenuated on both sides alike (no bias), only
//! less visible.
//!
//! Samples are left out where the known forces are not known well: within a window of a
//! joint at rest or reversing (its friction is whatever holds it, or changes sign), within a
//! window of a kink of an input (a step of the motor torque: the smoothed speed rounds the
//! corner while the integral of the input does not), and at the ends.

use super::savgol::SavitzkyGolay;

/// A measured trajectory on a uniform time grid.
#[derive(Debug, Clone)]
pub struct Record {
    pub time: Vec<f64>,
    /// One series per joint coordinate [rad].
    pub angles: Vec<Vec<f64>>,
    /// One series per model input (linear between samples), in the model's input order.
    pub inputs: Vec<Vec<f64>>,
}

/// The equations of motion of a model at one state, for inverse dynamics.
#[derive(Debug, Clone)]
pub struct JointForces {
    /// Mass matrix, row per joint.
    pub mass: Vec<Vec<f64>>,
    /// Every modelled generalized force but Coulomb friction.
    pub forces: Vec<f64>,
    /// Coulomb friction level of each joint (`−F·sign(q̇)` while sliding; 0 for none).
    pub coulomb: Vec<f64>,
}

/// A model whose joints discovery can invert.
pub trait JointModel {
    /// Joint names as effects place a torque (`armJoint`), in coordinate order.
    fn joints(&self) -> Vec<String>;
    /// The formula names of each joint's angle and speed (`armJoint.phi`, `armJoint.w`).
    fn state_names(&self) -> (Vec<String>, Vec<String>);
    /// The formula names of the inputs.
    fn input_names(&self) -> Vec<String>;
    fn forces(&self, q: &[f64], w: &[f64], u: &[f64]) -> Result<JointForces, String>;
}

/// The smoothed states and, per joint, the filtered residual torque and where it is valid.
#[derive(Debug, Clone)]
pub struct TorqueResidual {
    pub filter: SavitzkyGolay,
    pub dt: f64,
    pub angles: Vec<Vec<f64>>,
    pub speeds: Vec<Vec<f64>>,
    /// The slope of `e` per joint [N m] (NaN at the ends).
    pub torque: Vec<Vec<f64>>,
    /// Per joint, the samples where `torque` can be trusted.
    pub valid: Vec<Vec<bool>>,
}

/// Options of the residual estimate.
#[derive(Debug, Clone, Copy)]
pub struct ResidualOptions {
    /// Half-width of the Savitzky–Golay window in samples.
    pub half_window: usize,
    /// Degree of its polynomial.
    pub order: usize,
    /// A joint slower than this [rad/s] is treated as at rest or reversing.
    pub slow_speed: f64,
    /// A jump of an input's slope larger than this share of its range is a kink.
    pub kink_share: f64,
}

impl Default for ResidualOptions {
    fn default() -> Self {
        Self {
            half_window: 10,
            order: 3,
            slow_speed: 0.05,
            kink_share: 0.01,
        }
    }
}

/// The grid step of `time`, which must be uniform.
pub fn uniform_step(time: &[f64]) -> Result<f64, String> {
    if time.len() < 3 {
        return Err("discovery needs at least 3 samples".into());
    }
    let dt = (time[time.len() - 1] - time[0]) / (time.len() - 1) as f64;
    let uneven = time
        .windows(2)
        .any(|w| ((w[1] - w[0]) - dt).abs() > 1e-6 * dt.abs().max(1e-12));
    if dt.is_nan() || dt <= 0.0 || uneven {
        return Err("discovery needs samples on a uniform time grid".into());
    }
    Ok(dt)
}

/// The times on a uniform grid, the series on it, and whether they were interpolated.
pub type Regridded = (Vec<f64>, Vec<Vec<f64>>, bool);

/// Largest departure of a step from the mean step taken as the clock's jitter, as a share of
/// the step: a time column written in single precision (0.0499992 to 0.0500031 s at 20 Hz)
/// is a uniform grid; an irregular one (a lost sample: a step twice the others) is not.
pub const GRID_JITTER: f64 = 0.01;

/// `time` and each of `series` on a uniform time grid: the same samples, at the grid's times,
/// when every step is within [`GRID_JITTER`] of the mean step (the shift is far below the
/// smoothing window); otherwise interpolated linearly at the median step from the first
/// time to the last. The third value says whether it interpolated. `Err` when the times do
/// not increase.
pub fn regrid(time: &[f64], series: &[Vec<f64>]) -> Result<Regridded, String> {
    if time.len() < 3 {
        return Err("discovery needs at least 3 samples".into());
    }
    let steps: Vec<f64> = time.windows(2).map(|w| w[1] - w[0]).collect();
    if steps.iter().any(|s| s.is_nan() || *s <= 0.0) {
        return Err("discovery needs times that increase from one sample to the next".into());
    }
    let n = time.len();
    let mean = (time[n - 1] - time[0]) / (n - 1) as f64;
    if steps.iter().all(|s| (s - mean).abs() <= GRID_JITTER * mean) {
        let grid = (0..n).map(|i| time[0] + i as f64 * mean).collect();
        return Ok((grid, series.to_vec(), false));
    }
    let mut sorted = steps.clone();
    sorted.sort_by(f64::total_cmp);
    let step = sorted[sorted.len() / 2];
    // (a span that is a whole number of steps counts it, rounding aside)
    let count = ((time[n - 1] - time[0]) / step * (1.0 + 1e-9)).floor() as usize + 1;
    let grid: Vec<f64> = (0..count).map(|i| time[0] + i as f64 * step).collect();
    let resampled = series
        .iter()
        .map(|values| {
            let mut j = 0;
            grid.iter()
                .map(|&t| {
                    while j + 2 < n && time[j + 1] < t {
                        j += 1;
                    }
                    let share = ((t - time[j]) / (time[j + 1] - time[j])).clamp(0.0, 1.0);
                    values[j] + share * (values[j + 1] - values[j])
                })
                .collect()
        })
        .collect();
    Ok((grid, resampled, true))
}

/// The running trapezoidal integral of `y` with step `dt` (NaN propagates).
pub fn running_integral(y: &[f64], dt: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(y.len());
    let mut sum = 0.0;
    for (i, v) in y.iter().enumerate() {
        if i > 0 {
            sum += 0.5 * dt * (y[i - 1] + v);
        }
        out.push(sum);
    }
    out
}

/// `true` at every sample within `reach` samples of one where `flag` holds.
fn dilate(flag: &[bool], reach: usize) -> Vec<bool> {
    let n = flag.len();
    let mut out = vec![false; n];
    for (i, _) in flag.iter().enumerate().filter(|(_, f)| **f) {
        for o in out
            .iter_mut()
            .take((i + reach + 1).min(n))
            .skip(i.saturating_sub(reach))
        {
            *o = true;
        }
    }
    out
}

/// The filtered residual torque of `model` on `record`.
pub fn torque_residual(
    model: &dyn JointModel,
    record: &Record,
    options: &ResidualOptions,
) -> Result<TorqueResidual, String> {
    let dt = uniform_step(&record.time)?;
    let n = record.time.len();
    let joints = record.angles.len();
    if joints != model.joints().len() || record.inputs.len() != model.input_names().len() {
        return Err("the record's angles or inputs do not match the model's joints".into());
    }
    let filter = SavitzkyGolay::new(options.half_window, options.order);
    if n < 8 * filter.half {
        return Err(format!(
            "discovery needs at least {} samples, the record has {n}",
            8 * filter.half
        ));
    }
    let angles: Vec<Vec<f64>> = record.angles.iter().map(|a| filter.smooth(a)).collect();
    let speeds: Vec<Vec<f64>> = record
        .angles
        .iter()
        .map(|a| filter.derivative(a, dt))
        .collect();
    let (momentum, known, coulomb) = momentum_and_known(model, &angles, &speeds, &record.inputs)?;
    let h = filter.half;
    let kinks = input_kinks(&record.inputs, options.kink_share);
    let mut torque = Vec::with_capacity(joints);
    let mut valid = Vec::with_capacity(joints);
    for j in 0..joints {
        // Integrate from the first sample where the momentum is known.
        let start = 2 * h;
        let mut e = vec![f64::NAN; n];
        let integral = running_integral(&known[j][h..n - h], dt);
        for i in h..n - h {
            e[i] = momentum[j][i] - integral[i - h];
        }
        let rate = filter.derivative(&e, dt);
        let slow: Vec<bool> = speeds[j]
            .iter()
            .map(|w| coulomb[j] > 0.0 && (w.is_nan() || w.abs() < options.slow_speed))
            .collect();
        let slow = dilate(&slow, 2 * h + 1);
        let kink = dilate(&kinks, 2 * h + 1);
        let ok: Vec<bool> = (0..n)
            .map(|i| i >= start && i + start < n && !slow[i] && !kink[i] && rate[i].is_finite())
            .collect();
        torque.push(rate);
        valid.push(ok);
    }
    Ok(TorqueResidual {
        filter,
        dt,
        angles,
        speeds,
        torque,
        valid,
    })
}

/// Sample by sample: the momentum `M·q̇` of each joint, the rate the model explains
/// `h + Ṁ·q̇ − F·sign(q̇)`, and the Coulomb levels.
#[allow(clippy::type_complexity)]
fn momentum_and_known(
    model: &dyn JointModel,
    angles: &[Vec<f64>],
    speeds: &[Vec<f64>],
    inputs: &[Vec<f64>],
) -> Result<(Vec<Vec<f64>>, Vec<Vec<f64>>, Vec<f64>), String> {
    let (joints, n) = (angles.len(), angles.first().map_or(0, Vec::len));
    let mut momentum = vec![vec![f64::NAN; n]; joints];
    let mut known = vec![vec![f64::NAN; n]; joints];
    let mut coulomb = vec![0.0; joints];
    for i in 0..n {
        let q: Vec<f64> = angles.iter().map(|a| a[i]).collect();
        let w: Vec<f64> = speeds.iter().map(|s| s[i]).collect();
        if q.iter().chain(&w).any(|v| !v.is_finite()) {
            continue;
        }
        let u: Vec<f64> = inputs.iter().map(|s| s[i]).collect();
        let here = model.forces(&q, &w, &u)?;
        coulomb.clone_from(&here.coulomb);
        // Ṁ·q̇ by a central difference of M along the motion.
        let eps = 1e-6;
        let step =
            |sign: f64| -> Vec<f64> { q.iter().zip(&w).map(|(a, b)| a + sign * eps * b).collect() };
        let ahead = model.forces(&step(1.0), &w, &u)?.mass;
        let behind = model.forces(&step(-1.0), &w, &u)?.mass;
        for j in 0..joints {
            momentum[j][i] = (0..joints).map(|k| here.mass[j][k] * w[k]).sum();
            let mdot_w: f64 = (0..joints)
                .map(|k| (ahead[j][k] - behind[j][k]) / (2.0 * eps) * w[k])
                .sum();
            known[j][i] = here.forces[j] + mdot_w - here.coulomb[j] * w[j].signum();
        }
    }
    Ok((momentum, known, coulomb))
}

/// Samples where an input's slope jumps by more than `share` of its range.
fn input_kinks(inputs: &[Vec<f64>], share: f64) -> Vec<bool> {
    let n = inputs.first().map_or(0, Vec::len);
    let mut out = vec![false; n];
    for u in inputs {
        let (lo, hi) = u
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
                (a.min(*v), b.max(*v))
            });
        let range = hi - lo;
        for i in 1..n.saturating_sub(1) {
            if (u[i + 1] - 2.0 * u[i] + u[i - 1]).abs() > share * range {
                out[i] = true;
            }
        }
    }
    out
}

/// The filtered column of a candidate function `g` (values at the smoothed states): the same
/// slope of its running integral that turned `e` into the residual torque.
pub fn filtered_column(residual: &TorqueResidual, g: &[f64]) -> Vec<f64> {
    let h = residual.filter.half;
    let n = g.len();
    let mut column = vec![f64::NAN; n];
    if n > 2 * h {
        let integral = running_integral(&g[h..n - h], residual.dt);
        let mut full = vec![f64::NAN; n];
        full[h..n - h].copy_from_slice(&integral);
        column = residual.filter.derivative(&full, residual.dt);
    }
    column
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A clock written in single precision (the real rig's record: steps 0.0499992 to
    /// 0.0500031 s) is a uniform grid: the samples kept, at the grid's times.
    #[test]
    fn a_single_precision_clock_is_a_uniform_grid() {
        let time: Vec<f64> = (0..2000).map(|i| (i as f64 * 0.05) as f32 as f64).collect();
        assert!(uniform_step(&time).is_err(), "the strict check refuses it");
        let values: Vec<f64> = (0..2000).map(|i| (i as f64).sin()).collect();
        let (grid, series, resampled) = regrid(&time, std::slice::from_ref(&values)).unwrap();
        assert!(!resampled);
        assert_eq!(series[0], values);
        assert!((uniform_step(&grid).unwrap() - 0.05).abs() < 1e-7);
    }

    /// A lost sample (one step twice the others) is interpolated on the median step, and a
    /// linear signal stays exact; times that go back are refused, saying so.
    #[test]
    fn an_irregular_grid_is_interpolated_and_a_clock_going_back_refused() {
        let time: Vec<f64> = (0..101)
            .filter(|&i| i != 40)
            .map(|i| i as f64 * 0.01)
            .collect();
        let line: Vec<f64> = time.iter().map(|t| 3.0 * t - 1.0).collect();
        let (grid, series, resampled) = regrid(&time, &[line]).unwrap();
        assert!(resampled);
        assert_eq!(grid.len(), 101);
        assert!((uniform_step(&grid).unwrap() - 0.01).abs() < 1e-12);
        for (t, v) in grid.iter().zip(&series[0]) {
            assert!((v - (3.0 * t - 1.0)).abs() < 1e-12);
        }
        let back = [0.0, 0.01, 0.02, 0.015, 0.03];
        let error = regrid(&back, &[vec![0.0; 5]]).unwrap_err();
        assert!(error.contains("increase"), "{error}");
    }
}
