//! A calibration's outcome as the API's typed `CalibrationResult`, and back (what `calib
//! submit` renders): every value of `result.json`, with the figures the server derives
//! (each run's label and whether it reached the best, the evaluations answered from the
//! store).

use calib_analysis::report::runs::{self, RunRow};
use calib_engine::campaign::{FreeParameter, InputMapping};
use calib_engine::evidence::{Bound, RunsAtBest};
use calib_engine::outcome::{
    stop_name, stop_named, Best, CalibrationOutcome, ExperimentFit, ExperimentInput, Minimum,
    Named, Range, Run, Spread, WindowSummary,
};
use calib_proto::v1 as pb;
use std::collections::HashMap;

/// `outcome` as the API carries it.
pub fn result_message(outcome: &CalibrationOutcome) -> pb::CalibrationResult {
    let o = outcome;
    pb::CalibrationResult {
        version: o.version,
        campaign: o.campaign.clone(),
        model: o.model.clone(),
        model_version: o.model_version,
        measurement: o.measurement.clone(),
        window: Some(pb::ResultWindow {
            start: o.window.start,
            stop: o.window.stop,
            samples: o.window.samples as u64,
            windows: windows(&o.window.windows),
        }),
        free_parameters: o.free_parameters.iter().map(free_message).collect(),
        nominal_objective: o.nominal_objective,
        nominal_rms: map(&o.nominal_rms),
        best: Some(pb::BestRun {
            parameters: map(&o.best.parameters),
            objective: o.best.objective,
            method: o.best.method.clone(),
            start: o.best.start as u64,
            sse: map(&o.best.sse),
            rms: map(&o.best.rms),
            at_bound: o
                .best
                .at_bound
                .iter()
                .filter_map(|(n, b)| b.map(|b| (n.to_string(), bound_name(b).to_string())))
                .collect(),
        }),
        evaluations: o.evaluations,
        rounds: o.rounds,
        simulated: o.simulated,
        cached: o.cached,
        failed: o.failed,
        runs: run_messages(o),
        clusters: o.clusters.iter().map(minimum_message).collect(),
        runs_at_best: Some(runs_at_best_message(&o.runs_at_best)),
        spread: Some(pb::Spread {
            runs_within_1_percent: o.spread.runs_within_1_percent as u64,
            parameters: o
                .spread
                .parameters
                .iter()
                .map(|(n, r)| (n.to_string(), range(r.min, r.max)))
                .collect(),
        }),
        elapsed_seconds: o.elapsed_seconds,
        inputs: o
            .inputs
            .iter()
            .map(|i| pb::DrivenInput {
                model: i.model.clone(),
                model_index: i.model_index as u64,
                measured: i.measured.clone(),
                interpolation: i.interpolation.as_str().to_string(),
            })
            .collect(),
        experiments: o.experiments.iter().map(experiment_message).collect(),
        outputs: o.outputs(),
        from_store: o.from_store(),
    }
}

/// The runs of a finished campaign as the API lists them: the report's rows (label, flag
/// at the best), with how each run started and stopped.
pub fn run_messages(o: &CalibrationOutcome) -> Vec<pb::Run> {
    runs::rows(o)
        .into_iter()
        .zip(&o.runs)
        .map(|(row, run)| pb::Run {
            start_point: map(&run.start_point),
            stop: stop_name(run.stop).to_string(),
            restarts: run.restarts as u64,
            ..row_message(row)
        })
        .collect()
}

/// One row of the runs table as the API carries it.
pub fn row_message(r: RunRow) -> pb::Run {
    pb::Run {
        label: r.label,
        method: r.method,
        start: r.start as u64,
        evaluations: r.evaluations,
        rounds: r.rounds,
        iterations: r.iterations,
        termination: r.termination,
        objective: r.objective,
        parameters: r.parameters.into_iter().collect(),
        at_best: r.at_best,
        ..Default::default()
    }
}

pub fn runs_at_best_message(r: &RunsAtBest) -> pb::RunsAtBest {
    pb::RunsAtBest {
        count: r.count as u64,
        of: r.of as u64,
        tolerance: r.tolerance,
    }
}

fn free_message(p: &FreeParameter) -> pb::FreeParameter {
    pb::FreeParameter {
        name: p.name.clone(),
        index: p.index as u64,
        nominal: p.nominal,
        min: p.min,
        max: p.max,
        effect: p.effect,
        scale: serde_json::to_value(p.scale)
            .ok()
            .and_then(|v| v.as_str().map(str::to_string))
            .unwrap_or_default(),
        experiment: p.experiment.clone().unwrap_or_default(),
    }
}

