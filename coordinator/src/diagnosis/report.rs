//! What `calib diagnose` leaves behind: `diagnosis.json`, `diagnosis.md` and SVG plots
//! (residual before and after, measured against the model before and after, residual
//! autocorrelation before and after).

use super::{Diagnosis, Fit, Verdict, NOISE_FACTOR};
use crate::error::{Error, Result};
use crate::report::plot::{line_plot, sanitize, time_plot, Series};
use plotters::style::RGBColor;
use serde_json::{json, Map, Value};
use std::fmt::Write;
use std::path::{Path, PathBuf};

const MEASURED: RGBColor = RGBColor(120, 120, 120);
const BEFORE: RGBColor = RGBColor(220, 50, 47);
const AFTER: RGBColor = RGBColor(38, 139, 210);

fn per_output(d: &Diagnosis, values: &[f64]) -> Value {
    Value::Object(
        d.campaign
            .outputs
            .iter()
            .zip(values)
            .map(|(o, v)| (o.model.clone(), json!(v)))
            .collect(),
    )
}

fn parameters(fit: &Fit) -> Value {
    Value::Object(
        fit.parameters
            .iter()
            .map(|p| {
                (
                    p.name.clone(),
                    json!({ "value": p.value, "ci_low": p.ci_low, "ci_high": p.ci_high, "std": p.std, "effect": p.effect }),
                )
            })
            .collect::<Map<_, _>>(),
    )
}

fn fit_json(d: &Diagnosis, fit: &Fit) -> Value {
    json!({
        "effects": fit.effects,
        "objective": fit.objective,
        "held_out_objective": fit.held_out_objective,
        "rms": per_output(d, &fit.rms),
        "held_out_rms": per_output(d, &fit.held_out_rms),
        "white": Value::Object(d.campaign.outputs.iter().zip(&fit.residual).map(|(o, r)| (o.model.clone(), json!(r.white))).collect()),
        "ljung_box": per_output(d, &fit.residual.iter().map(|r| r.ljung_box).collect::<Vec<_>>()),
        "parameters": parameters(fit),
        "correlation": fit.correlation,
        "effective_samples": fit.effective_samples,
        "aic": fit.aic,
        "bic": fit.bic,
        "evaluations": fit.evaluations,
    })
}

/// The machine-readable diagnosis (`diagnosis.json`).
pub fn diagnosis_json(d: &Diagnosis) -> Value {
    json!({
        "campaign": d.campaign.name,
        "model": d.campaign.model.info().name,
        "fit_window": { "start": d.fit_window.0, "stop": d.fit_window.1 },
        "holdout_window": { "start": d.holdout_window.0, "stop": d.holdout_window.1 },
        "noise": per_output(d, &d.noise),
        "noise_floor": d.noise_floor,
        "baseline": fit_json(d, &d.baseline),
        "candidates": d.candidates.iter().map(|c| json!({
            "effect": c.effect,
            "score": c.score,
            "linear_score": c.linear_score,
            "estimate": c.estimate,
            "objective": c.objective,
        })).collect::<Vec<_>>(),
        "refits": d.refits.iter().map(|f| fit_json(d, f)).collect::<Vec<_>>(),
        "selected": d.selected,
        "final": fit_json(d, &d.final_fit),
        "verdict": d.verdict,
        "explained": d.explained(),
        "partial": d.verdict == Verdict::Partial,
        "explained_fraction": d.explained_fraction,
        "elapsed_seconds": d.elapsed.as_secs_f64(),
    })
}

/// One sentence a person can act on.
pub fn verdict_text(d: &Diagnosis) -> String {
    let ratio = d.final_fit.objective / d.noise_floor;
    match d.verdict {
        Verdict::Noise => format!(
            "The residual is consistent with sensor noise: the objective {:.4e} is {:.2}x the noise floor {:.4e} estimated from the data. Nothing is missing from the model; nothing was added.",
            d.baseline.objective, d.baseline.objective / d.noise_floor, d.noise_floor
        ),
        Verdict::Explained => format!(
            "Missing physics found: {}. Adding it brings the objective from {:.4e} to {:.4e} ({:.1}x lower, {:.2}x the noise floor) and the held-out objective from {:.4e} to {:.4e}.",
            d.selected.join(" + "),
            d.baseline.objective,
            d.final_fit.objective,
            d.baseline.objective / d.final_fit.objective,
            ratio,
            d.baseline.held_out_objective,
            d.final_fit.held_out_objective
        ),
        Verdict::Partial => format!(
            "Partly explained: {} removes {:.0}% of the residual above the noise floor (objective {:.4e} -> {:.4e}, still {:.2}x the noise floor, above the {NOISE_FACTOR}x that noise would leave). Something the candidates do not describe is missing too.",
            d.selected.join(" + "),
            100.0 * d.explained_fraction,
            d.baseline.objective,
            d.final_fit.objective,
            ratio
        ),
        Verdict::Unexplained => format!(
            "No candidate explains the residual: the objective {:.4e} is {:.2}x the noise floor, and no effect (alone or in pairs) lowers the information criterion decisively while also lowering the held-out error. The best attempt is listed below; the missing piece lies outside the candidate library.",
            d.baseline.objective,
            d.baseline.objective / d.noise_floor
        ),
    }
}

