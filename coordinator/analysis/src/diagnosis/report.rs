//! What `calib diagnose` leaves behind: `diagnosis.json`, `diagnosis.md` and SVG plots
//! (residual before and after, measured against the model before and after, residual
//! autocorrelation before and after).

use super::{verdict, Diagnosis, Fit, Verdict};
use crate::report::chart;
use crate::report::chart::RGBColor;
use crate::report::plot::{self, line_plot, sanitize, time_plot, Dash, Series};
use calib_engine::error::{Error, Result};
use calib_engine::evidence::{self, bound_hits, bound_sentence};
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

/// The bound each fitted parameter sits on (`min`, `max` or none), in the order of
/// `fit.parameters`.
fn bounds(fit: &Fit) -> Vec<Option<evidence::Bound>> {
    fit.free
        .iter()
        .zip(&fit.point)
        .map(|(p, &v)| evidence::at_bound(v, p.nominal, p.min, p.max))
        .collect()
}

fn parameters(fit: &Fit) -> Value {
    let bounds = bounds(fit);
    Value::Object(
        fit.parameters
            .iter()
            .enumerate()
            .map(|(i, p)| {
                (
                    p.name.clone(),
                    json!({
                        "value": p.value,
                        "ci_low": p.ci_low,
                        "ci_high": p.ci_high,
                        "std": p.std,
                        "effect": p.effect,
                        "at_bound": bounds.get(i).copied().flatten(),
                    }),
                )
            })
            .collect::<Map<_, _>>(),
    )
}

/// One sentence per parameter of `fit` that sits on a bound.
pub fn bound_notes(fit: &Fit) -> Vec<String> {
    bound_hits(&fit.free, &fit.point)
        .iter()
        .map(bound_sentence)
        .collect()
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
        "runs_at_best": fit.runs_at_best,
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
        "noise_limit": d.floor.limit,
        "noise_test_level": verdict::NOISE_TEST_LEVEL,
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
        "equivalents": d.equivalents.iter().map(|f| json!({
            "effects": f.effects,
            "objective": f.objective,
            "held_out_objective": f.held_out_objective,
        })).collect::<Vec<_>>(),
        "verdict": d.verdict,
        "verdict_sentence": verdict_text(d),
        "explained": d.explained(),
        "partial": d.verdict == Verdict::Partial,
        "explained_fraction": d.explained_fraction,
        "bound_notes": bound_notes(&d.final_fit),
        "profiles": d.profiles.iter().map(crate::profile::report::parameter_json).collect::<Vec<_>>(),
        "profile_threshold": d.profile_threshold,
        "evaluations": d.stats.evaluations.requested,
        "simulated": d.stats.evaluations.simulated,
        "cached": d.stats.evaluations.cached,
        "trajectories": d.stats.trajectories,
        "elapsed_seconds": d.elapsed.as_secs_f64(),
    })
}

/// One sentence a person can act on, and the sets the record cannot tell from it.
pub fn verdict_text(d: &Diagnosis) -> String {
    let sentence = verdict::sentence(&verdict::Outcome {
        verdict: d.verdict,
        selected: &d.selected,
        baseline: &d.baseline,
        final_fit: &d.final_fit,
        noise_floor: d.noise_floor,
        noise_limit: d.floor.limit,
        explained_fraction: d.explained_fraction,
    });
    if d.equivalents.is_empty() {
        return sentence;
    }
    let others: Vec<String> = d
        .equivalents
        .iter()
        .map(|f| {
            format!(
                "{} ({:.2}x the floor)",
                f.effects.join(" + "),
                f.objective / d.noise_floor
            )
        })
        .collect();
    format!(
        "{sentence} The record cannot tell it from {}: {} also leave{} nothing but noise, \
         so the data do not decide between them.",
        others.join("; "),
        if others.len() == 1 { "that" } else { "these" },
        if others.len() == 1 { "s" } else { "" }
    )
}

