//! The typed outcome ([`crate::outcome`]) of a calibration from what it found.

use super::Calibration;
use crate::evidence::{self, Bound};
use crate::optim::multistart::RunOutcome;
use crate::outcome::{
    Best, CalibrationOutcome, ExperimentFit, ExperimentInput, Minimum, Named, Range, Run, Spread,
    WindowSummary, VERSION,
};

fn named(names: &[String], values: &[f64]) -> Named<f64> {
    names.iter().cloned().zip(values.iter().copied()).collect()
}

impl CalibrationOutcome {
    /// What calibration `c` found, as `result.json` states it.
    pub fn of(c: &Calibration) -> Self {
        let names: Vec<String> = c.campaign.free.iter().map(|p| p.name.clone()).collect();
        let best = c.best_run();
        let samples = c.objective.grid.len() as f64;
        let per_output = |values: &[f64]| -> Named<f64> {
            c.campaign
                .outputs
                .iter()
                .zip(values)
                .map(|(o, v)| (o.model.clone(), *v))
                .collect()
        };
        let rms: Vec<f64> = c
            .best_evaluation
            .sse
            .iter()
            .map(|s| (s / samples).sqrt())
            .collect();
        let nominal_rms: Vec<f64> = c.nominal.sse.iter().map(|s| (s / samples).sqrt()).collect();
        let runs = runs(c, &names);
        let clusters = minima(c, &names);
        // Spread of the parameters over the runs that reached the best objective.
        let threshold = evidence::best_threshold(best.objective);
        let agreeing: Vec<_> = c.runs.iter().filter(|r| r.objective <= threshold).collect();
        let spread = spread(&agreeing, &names);
        let objectives: Vec<f64> = c.runs.iter().map(|r| r.objective).collect();
        let at_bound = bounds_reached(c, best);
        let info = c.campaign.model.info();
        CalibrationOutcome {
            version: VERSION,
            campaign: c.campaign.name.clone(),
            model: info.name.clone(),
            model_version: info.version,
            measurement: c.measurement.source.display().to_string(),
            window: window_summary(c),
            free_parameters: c.campaign.free.clone(),
            nominal_objective: c.nominal.objective,
            nominal_rms: per_output(&nominal_rms),
            best: Best {
                parameters: named(&names, &best.point),
                objective: best.objective,
                method: best.method.name().to_string(),
                start: best.start,
                sse: per_output(&c.best_evaluation.sse),
                rms: per_output(&rms),
                at_bound,
            },
            evaluations: c.evaluations() as u64,
            rounds: c.rounds() as u64,
            simulated: c.stats.simulated,
            cached: c.stats.cached,
            failed: c.stats.failed,
            runs,
            clusters,
            runs_at_best: evidence::runs_at_best(&objectives),
            spread: Spread {
                runs_within_1_percent: agreeing.len(),
                parameters: spread,
            },
            elapsed_seconds: c.elapsed.as_secs_f64(),
            inputs: c.campaign.inputs.clone(),
            experiments: experiments(c),
        }
    }
}

/// The time window fitted and its samples; the separate windows only when there are several.
fn window_summary(c: &Calibration) -> WindowSummary {
    WindowSummary {
        start: c.campaign.window.0,
        stop: c.campaign.window.1,
        samples: c.objective.grid.len(),
        windows: if c.campaign.windows.len() > 1 {
            c.campaign.windows.clone()
        } else {
            Vec::new()
        },
    }
}

/// The bound of its range each free parameter of the best run sits on, if any.
fn bounds_reached(c: &Calibration, best: &RunOutcome) -> Named<Option<Bound>> {
    c.campaign
        .free
        .iter()
        .zip(&best.point)
        .map(|(p, &v)| {
            (
                p.name.clone(),
                evidence::at_bound(v, p.nominal, p.min, p.max),
            )
        })
        .collect()
}

/// Every run: where it started, where it ended, what it cost and why it stopped.
fn runs(c: &Calibration, names: &[String]) -> Vec<Run> {
    c.runs
        .iter()
        .map(|r| Run {
            method: r.method.name().to_string(),
            start: r.start,
            start_point: named(names, &r.start_point),
            parameters: named(names, &r.point),
            objective: r.objective,
            evaluations: r.evaluations,
            rounds: r.rounds as u64,
            iterations: r.iterations,
            termination: r.termination.clone(),
            stop: r.stop,
            restarts: r.restarts,
        })
        .collect()
}

/// The distinct minima the runs ended in.
fn minima(c: &Calibration, names: &[String]) -> Vec<Minimum> {
    c.clusters
        .iter()
        .map(|k| Minimum {
            objective: k.objective,
            parameters: named(names, &k.point),
            runs: k.runs.clone(),
            kind: k.kind,
            extent: names
                .iter()
                .cloned()
                .zip(k.extent.iter().copied())
                .collect(),
        })
        .collect()
}

/// The range of each parameter over the runs `agreeing` (those at the best objective).
fn spread(agreeing: &[&RunOutcome], names: &[String]) -> Named<Range> {
    names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            let values = agreeing.iter().map(|r| r.point[i]);
            let min = values.clone().fold(f64::INFINITY, f64::min);
            let max = values.fold(f64::NEG_INFINITY, f64::max);
            (n.clone(), Range { min, max })
        })
        .collect()
}

/// Each experiment's share of the best fit, when the campaign fits several records.
fn experiments(c: &Calibration) -> Vec<ExperimentFit> {
    if c.objective.more.is_empty() && c.objective.name.is_empty() {
        return Vec::new();
    }
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
            let over = |values: &[f64], f: &dyn Fn(f64) -> f64| -> Named<f64> {
                e.outputs
                    .iter()
                    .zip(values)
                    .map(|(o, v)| (o.model.clone(), f(*v)))
                    .collect()
            };
            ExperimentFit {
                name: e.name.clone(),
                measurement: e.measurement_file.display().to_string(),
                windows: e.windows.clone(),
                samples: part.grid.len(),
                inputs: e
                    .inputs
                    .iter()
                    .map(|i| ExperimentInput {
                        model: i.model.clone(),
                        measured: i.measured.clone(),
                        interpolation: i.interpolation.as_str().to_string(),
                    })
                    .collect(),
                sse: over(sse, &|v| v),
                rms: over(sse, &|v| (v / samples).sqrt()),
                nominal_rms: over(nominal, &|v| (v / samples).sqrt()),
                objective: part
                    .weights
                    .iter()
                    .zip(sse)
                    .map(|(k, s)| k * s)
                    .sum::<f64>(),
            }
        })
        .collect()
}