fn fit_table(s: &mut String, fit: &Fit) {
    let _ = writeln!(s, "| parameter | value | 95% interval |");
    let _ = writeln!(s, "|---|---|---|");
    for p in &fit.parameters {
        let mark = if p.effect { " (effect)" } else { "" };
        let _ = writeln!(
            s,
            "| `{}`{mark} | {:.6e} | [{:.6e}, {:.6e}] |",
            p.name, p.value, p.ci_low, p.ci_high
        );
    }
    let _ = writeln!(s);
    let n = fit.parameters.len();
    let strong: Vec<String> = (0..n)
        .flat_map(|i| (i + 1..n).map(move |j| (i, j)))
        .filter(|&(i, j)| fit.correlation[i][j].abs() > 0.95)
        .map(|(i, j)| {
            format!(
                "`{}` and `{}` ({:+.3})",
                fit.parameters[i].name, fit.parameters[j].name, fit.correlation[i][j]
            )
        })
        .collect();
    if !strong.is_empty() {
        let _ = writeln!(
            s,
            "Strongly correlated (the data can hardly tell them apart): {}.\n",
            strong.join(", ")
        );
    }
}

/// The Markdown report (`diagnosis.md`).
pub fn markdown(d: &Diagnosis, plots: &[PathBuf]) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Diagnosis of `{}` (model `{}`)\n",
        d.campaign.name,
        d.campaign.model.info().name
    );
    let _ = writeln!(s, "**Verdict:** {}\n", verdict_text(d));
    let _ = writeln!(
        s,
        "Fitted window {:.3}–{:.3} s, held-out window {:.3}–{:.3} s. Noise floor {:.4e} (noise per output estimated from the data: {}).\n",
        d.fit_window.0,
        d.fit_window.1,
        d.holdout_window.0,
        d.holdout_window.1,
        d.noise_floor,
        d.campaign
            .outputs
            .iter()
            .zip(&d.noise)
            .map(|(o, n)| format!("`{}` σ = {:.3e}", o.model, n))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(s, "## Error before and after\n");
    let _ = writeln!(
        s,
        "| | objective | held-out objective | BIC | residual white |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|");
    for (label, fit) in [("baseline", &d.baseline), ("final", &d.final_fit)] {
        let white: Vec<String> = d
            .campaign
            .outputs
            .iter()
            .zip(&fit.residual)
            .map(|(o, r)| format!("{}: {}", o.model, if r.white { "yes" } else { "no" }))
            .collect();
        let _ = writeln!(
            s,
            "| {label} | {:.4e} | {:.4e} | {:.1} | {} |",
            fit.objective,
            fit.held_out_objective,
            fit.bic,
            white.join(", ")
        );
    }
    let _ = writeln!(
        s,
        "\n| output | RMS before | RMS after | held-out RMS before | held-out RMS after |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|");
    for (i, o) in d.campaign.outputs.iter().enumerate() {
        let _ = writeln!(
            s,
            "| `{}` | {:.4e} | {:.4e} | {:.4e} | {:.4e} |",
            o.model,
            d.baseline.rms[i],
            d.final_fit.rms[i],
            d.baseline.held_out_rms[i],
            d.final_fit.held_out_rms[i]
        );
    }
    let _ = writeln!(s, "\n## Candidates, ranked without refitting\n");
    let _ = writeln!(s, "Score: the share of the residual's sum of squares the effect could remove, linearised at the baseline optimum.\n");
    let _ = writeln!(
        s,
        "| rank | effect | score | linear estimate | objective after refit |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|");
    for (i, c) in d.candidates.iter().enumerate() {
        let refit = c.objective.map_or("—".to_string(), |o| format!("{o:.4e}"));
        let _ = writeln!(
            s,
            "| {} | `{}` | {:.4} | {:.4e} | {} |",
            i + 1,
            c.effect,
            c.score,
            c.estimate,
            refit
        );
    }
    if !d.refits.is_empty() {
        let _ = writeln!(s, "\n## Refits\n");
        let _ = writeln!(
            s,
            "| effects | objective | held-out | AIC | BIC | evaluations |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|");
        for f in &d.refits {
            let _ = writeln!(
                s,
                "| {} | {:.4e} | {:.4e} | {:.1} | {:.1} | {} |",
                f.effects.join(" + "),
                f.objective,
                f.held_out_objective,
                f.aic,
                f.bic,
                f.evaluations
            );
        }
    }
    let _ = writeln!(s, "\n## Baseline parameters\n");
    fit_table(&mut s, &d.baseline);
    if !d.selected.is_empty() {
        let _ = writeln!(s, "## Final parameters (with {})\n", d.selected.join(" + "));
        fit_table(&mut s, &d.final_fit);
    }
    let _ = writeln!(s, "## Plots\n");
    for p in plots {
        if let Some(name) = p.file_name() {
            let _ = writeln!(s, "![{0}]({0})\n", name.to_string_lossy());
        }
    }
    s
}