fn fit_table(s: &mut String, fit: &Fit) {
    let _ = writeln!(s, "| parameter | value | 95% interval | bound |");
    let _ = writeln!(s, "|---|---|---|---|");
    let bounds = bounds(fit);
    for (i, p) in fit.parameters.iter().enumerate() {
        let mark = if p.effect { " (effect)" } else { "" };
        let bound = match bounds.get(i).copied().flatten() {
            Some(b) => format!("**at {} bound**", b.word()),
            None => String::new(),
        };
        let _ = writeln!(
            s,
            "| `{}`{mark} | {:.6e} | [{:.6e}, {:.6e}] | {bound} |",
            p.name, p.value, p.ci_low, p.ci_high
        );
    }
    let _ = writeln!(s);
    let notes = bound_notes(fit);
    for note in &notes {
        let _ = writeln!(s, "- {note}");
    }
    if !notes.is_empty() {
        let _ = writeln!(s);
    }
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
    write_heading(&mut s, d);
    write_errors(&mut s, d);
    write_candidates(&mut s, d);
    write_refits(&mut s, d);
    write_parameters(&mut s, d);
    write_profiles(&mut s, d);
    write_plot_links(&mut s, plots);
    s
}

/// The title, the verdict, the windows and the noise.
fn write_heading(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(
        s,
        "# Diagnosis of `{}` (model `{}`)\n",
        d.campaign.name,
        d.campaign.model.info().name
    );
    let _ = writeln!(s, "**Verdict:** {}\n", verdict_text(d));
    let _ = writeln!(
        s,
        "Fitted window {:.3}–{:.3} s, held-out window {:.3}–{:.3} s. Noise floor {:.4e} (noise per output estimated from the data: {}); noise alone leaves more than {:.3}x the floor {:.0}% of the time.\n",
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
            .join(", "),
        d.floor.limit,
        100.0 * verdict::NOISE_TEST_LEVEL
    );
}

/// The objectives and each output's error, before and after.
fn write_errors(s: &mut String, d: &Diagnosis) {
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
}

/// The candidates as ranked, with their refitted objectives.
fn write_candidates(s: &mut String, d: &Diagnosis) {
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
}

/// Every refit the diagnosis made.
fn write_refits(s: &mut String, d: &Diagnosis) {
    if !d.refits.is_empty() {
        let _ = writeln!(s, "\n## Refits\n");
        let _ = writeln!(
            s,
            "| effects | objective | held-out | AIC | BIC | evaluations | runs at the best |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|---|");
        for f in &d.refits {
            let _ = writeln!(
                s,
                "| {} | {:.4e} | {:.4e} | {:.1} | {:.1} | {} | {} of {} |",
                f.effects.join(" + "),
                f.objective,
                f.held_out_objective,
                f.aic,
                f.bic,
                f.evaluations,
                f.runs_at_best.count,
                f.runs_at_best.of
            );
        }
    }
}

/// The baseline's fitted parameters, and the final ones when effects were selected.
fn write_parameters(s: &mut String, d: &Diagnosis) {
    let _ = writeln!(
        s,
        "\n## Baseline parameters\n\n{} of {} runs of the baseline calibration reached its best objective within {:.0}%.\n",
        d.baseline.runs_at_best.count,
        d.baseline.runs_at_best.of,
        100.0 * d.baseline.runs_at_best.tolerance
    );
    fit_table(s, &d.baseline);
    if !d.selected.is_empty() {
        let _ = writeln!(s, "## Final parameters (with {})\n", d.selected.join(" + "));
        fit_table(s, &d.final_fit);
    }
}

/// The profile-likelihood intervals of the selected effects.
fn write_profiles(s: &mut String, d: &Diagnosis) {
    if !d.profiles.is_empty() {
        let _ = writeln!(
            s,
            "## Profile likelihood intervals of the selected effects\n"
        );
        let _ = writeln!(
            s,
            "| effect | value | profile 95% interval | linearised 95% interval |"
        );
        let _ = writeln!(s, "|---|---|---|---|");
        let end = |v: Option<f64>| v.map_or_else(|| "open".to_string(), |v| format!("{v:.6e}"));
        for p in &d.profiles {
            let _ = writeln!(
                s,
                "| `{}` | {:.6e} | [{}, {}] | [{:.6e}, {:.6e}] |",
                p.name,
                p.value,
                end(p.ci_low()),
                end(p.ci_high()),
                p.linearised.ci_low,
                p.linearised.ci_high
            );
        }
        let _ = writeln!(s);
        for p in &d.profiles {
            if let Some(c) = p.conclusion() {
                let _ = writeln!(s, "- {c}");
            }
        }
        let _ = writeln!(s);
    }
}

