//! What a calibration leaves behind: `result.json`, a table for the terminal, SVG plots.

pub mod chart;
pub mod evidence;
pub mod plot;
#[cfg(test)]
mod readable;
pub mod runs;
pub mod table;
pub mod ticks;

use crate::calibration::Calibration;
use crate::error::{Error, Result};
use serde_json::{json, Map, Value};
use std::path::{Path, PathBuf};

fn named(names: &[String], values: &[f64]) -> Value {
    Value::Object(
        names
            .iter()
            .zip(values)
            .map(|(n, v)| (n.clone(), json!(v)))
            .collect::<Map<_, _>>(),
    )
}

/// The machine-readable result of a calibration (`result.json`).
pub fn result_json(c: &Calibration) -> Value {
    let names: Vec<String> = c.campaign.free.iter().map(|p| p.name.clone()).collect();
    let best = c.best_run();
    let samples = c.objective.grid.len() as f64;
    let per_output = |values: &[f64]| {
        Value::Object(
            c.campaign
                .outputs
                .iter()
                .zip(values)
                .map(|(o, v)| (o.model.clone(), json!(v)))
                .collect(),
        )
    };
    let rms: Vec<f64> = c
        .best_evaluation
        .sse
        .iter()
        .map(|s| (s / samples).sqrt())
        .collect();
    let nominal_rms: Vec<f64> = c.nominal.sse.iter().map(|s| (s / samples).sqrt()).collect();
    let runs: Vec<Value> = c
        .runs
        .iter()
        .map(|r| {
            json!({
                "method": r.method.name(),
                "start": r.start,
                "start_point": named(&names, &r.start_point),
                "parameters": named(&names, &r.point),
                "objective": r.objective,
                "evaluations": r.evaluations,
                "rounds": r.rounds,
                "iterations": r.iterations,
                "termination": r.termination,
                "stop": r.stop,
                "restarts": r.restarts,
            })
        })
        .collect();
    let clusters: Vec<Value> = c
        .clusters
        .iter()
        .map(|k| {
            json!({
                "objective": k.objective,
                "parameters": named(&names, &k.point),
                "runs": k.runs,
                "kind": k.kind,
                "extent": names.iter().zip(&k.extent).map(|(n, (lo, hi))| (n.clone(), json!([lo, hi]))).collect::<Map<String, Value>>(),
            })
        })
        .collect();
    // Spread of the parameters over the runs that reached the best objective.
    let threshold = evidence::best_threshold(best.objective);
    let agreeing: Vec<_> = c.runs.iter().filter(|r| r.objective <= threshold).collect();
    let spread: Map<String, Value> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let values = agreeing.iter().map(|r| r.point[i]);
            let min = values.clone().fold(f64::INFINITY, f64::min);
            let max = values.fold(f64::NEG_INFINITY, f64::max);
            (n.clone(), json!({ "min": min, "max": max }))
        })
        .collect();
    let objectives: Vec<f64> = c.runs.iter().map(|r| r.objective).collect();
    let at_best = evidence::runs_at_best(&objectives);
    let at_bound: Map<String, Value> = c
        .campaign
        .free
        .iter()
        .zip(&best.point)
        .map(|(p, &v)| {
            (
                p.name.clone(),
                json!(evidence::at_bound(v, p.nominal, p.min, p.max)),
            )
        })
        .collect();
    let evaluations = c.evaluations() as u64;
    // Each experiment's share of the best fit, when the campaign fits several records.
    let experiments: Vec<Value> = if c.objective.more.is_empty() && c.objective.name.is_empty() {
        Vec::new()
    } else {
        let mut from = 0;
        c.campaign
            .experiments()
            .iter()
            .zip(c.objective.experiments())
            .map(|(e, part)| {
                let n = part.outputs.len();
                let sse = &c.best_evaluation.sse[from..(from + n).min(c.best_evaluation.sse.len())];
                let nominal = &c.nominal.sse[from..(from + n).min(c.nominal.sse.len())];
                from += n;
                let samples = part.grid.len() as f64;
                let over = |values: &[f64], f: &dyn Fn(f64) -> f64| {
                    Value::Object(
                        e.outputs
                            .iter()
                            .zip(values)
                            .map(|(o, v)| (o.model.clone(), json!(f(*v))))
                            .collect(),
                    )
                };
                let by_output = |f: &dyn Fn(f64) -> f64| over(sse, f);
                json!({
                    "name": e.name,
                    "measurement": e.measurement_file.display().to_string(),
                    "windows": e.windows.iter().map(|w| json!([w.0, w.1])).collect::<Vec<_>>(),
                    "samples": part.grid.len(),
                    "inputs": e.inputs.iter().map(|i| json!({"model": i.model, "measured": i.measured, "interpolation": i.interpolation.as_str()})).collect::<Vec<_>>(),
                    "sse": by_output(&|v| v),
                    "rms": by_output(&|v| (v / samples).sqrt()),
                    "nominal_rms": over(nominal, &|v| (v / samples).sqrt()),
                    "objective": part.weights.iter().zip(sse).map(|(k, s)| k * s).sum::<f64>(),
                })
            })
            .collect()
    };
    let mut result = json!({
        "campaign": c.campaign.name,
        "model": c.campaign.model.info().name,
        "model_version": c.campaign.model.info().version,
        "measurement": c.measurement.source.display().to_string(),
        "window": { "start": c.campaign.window.0, "stop": c.campaign.window.1, "samples": c.objective.grid.len() },
        "free_parameters": c.campaign.free,
        "nominal_objective": c.nominal.objective,
        "nominal_rms": per_output(&nominal_rms),
        "best": {
            "parameters": named(&names, &best.point),
            "objective": best.objective,
            "method": best.method.name(),
            "start": best.start,
            "sse": per_output(&c.best_evaluation.sse),
            "rms": per_output(&rms),
            "at_bound": at_bound,
        },
        "evaluations": evaluations,
        "rounds": c.rounds(),
        "simulated": c.stats.simulated,
        "cached": c.stats.cached,
        "failed": c.stats.failed,
        "runs": runs,
        "clusters": clusters,
        "runs_at_best": at_best,
        "spread": { "runs_within_1_percent": agreeing.len(), "parameters": spread },
        "elapsed_seconds": c.elapsed.as_secs_f64(),
    });
    if !c.campaign.inputs.is_empty() {
        result["inputs"] = json!(c.campaign.inputs);
    }
    if c.campaign.windows.len() > 1 {
        result["window"]["windows"] = json!(c
            .campaign
            .windows
            .iter()
            .map(|w| json!([w.0, w.1]))
            .collect::<Vec<_>>());
    }
    if !experiments.is_empty() {
        result["experiments"] = Value::Array(experiments);
    }
    result
}

/// Write `result.json` and one plot per output into `dir`; the paths written.
pub fn write(c: &Calibration, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    let path = dir.join("result.json");
    let text = serde_json::to_string_pretty(&result_json(c)).expect("json of plain values");
    std::fs::write(&path, text + "\n").map_err(|source| Error::Write {
        path: path.clone(),
        source,
    })?;
    written.push(path);
    written.extend(plot::write_fit_plots(c, dir)?);
    written.push(plot::write_waterfall(c, dir)?);
    Ok(written)
}