fn minimum_message(k: &Minimum) -> pb::Minimum {
    pb::Minimum {
        objective: k.objective,
        parameters: map(&k.parameters),
        runs: k.runs.iter().map(|&i| i as u64).collect(),
        kind: stop_name(k.kind).to_string(),
        extent: k
            .extent
            .iter()
            .map(|(n, (lo, hi))| (n.to_string(), range(*lo, *hi)))
            .collect(),
    }
}

fn experiment_message(e: &ExperimentFit) -> pb::ExperimentFit {
    pb::ExperimentFit {
        name: e.name.clone(),
        measurement: e.measurement.clone(),
        windows: windows(&e.windows),
        samples: e.samples as u64,
        inputs: e
            .inputs
            .iter()
            .map(|i| pb::Input {
                model: i.model.clone(),
                measured: i.measured.clone(),
                interpolation: i.interpolation.clone(),
            })
            .collect(),
        sse: map(&e.sse),
        rms: map(&e.rms),
        nominal_rms: map(&e.nominal_rms),
        objective: e.objective,
        outputs: e.rms.names().map(str::to_string).collect(),
    }
}

fn map(named: &Named<f64>) -> HashMap<String, f64> {
    named.iter().map(|(n, v)| (n.to_string(), *v)).collect()
}

fn range(min: f64, max: f64) -> pb::ValueRange {
    pb::ValueRange { min, max }
}

fn windows(w: &[(f64, f64)]) -> Vec<pb::Window> {
    w.iter()
        .map(|&(start, stop)| pb::Window { start, stop })
        .collect()
}

fn bound_name(b: Bound) -> &'static str {
    match b {
        Bound::Min => "min",
        Bound::Max => "max",
    }
}

/// The outcome a `CalibrationResult` carries: what the coordinator's `result.json` holds,
/// value for value.
pub fn outcome_of(m: &pb::CalibrationResult) -> CalibrationOutcome {
    let free: Vec<FreeParameter> = m.free_parameters.iter().map(free_parameter).collect();
    let names: Vec<String> = free.iter().map(|p| p.name.clone()).collect();
    let best = m.best.clone().unwrap_or_default();
    let window = m.window.clone().unwrap_or_default();
    let spread = m.spread.clone().unwrap_or_default();
    let (count, of, tolerance) = m
        .runs_at_best
        .as_ref()
        .map_or((0, 0, 0.0), |r| (r.count, r.of, r.tolerance));
    CalibrationOutcome {
        version: m.version,
        campaign: m.campaign.clone(),
        model: m.model.clone(),
        model_version: m.model_version,
        measurement: m.measurement.clone(),
        window: WindowSummary {
            start: window.start,
            stop: window.stop,
            samples: window.samples as usize,
            windows: pairs(&window.windows),
        },
        nominal_rms: ordered(&m.nominal_rms, &m.outputs),
        best: Best {
            parameters: ordered(&best.parameters, &names),
            objective: best.objective,
            method: best.method.clone(),
            start: best.start as usize,
            sse: ordered(&best.sse, &m.outputs),
            rms: ordered(&best.rms, &m.outputs),
            at_bound: names
                .iter()
                .map(|n| {
                    let bound = match best.at_bound.get(n).map(String::as_str) {
                        Some("min") => Some(Bound::Min),
                        Some("max") => Some(Bound::Max),
                        _ => None,
                    };
                    (n.clone(), bound)
                })
                .collect(),
        },
        free_parameters: free,
        nominal_objective: m.nominal_objective,
        evaluations: m.evaluations,
        rounds: m.rounds,
        simulated: m.simulated,
        cached: m.cached,
        failed: m.failed,
        runs: m.runs.iter().map(|r| run(r, &names)).collect(),
        clusters: m.clusters.iter().map(|k| minimum(k, &names)).collect(),
        runs_at_best: RunsAtBest {
            count: count as usize,
            of: of as usize,
            tolerance,
        },
        spread: Spread {
            runs_within_1_percent: spread.runs_within_1_percent as usize,
            parameters: names
                .iter()
                .filter_map(|n| {
                    let r = spread.parameters.get(n)?;
                    Some((
                        n.clone(),
                        Range {
                            min: r.min,
                            max: r.max,
                        },
                    ))
                })
                .collect(),
        },
        elapsed_seconds: m.elapsed_seconds,
        inputs: m.inputs.iter().map(driven_input).collect(),
        experiments: m.experiments.iter().map(experiment).collect(),
    }
}