/// A link to each plot.
fn write_plot_links(s: &mut String, plots: &[PathBuf]) {
    let _ = writeln!(s, "## Plots\n");
    for p in plots {
        if let Some(name) = p.file_name() {
            let _ = writeln!(s, "![{0}]({0})\n", name.to_string_lossy());
        }
    }
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
    let objective = calib_engine::objective::Objective::new(campaign, &d.measurement)?;
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
                Series::new("baseline", grid, &d.baseline.residual_series[i], BEFORE, 1)
                    .dashed(Dash::Dashed),
                Series::new(
                    &after_label,
                    grid,
                    &d.final_fit.residual_series[i],
                    AFTER,
                    1,
                ),
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
            &plot::with_unit(&o.model, unit),
            &[
                // The models first, the measured data last: drawn above them.
                Series::new("baseline model", grid, &baseline, BEFORE, 2).dashed(Dash::Dashed),
                Series::new(&after_label, grid, &fin, AFTER, 3),
                Series::new("measured", grid, measured, plot::MEASURED, 1),
            ],
            None,
        )?;
        written.push(path);
    }
    written.push(write_autocorrelation(d, dir, &after_label)?);
    Ok(written)
}

/// The residual autocorrelation before and after, with the band of white noise.
fn write_autocorrelation(d: &Diagnosis, dir: &Path, after_label: &str) -> Result<PathBuf> {
    let campaign = &d.campaign;
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
        // Outputs told apart by dash pattern, baseline and after by colour.
        let (_, dash) = chart::style(i * chart::PALETTE.len());
        series.push(
            Series::new(
                before,
                &lags,
                &d.baseline.residual[i].autocorrelation,
                BEFORE,
                1,
            )
            .dashed(dash),
        );
        series.push(
            Series::new(
                after,
                &lags,
                &d.final_fit.residual[i].autocorrelation,
                AFTER,
                2,
            )
            .dashed(dash),
        );
    }
    // The band within which the autocorrelation of white noise stays 95% of the time.
    let n = d.baseline.residual.first().map_or(1, |r| r.samples).max(1) as f64;
    let band = vec![1.96 / n.sqrt(); lags.len()];
    let minus_band: Vec<f64> = band.iter().map(|b| -b).collect();
    series.push(
        Series::new("white-noise band (95%)", &lags, &band, MEASURED, 1).dashed(Dash::Dotted),
    );
    series.push(Series::new("", &lags, &minus_band, MEASURED, 1).dashed(Dash::Dotted));
    let path = dir.join("autocorrelation.svg");
    line_plot(
        &path,
        "residual autocorrelation before and after",
        "lag [samples]",
        "autocorrelation",
        &series,
        None,
    )?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::testing::fit;

    #[test]
    fn parameters_on_a_bound_are_flagged_with_a_sentence() {
        let f = fit(&[
            ("CF_RefHT", 1.0, 0.1, 5.0, 5.0, false),
            ("CF_Refdp", 1.0, 0.1, 5.0, 0.33, false),
            ("viscous_friction.arm", 0.0, 0.0, 0.01, 0.0, true),
            ("lag(y)", 0.0, 0.0, 2.0, 2.0, true),
        ]);
        let json = parameters(&f);
        assert_eq!(json["CF_RefHT"]["at_bound"], "max");
        assert!(json["CF_Refdp"]["at_bound"].is_null());
        assert_eq!(json["viscous_friction.arm"]["at_bound"], "min");
        assert_eq!(json["lag(y)"]["at_bound"], "max");
        let notes = bound_notes(&f);
        assert_eq!(notes.len(), 3, "{notes:?}");
        assert!(notes[0].starts_with("`CF_RefHT`") && notes[0].contains("upper bound 5"));
        assert!(notes[1].contains("none of it"), "{}", notes[1]);
        assert!(notes[2].contains("[[effects]]"), "{}", notes[2]);
        let mut table = String::new();
        fit_table(&mut table, &f);
        assert_eq!(table.matches("**at upper bound**").count(), 2, "{table}");
        assert_eq!(table.matches("**at lower bound**").count(), 1, "{table}");
    }

    #[test]
    fn a_fit_inside_its_bounds_has_no_notes() {
        let f = fit(&[("armFriction", 0.012, 0.0, 0.9, 0.0101, false)]);
        assert!(bound_notes(&f).is_empty());
        assert!(parameters(&f)["armFriction"]["at_bound"].is_null());
    }
}
