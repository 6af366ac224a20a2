//! What a profile analysis writes: `profile.json`, a table, and one SVG plot per profiled
//! parameter (the rise of the objective against the parameter, the threshold, the
//! linearised parabola and the interval).

use super::{ParameterProfile, Profiles, SideProfile};
use crate::report::chart::RGBColor;
use crate::report::chart::{self, Chart};
use crate::report::plot::{sanitize, with_unit, Dash, Series};
use calib_engine::error::{Error, Result};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A number for JSON: `null` when absent or not finite.
fn number(v: Option<f64>) -> Value {
    match v {
        Some(v) if v.is_finite() => json!(v),
        _ => Value::Null,
    }
}

fn side_json(side: &SideProfile) -> Value {
    json!({
        "end": side.end,
        "ci": number(side.ci),
        "evaluations": side.evaluations,
        "points": side.points.iter().map(|p| json!({
            "value": p.value,
            "objective": p.objective,
            "rise": p.rise,
            "reoptimised": p.reoptimised,
            "point": p.point,
        })).collect::<Vec<_>>(),
    })
}

/// One parameter's entry of `profile.json`.
pub fn parameter_json(p: &ParameterProfile) -> Value {
    json!({
        "name": p.name,
        "scale": p.scale,
        "min": p.min,
        "max": p.max,
        "value": p.value,
        "ci_low": number(p.ci_low()),
        "ci_high": number(p.ci_high()),
        "identifiable": p.identifiable(),
        "linearised": {
            "ci_low": number(Some(p.linearised.ci_low)),
            "ci_high": number(Some(p.linearised.ci_high)),
            "std": number(Some(p.linearised.std)),
        },
        "low": side_json(&p.low),
        "high": side_json(&p.high),
        "conclusion": p.conclusion(),
    })
}

/// The content of `profile.json`.
pub fn profile_json(s: &Profiles) -> Value {
    json!({
        "campaign": s.campaign,
        "confidence": 0.95,
        "best": {
            "from": s.best_from,
            "objective": s.best_objective,
            "parameters": s.names.iter().zip(&s.best).map(|(n, v)| (n.clone(), json!(v))).collect::<serde_json::Map<_, _>>(),
        },
        "threshold": s.threshold,
        "lowest_objective": s.lowest,
        "parameters": s.profiles.iter().map(parameter_json).collect::<Vec<_>>(),
        "conclusions": s.conclusions(),
        "evaluations": s.stats.evaluations,
        "trajectories": s.stats.trajectories,
        "calibration_evaluations": s.calibration,
        "elapsed_seconds": s.elapsed.as_secs_f64(),
    })
}

fn bound(v: Option<f64>) -> String {
    v.map_or_else(|| "open".to_string(), |v| format!("{v:.6e}"))
}

/// The table: one row per profiled parameter, the threshold, the conclusions.
pub fn table(s: &Profiles) -> String {
    let width = s
        .profiles
        .iter()
        .map(|p| p.name.chars().count())
        .max()
        .unwrap_or(9)
        .max(9);
    let mut out = String::new();
    write_header(&mut out, s, width);
    write_rows(&mut out, s, width);
    write_footer(&mut out, s);
    out
}

/// Where the best point came from and the threshold (with what it is made of), then the
/// column headings of the table.
fn write_header(out: &mut String, s: &Profiles, width: usize) {
    let from = match s.best_from {
        super::BestFrom::Store => "from the store",
        super::BestFrom::Calibrated => "calibrated first",
        super::BestFrom::Fit => "the fit's",
    };
    let _ = writeln!(
        out,
        "best point ({from}): objective {:.6e}; threshold Δ = {:.4e} = {:.4} · s² {:.4e} · N/N_eff {:.3} (N = {}, N_eff = {:.0})\n",
        s.best_objective,
        s.threshold.delta,
        s.threshold.chi_square,
        s.threshold.s2,
        s.threshold.inflation,
        s.threshold.samples,
        s.threshold.effective_samples
    );
    let _ = writeln!(
        out,
        "  {:<width$} {:>13}  {:>31}  {:>31}  {:>12} {:>11}",
        "parameter",
        "value",
        "profile 95% interval",
        "linearised 95% interval",
        "identifiable",
        "evaluations"
    );
}

/// One row per profiled parameter: its value, both 95% intervals, whether it is
/// identifiable and what its profile cost.
fn write_rows(out: &mut String, s: &Profiles, width: usize) {
    for p in &s.profiles {
        let _ = writeln!(
            out,
            "  {:<width$} {:>13.6e}  {:>31}  {:>31}  {:>12} {:>11}",
            p.name,
            p.value,
            format!("[{}, {}]", bound(p.ci_low()), bound(p.ci_high())),
            format!(
                "[{:.6e}, {:.6e}]",
                p.linearised.ci_low, p.linearised.ci_high
            ),
            if p.identifiable() { "yes" } else { "no" },
            p.low.evaluations + p.high.evaluations
        );
    }
}