/// Write `diagnosis.json`, `diagnosis.md` and the plots into `dir`; the paths written.
pub fn write(d: &Diagnosis, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let plots = write_plots(d, dir)?;
    let mut written = Vec::new();
    let json_path = dir.join("diagnosis.json");
    let text = serde_json::to_string_pretty(&diagnosis_json(d)).expect("json of plain values");
    std::fs::write(&json_path, text + "\n").map_err(|source| Error::Write {
        path: json_path.clone(),
        source,
    })?;
    written.push(json_path);
    let md_path = dir.join("diagnosis.md");
    std::fs::write(&md_path, markdown(d, &plots)).map_err(|source| Error::Write {
        path: md_path.clone(),
        source,
    })?;
    written.push(md_path);
    written.extend(plots);
    Ok(written)
}

fn write_plots(d: &Diagnosis, dir: &Path) -> Result<Vec<PathBuf>> {
    let campaign = &d.campaign;
    let mut written = Vec::new();
    let objective = crate::objective::Objective::new(campaign, &d.measurement)?;
    let grid = &objective.grid;
    let after_label = if d.selected.is_empty() {
        "after (nothing added)".to_string()
    } else {
        format!("with {}", d.selected.join(" + "))
    };
    for (i, o) in campaign.outputs.iter().enumerate() {
        let name = sanitize(&o.model);
        let unit = &campaign.model.info().outputs[o.model_index].unit;
        // Residual over time.
        let path = dir.join(format!("residual_{name}.svg"));
        time_plot(
            &path,
            &format!("residual of {}: measured − model", o.model),
            &format!("residual [{unit}]"),
            &[
                Series {
                    label: "baseline",
                    time: grid,
                    values: &d.baseline.residual_series[i],
                    color: BEFORE,
                    width: 1,
                },
                Series {
                    label: &after_label,
                    time: grid,
                    values: &d.final_fit.residual_series[i],
                    color: AFTER,
                    width: 1,
                },
            ],
            None,
        )?;
        written.push(path);
        // Measured against the model.
        let measured = &objective.measured[i];
        let baseline: Vec<f64> = measured
            .iter()
            .zip(&d.baseline.residual_series[i])
            .map(|(m, r)| m - r)
            .collect();
        let fin: Vec<f64> = measured
            .iter()
            .zip(&d.final_fit.residual_series[i])
            .map(|(m, r)| m - r)
            .collect();
        let path = dir.join(format!("fit_{name}.svg"));
        time_plot(
            &path,
            &format!("{}: measured and model before and after", o.model),
            &format!("{} [{unit}]", o.model),
            &[
                Series {
                    label: "measured",
                    time: grid,
                    values: measured,
                    color: MEASURED,
                    width: 1,
                },
                Series {
                    label: "baseline model",
                    time: grid,
                    values: &baseline,
                    color: BEFORE,
                    width: 1,
                },
                Series {
                    label: &after_label,
                    time: grid,
                    values: &fin,
                    color: AFTER,
                    width: 2,
                },
            ],
            None,
        )?;
        written.push(path);
    }
    // Residual autocorrelation.
    let lags: Vec<f64> = (1..=d
        .baseline
        .residual
        .first()
        .map_or(0, |r| r.autocorrelation.len()))
        .map(|k| k as f64)
        .collect();
    let labels: Vec<(String, String)> = campaign
        .outputs
        .iter()
        .map(|o| {
            (
                format!("{} baseline", o.model),
                format!("{} {}", o.model, after_label),
            )
        })
        .collect();
    let mut series = Vec::new();
    for (i, (before, after)) in labels.iter().enumerate() {
        series.push(Series {
            label: before,
            time: &lags,
            values: &d.baseline.residual[i].autocorrelation,
            color: BEFORE,
            width: 1 + i as u32,
        });
        series.push(Series {
            label: after,
            time: &lags,
            values: &d.final_fit.residual[i].autocorrelation,
            color: AFTER,
            width: 1 + i as u32,
        });
    }
    // The band within which the autocorrelation of white noise stays 95% of the time.
    let n = d.baseline.residual.first().map_or(1, |r| r.samples).max(1) as f64;
    let band = vec![1.96 / n.sqrt(); lags.len()];
    let minus_band: Vec<f64> = band.iter().map(|b| -b).collect();
    series.push(Series {
        label: "white-noise band (95%)",
        time: &lags,
        values: &band,
        color: MEASURED,
        width: 1,
    });
    series.push(Series {
        label: "",
        time: &lags,
        values: &minus_band,
        color: MEASURED,
        width: 1,
    });
    let path = dir.join("autocorrelation.svg");
    line_plot(
        &path,
        "residual autocorrelation before and after",
        "lag [samples]",
        "autocorrelation",
        &series,
        None,
    )?;
    written.push(path);
    Ok(written)
}
