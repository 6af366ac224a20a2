//! What a sensitivity analysis writes: `sensitivity.json`, a table, and one SVG bar chart per
//! quantity (the objective and each output's contribution).

use super::Sensitivity;
use crate::report::chart::RGBColor;
use crate::report::chart::{self, Bars as BarSet, Chart};
use crate::report::plot::sanitize;
use calib_engine::campaign::Scale;
use calib_engine::error::{Error, Result};
use serde_json::{json, Value};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

/// A number for JSON: `null` when it is not finite.
fn number(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// The statistics of parameter `i` on quantity `q`.
fn statistics(s: &Sensitivity, q: usize, i: usize) -> Value {
    let quantity = &s.quantities[q];
    let mut v = serde_json::Map::new();
    if let Some(m) = &quantity.morris {
        v.insert("mu".into(), number(m.mu[i]));
        v.insert("mu_star".into(), number(m.mu_star[i]));
        v.insert("sigma".into(), number(m.sigma[i]));
    }
    if let Some(sobol) = &quantity.sobol {
        v.insert("first".into(), number(sobol.first[i]));
        v.insert(
            "first_ci".into(),
            json!([number(sobol.first_ci[i].0), number(sobol.first_ci[i].1)]),
        );
        v.insert("total".into(), number(sobol.total[i]));
        v.insert(
            "total_ci".into(),
            json!([number(sobol.total_ci[i].0), number(sobol.total_ci[i].1)]),
        );
    }
    Value::Object(v)
}

/// The entry of parameter `i` in `sensitivity.json`: its range, whether it is influential
/// and where it was kept, its statistics on the objective and on each output, and at the fit.
fn parameter_json(s: &Sensitivity, i: usize) -> Value {
    let mut p = serde_json::Map::new();
    p.insert("name".into(), json!(s.parameters[i]));
    p.insert(
        "scale".into(),
        json!(match s.scales[i] {
            Scale::Lin => "lin",
            Scale::Log10 => "log10",
        }),
    );
    p.insert("min".into(), json!(s.bounds[i].0));
    p.insert("max".into(), json!(s.bounds[i].1));
    p.insert("influential".into(), json!(s.influential(i)));
    p.insert(
        "kept_for".into(),
        s.kept_for(i)
            .map_or(Value::Null, |q| json!(s.quantities[q].name)),
    );
    if let Value::Object(stats) = statistics(s, 0, i) {
        p.extend(stats);
    }
    let outputs: serde_json::Map<String, Value> = (1..s.quantities.len())
        .map(|q| (s.quantities[q].name.clone(), statistics(s, q, i)))
        .collect();
    p.insert("outputs".into(), Value::Object(outputs));
    if let Some(a) = &s.at_fit {
        let outputs: serde_json::Map<String, Value> = (1..s.quantities.len())
            .map(|q| (s.quantities[q].name.clone(), number(a.indices[q][i])))
            .collect();
        p.insert(
            "at_fit".into(),
            json!({"objective": number(a.indices[0][i]), "outputs": outputs}),
        );
        p.insert(
            "kept_at_fit".into(),
            s.kept_at_fit(i)
                .map_or(Value::Null, |q| json!(s.quantities[q].name)),
        );
    }
    Value::Object(p)
}

/// The content of `sensitivity.json`.
pub fn sensitivity_json(s: &Sensitivity) -> Value {
    let parameters: Vec<Value> = (0..s.parameters.len())
        .map(|i| parameter_json(s, i))
        .collect();
    let methods: Vec<&str> = [
        (s.quantities[0].morris.is_some(), "morris"),
        (s.quantities[0].sobol.is_some(), "sobol"),
    ]
    .into_iter()
    .filter_map(|(ran, name)| ran.then_some(name))
    .collect();
    json!({
        "campaign": s.campaign,
        "methods": methods,
        "samples": s.settings.samples,
        "seed": s.settings.seed,
        "morris": {
            "levels": super::sampling::MORRIS_LEVELS,
            "points": s.morris_points,
            "failed": s.morris_failed,
        },
        "sobol": {
            "points": s.sobol_points,
            "failed": s.sobol_failed,
            "excluded_samples": s.sobol_excluded,
            "bootstrap_resamples": super::sampling::BOOTSTRAP_RESAMPLES,
            "confidence": 0.95,
        },
        "influential_total": super::INFLUENTIAL_TOTAL,
        "at_fit": s.at_fit.as_ref().map_or(Value::Null, |a| json!({
            "source": a.source,
            "objective": number(a.objective),
            "parameters": s.parameters.iter().zip(&a.point)
                .map(|(n, v)| (n.clone(), number(*v)))
                .collect::<serde_json::Map<String, Value>>(),
            "unit_step": super::local::UNIT_STEP,
            "simulated": a.simulated,
        })),
        "parameters": parameters,
        "fixable": s.fixable(),
        "conclusion": s.conclusion(),
        "evaluations": s.stats,
    })
}

/// The table: one block per quantity, one row per parameter.
pub fn table(s: &Sensitivity) -> String {
    let width = s
        .parameters
        .iter()
        .map(|p| p.chars().count())
        .max()
        .unwrap_or(9)
        .max(9);
    let mut out = String::new();
    for quantity in &s.quantities {
        let title = if quantity.name == "objective" {
            "objective".to_string()
        } else {
            format!("contribution of {}", quantity.name)
        };
        let _ = writeln!(out, "{title}");
        let mut header = format!("  {:<width$}", "parameter");
        if quantity.morris.is_some() {
            header.push_str(&format!(" {:>11} {:>11}", "mu*", "sigma"));
        }
        if quantity.sobol.is_some() {
            header.push_str(&format!(
                " {:>7} {:>17} {:>7} {:>17}",
                "first", "95% CI", "total", "95% CI"
            ));
        }
        let _ = writeln!(out, "{header}");
        for (i, name) in s.parameters.iter().enumerate() {
            let mut row = format!("  {name:<width$}");
            if let Some(m) = &quantity.morris {
                row.push_str(&format!(" {:>11.4e} {:>11.4e}", m.mu_star[i], m.sigma[i]));
            }
            if let Some(sobol) = &quantity.sobol {
                let ci = |(lo, hi): (f64, f64)| format!("[{lo:.3}, {hi:.3}]");
                row.push_str(&format!(
                    " {:>7.3} {:>17} {:>7.3} {:>17}",
                    sobol.first[i],
                    ci(sobol.first_ci[i]),
                    sobol.total[i],
                    ci(sobol.total_ci[i])
                ));
            }
            let _ = writeln!(out, "{row}");
        }
        let _ = writeln!(out);
    }
    if let Some(a) = &s.at_fit {
        table_at_fit(&mut out, s, a, width);
    }
    let _ = writeln!(
        out,
        "{} evaluations ({} simulated, {} from the store); failed: {} of the Morris points, \
         {} of the Sobol points ({} base samples left out)",
        s.stats.requested,
        s.stats.simulated,
        s.stats.cached,
        s.morris_failed,
        s.sobol_failed,
        s.sobol_excluded
    );
    let _ = writeln!(out, "{}", s.conclusion());
    out
}

/// The block of the local indices at the fit: one column per quantity.
fn table_at_fit(out: &mut String, s: &Sensitivity, a: &super::local::AtFit, width: usize) {
    let _ = writeln!(
        out,
        "at the fit ({}, objective {:.6e}): local index, each parameter's share of the squared \
         sensitivities",
        a.source, a.objective
    );
    let mut header = format!("  {:<width$} {:>12}", "parameter", "value");
    for q in &s.quantities {
        header.push_str(&format!(" {:>14}", q.name));
    }
    let _ = writeln!(out, "{header}");
    for (i, name) in s.parameters.iter().enumerate() {
        let mut row = format!("  {name:<width$} {:>12.6e}", a.point[i]);
        for q in &a.indices {
            row.push_str(&format!(" {:>14.3}", q[i]));
        }
        let _ = writeln!(out, "{row}");
    }
    let _ = writeln!(out);
}

/// Write `sensitivity.json` and one bar chart per quantity into `dir` (created).
pub fn write(s: &Sensitivity, dir: &Path) -> Result<Vec<PathBuf>> {
    let write_error = |path: &Path, source: std::io::Error| Error::Write {
        path: path.to_path_buf(),
        source,
    };
    std::fs::create_dir_all(dir).map_err(|e| write_error(dir, e))?;
    let json_path = dir.join("sensitivity.json");
    let text = serde_json::to_string_pretty(&sensitivity_json(s)).expect("plain data");
    std::fs::write(&json_path, text).map_err(|e| write_error(&json_path, e))?;
    let mut written = vec![json_path];
    for (q, quantity) in s.quantities.iter().enumerate() {
        let path = dir.join(format!("sensitivity_{}.svg", sanitize(&quantity.name)));
        bar_chart(s, q, &path).map_err(|e| write_error(&path, std::io::Error::other(e)))?;
        written.push(path);
    }
    Ok(written)
}

/// Bars per parameter: first-order and total indices (with their intervals) when Sobol ran,
/// else μ* with σ as whisker.
fn bar_chart(s: &Sensitivity, q: usize, path: &Path) -> std::result::Result<(), String> {
    let quantity = &s.quantities[q];
    let title = if quantity.name == "objective" {
        format!("{}: sensitivity of the objective", s.campaign)
    } else {
        format!(
            "{}: sensitivity of {}'s contribution",
            s.campaign, quantity.name
        )
    };
    // Series: (label, values, intervals, colour).
    type Bars = (String, Vec<f64>, Vec<(f64, f64)>, RGBColor);
    let (series, y_desc): (Vec<Bars>, &str) = match (&quantity.sobol, &quantity.morris) {
        (Some(sobol), _) => (
            vec![
                (
                    "first-order index".into(),
                    sobol.first.clone(),
                    sobol.first_ci.clone(),
                    RGBColor(38, 139, 210),
                ),
                (
                    "total index".into(),
                    sobol.total.clone(),
                    sobol.total_ci.clone(),
                    RGBColor(203, 75, 22),
                ),
            ],
            "Sobol index (95% bootstrap interval)",
        ),
        (None, Some(m)) => (
            vec![(
                "mu* (whisker: sigma)".into(),
                m.mu_star.clone(),
                m.mu_star
                    .iter()
                    .zip(&m.sigma)
                    .map(|(u, sd)| (u - sd, u + sd))
                    .collect(),
                RGBColor(38, 139, 210),
            )],
            "Morris mu* (unit box of the scaled bounds)",
        ),
        (None, None) => return Ok(()),
    };
    let bars: Vec<BarSet> = series
        .iter()
        .map(|(label, values, intervals, color)| BarSet {
            label,
            values,
            intervals,
            color: *color,
        })
        .collect();
    let text = bar_chart_svg(&title, y_desc, &s.parameters, &bars);
    std::fs::write(path, text).map_err(|e| e.to_string())
}

/// The SVG of a bar chart: one group of bars per parameter, named below the axis, the
/// legend beside the data area.
pub fn bar_chart_svg(title: &str, y_label: &str, names: &[String], bars: &[BarSet]) -> String {
    chart::render(&Chart {
        title,
        y_label,
        categories: names,
        bars,
        size: (900, 450),
        ..Chart::default()
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensitivity::sampling::MorrisEffects;
    use crate::sensitivity::{Methods, Quantity, Settings};
    use calib_engine::evaluator::CacheStats;

    /// Morris alone on two parameters: `a` with μ* 1, `b` with μ* 0.005.
    fn morris_only() -> Sensitivity {
        let effects = MorrisEffects {
            mu: vec![1.0, -0.005],
            mu_star: vec![1.0, 0.005],
            sigma: vec![0.1, 0.0],
            effects: vec![4, 4],
        };
        Sensitivity {
            campaign: "c".into(),
            parameters: vec!["a".into(), "b".into()],
            scales: vec![Scale::Lin, Scale::Log10],
            bounds: vec![(0.0, 1.0), (1e-3, 1.0)],
            nominals: vec![0.5, 0.5],
            settings: Settings {
                methods: Methods::Morris,
                samples: 4,
                seed: 1,
            },
            quantities: ["objective", "y/1"]
                .into_iter()
                .map(|name| Quantity {
                    name: name.into(),
                    morris: Some(effects.clone()),
                    sobol: None,
                })
                .collect(),
            morris_points: 12,
            morris_failed: 0,
            sobol_points: 0,
            sobol_failed: 0,
            sobol_excluded: 0,
            stats: CacheStats::default(),
            at_fit: None,
        }
    }

    #[test]
    fn with_morris_alone_a_parameter_below_a_hundredth_of_the_largest_mu_star_is_fixable() {
        let s = morris_only();
        assert!(s.influential(0));
        assert!(!s.influential(1));
        assert_eq!(s.fixable(), vec!["b"]);
        assert!(
            s.conclusion().starts_with("b can be held fixed"),
            "{}",
            s.conclusion()
        );
        let json = sensitivity_json(&s);
        let b = &json["parameters"][1];
        assert_eq!(b["scale"], "log10");
        assert_eq!(b["mu_star"], 0.005);
        assert_eq!(b["influential"], false);
        assert!(b.get("total").is_none(), "{b}");
        assert_eq!(b["outputs"]["y/1"]["mu_star"], 0.005);
        assert_eq!(json["methods"], serde_json::json!(["morris"]));
    }

    #[test]
    fn a_parameter_that_moves_one_output_is_kept_for_it_however_small_on_the_objective() {
        let mut s = morris_only();
        // On the output's contribution `b` has half the largest μ*.
        s.quantities[1].morris = Some(MorrisEffects {
            mu: vec![1.0, 0.5],
            mu_star: vec![1.0, 0.5],
            sigma: vec![0.1, 0.0],
            effects: vec![4, 4],
        });
        assert!(!s.influential_on(0, 1));
        assert!(s.influential_on(1, 1));
        assert!(s.influential(1));
        assert_eq!(s.kept_for(0), None, "influential on the objective itself");
        assert_eq!(s.kept_for(1), Some(1));
        assert!(s.fixable().is_empty());
        let conclusion = s.conclusion();
        assert!(
            conclusion.starts_with("No parameter can be held fixed")
                && conclusion.contains("b is kept for y/1: its μ* is 0.500 of the largest there"),
            "{conclusion}"
        );
        assert_eq!(sensitivity_json(&s)["parameters"][1]["kept_for"], "y/1");
        assert_eq!(
            sensitivity_json(&s)["parameters"][0]["kept_for"],
            Value::Null
        );
    }

    #[test]
    fn a_morris_chart_is_written_per_quantity() {
        let dir = tempfile::tempdir().unwrap();
        let written = write(&morris_only(), dir.path()).unwrap();
        let names: Vec<String> = written
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into_owned())
            .collect();
        assert_eq!(
            names,
            [
                "sensitivity.json",
                "sensitivity_objective.svg",
                "sensitivity_y_1.svg"
            ]
        );
        let svg = std::fs::read_to_string(dir.path().join("sensitivity_y_1.svg")).unwrap();
        assert!(svg.contains("mu* (whisker: sigma)"), "{svg}");
        assert!(svg.contains("y/1"));
    }
}