/// A note when a profile found a lower objective than the best point's, the evaluations,
/// and the conclusions.
fn write_footer(out: &mut String, s: &Profiles) {
    let _ = writeln!(out);
    if s.lowest < s.best_objective - 0.1 * s.threshold.delta {
        let _ = writeln!(
            out,
            "note: a profile point reached objective {:.6e}, below the best point's by more than a tenth of the threshold: the calibration had not converged.",
            s.lowest
        );
    }
    let _ = writeln!(
        out,
        "{} evaluations ({} simulated, {} from the store), {} trajectories{}",
        s.stats.evaluations.requested,
        s.stats.evaluations.simulated,
        s.stats.evaluations.cached,
        s.stats.trajectories,
        match &s.calibration {
            Some(c) => format!(
                "; the calibration first: {} evaluations ({} simulated)",
                c.requested, c.simulated
            ),
            None => String::new(),
        }
    );
    let conclusions = s.conclusions();
    if conclusions.is_empty() {
        let _ = writeln!(out, "Every profiled parameter is identifiable.");
    }
    for c in conclusions {
        let _ = writeln!(out, "{c}");
    }
}

/// Write `profile.json` and one plot per profiled parameter into `dir` (created).
pub fn write(s: &Profiles, dir: &Path) -> Result<Vec<PathBuf>> {
    let write_error = |path: &Path, source: std::io::Error| Error::Write {
        path: path.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(|e| write_error(dir, e))?;
    let json_path = dir.join("profile.json");
    let text = serde_json::to_string_pretty(&profile_json(s)).expect("plain data");
    std::fs::write(&json_path, text).map_err(|e| write_error(&json_path, e))?;
    let mut written = vec![json_path];
    for p in &s.profiles {
        let path = dir.join(format!("profile_{}.svg", sanitize(&p.name)));
        plot(s, p, &path)?;
        written.push(path);
    }
    Ok(written)
}

/// The rise of the objective along the profile, the threshold, the linearised parabola
/// `Δ·((v − p̂)/(1.96 σ))²`, and the interval shaded (to the bound on an open side).
fn plot(s: &Profiles, p: &ParameterProfile, path: &Path) -> Result<()> {
    let delta = s.threshold.delta;
    let mut profile: Vec<(f64, f64)> = p
        .low
        .points
        .iter()
        .rev()
        .map(|q| (q.value, q.rise))
        .chain(std::iter::once((p.value, 0.0)))
        .chain(p.high.points.iter().map(|q| (q.value, q.rise)))
        .filter(|(_, r)| r.is_finite() && *r < 1e29)
        .collect();
    profile.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (x0, x1) = profile
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), (x, _)| {
            (a.min(*x), b.max(*x))
        });
    // Keep the plot readable: rises far above the threshold are cut at 4Δ.
    let (xs, rises): (Vec<f64>, Vec<f64>) = profile
        .iter()
        .map(|&(x, r)| (x, r.min(4.0 * delta)))
        .unzip();
    let sigma = p.linearised.std;
    let grid: Vec<f64> = (0..=200)
        .map(|k| x0 + (x1 - x0) * k as f64 / 200.0)
        .collect();
    let parabola: Vec<f64> = grid
        .iter()
        .map(|v| {
            if sigma.is_finite() && sigma > 0.0 {
                (delta * ((v - p.value) / (1.959_964 * sigma)).powi(2)).min(4.0 * delta)
            } else {
                0.0
            }
        })
        .collect();
    let title = format!(
        "{}: profile of {} ({})",
        s.campaign,
        p.name,
        if p.identifiable() {
            "identifiable"
        } else {
            "not identifiable"
        }
    );
    let shade = (p.ci_low().unwrap_or(x0), p.ci_high().unwrap_or(x1));
    let unit = s
        .names
        .iter()
        .position(|n| *n == p.name)
        .and_then(|i| s.units.get(i))
        .map_or("", |u| u.as_str());
    let text = profile_svg(
        &title,
        &with_unit(&p.name, unit),
        (&xs, &rises),
        (&grid, &parabola),
        delta,
        shade,
    );
    std::fs::write(path, text).map_err(|source| Error::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// The SVG of a profile plot: the profile's points `(values, rises)`, the linearised
/// parabola over `(grid, values)`, the threshold `delta` across, the interval `shade`
/// shaded.
pub fn profile_svg(
    title: &str,
    x_label: &str,
    profile: (&[f64], &[f64]),
    parabola: (&[f64], &[f64]),
    delta: f64,
    shade: (f64, f64),
) -> String {
    let (x0, x1) = profile
        .0
        .iter()
        .chain(parabola.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
            (a.min(*x), b.max(*x))
        });
    let threshold_x = [x0, x1];
    let threshold_y = [delta, delta];
    let series = [
        Series::new(
            "linearised (Jacobian)",
            parabola.0,
            parabola.1,
            RGBColor(150, 150, 150),
            1,
        )
        .dashed(Dash::Dashed),
        Series::new(
            "95% threshold",
            &threshold_x,
            &threshold_y,
            RGBColor(220, 50, 47),
            1,
        )
        .dashed(Dash::DashDot),
        Series::new(
            "profile (others re-optimised)",
            profile.0,
            profile.1,
            RGBColor(38, 139, 210),
            2,
        ),
        Series::new("", profile.0, profile.1, RGBColor(38, 139, 210), 1).dots(3.0),
    ];
    chart::render(&Chart {
        title,
        x_label,
        y_label: "objective − best objective",
        series: &series,
        shades: &[shade],
        ..Chart::default()
    })
}