fn free_parameter(p: &pb::FreeParameter) -> FreeParameter {
    FreeParameter {
        name: p.name.clone(),
        index: p.index as usize,
        nominal: p.nominal,
        min: p.min,
        max: p.max,
        effect: p.effect,
        scale: serde_json::from_value(serde_json::Value::String(p.scale.clone()))
            .unwrap_or_default(),
        experiment: (!p.experiment.is_empty()).then(|| p.experiment.clone()),
    }
}

fn driven_input(i: &pb::DrivenInput) -> InputMapping {
    InputMapping {
        model: i.model.clone(),
        model_index: i.model_index as usize,
        measured: i.measured.clone(),
        interpolation: serde_json::from_value(serde_json::Value::String(i.interpolation.clone()))
            .unwrap_or_default(),
    }
}

fn run(r: &pb::Run, names: &[String]) -> Run {
    Run {
        method: r.method.clone(),
        start: r.start as usize,
        start_point: ordered(&r.start_point, names),
        parameters: ordered(&r.parameters, names),
        objective: r.objective,
        evaluations: r.evaluations as usize,
        rounds: r.rounds,
        iterations: r.iterations,
        termination: r.termination.clone(),
        stop: stop_named(&r.stop),
        restarts: r.restarts as usize,
    }
}

fn minimum(k: &pb::Minimum, names: &[String]) -> Minimum {
    Minimum {
        objective: k.objective,
        parameters: ordered(&k.parameters, names),
        runs: k.runs.iter().map(|&i| i as usize).collect(),
        kind: stop_named(&k.kind),
        extent: names
            .iter()
            .filter_map(|n| k.extent.get(n).map(|r| (n.clone(), (r.min, r.max))))
            .collect(),
    }
}

fn experiment(e: &pb::ExperimentFit) -> ExperimentFit {
    ExperimentFit {
        name: e.name.clone(),
        measurement: e.measurement.clone(),
        windows: pairs(&e.windows),
        samples: e.samples as usize,
        inputs: e
            .inputs
            .iter()
            .map(|i| ExperimentInput {
                model: i.model.clone(),
                measured: i.measured.clone(),
                interpolation: i.interpolation.clone(),
            })
            .collect(),
        sse: ordered(&e.sse, &e.outputs),
        rms: ordered(&e.rms, &e.outputs),
        nominal_rms: ordered(&e.nominal_rms, &e.outputs),
        objective: e.objective,
    }
}

fn pairs(w: &[pb::Window]) -> Vec<(f64, f64)> {
    w.iter().map(|w| (w.start, w.stop)).collect()
}

/// The values of `map` in the order of `names`, then any other in the order of their names.
fn ordered(map: &HashMap<String, f64>, names: &[String]) -> Named<f64> {
    let mut rest: Vec<(&String, &f64)> = map.iter().filter(|(n, _)| !names.contains(n)).collect();
    rest.sort_by(|a, b| a.0.cmp(b.0));
    names
        .iter()
        .filter_map(|n| map.get(n).map(|v| (n.clone(), *v)))
        .chain(rest.into_iter().map(|(n, v)| (n.clone(), *v)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An outcome with a value of every kind, infinities included.
    fn outcome() -> CalibrationOutcome {
        let text = include_str!("../../../engine/src/outcome/testdata/two_experiments.json");
        serde_json::from_str(text).unwrap()
    }

    #[test]
    fn a_result_message_carries_every_value_of_the_outcome() {
        let o = outcome();
        let back = outcome_of(&result_message(&o));
        assert_eq!(back, o);
        assert_eq!(back.to_json_text(), o.to_json_text());
    }

    #[test]
    fn the_server_flags_the_runs_at_the_best_and_counts_the_store() {
        let o = outcome();
        let m = result_message(&o);
        let flagged: Vec<bool> = m.runs.iter().map(|r| r.at_best).collect();
        assert_eq!(flagged, o.at_best());
        assert_eq!(flagged, [true, false, true, false]);
        assert_eq!(m.runs[1].label, "powell #0");
        assert_eq!(m.from_store, o.evaluations - o.simulated);
        assert_eq!(m.outputs, ["armJoint.phi", "pendulumJoint.phi"]);
    }
}
