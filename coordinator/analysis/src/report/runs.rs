//! A campaign's runs as rows (what `calib calibrate` prints per run, and what the web app's
//! table of runs shows), each named by one label everywhere.

use super::evidence;
use calib_engine::outcome::CalibrationOutcome;
use calib_engine::store::RunBest;

/// One run (one method from one start) of a campaign.
#[derive(Debug, Clone, PartialEq)]
pub struct RunRow {
    /// [`run_label`]: how tables, plots and pages name the run.
    pub label: String,
    pub method: String,
    /// Index of its start (0 is the nominal point), as `calib calibrate` prints it.
    pub start: usize,
    pub evaluations: u64,
    /// Batches it sent and waited for, one after another.
    pub rounds: u64,
    /// Iterations of its method; 0 while it runs.
    pub iterations: u64,
    /// Why it stopped; empty while it runs.
    pub termination: String,
    /// Its final objective, or the best so far (`+∞` before its first point).
    pub objective: f64,
    /// Its best point by free parameter name, in the campaign's order.
    pub parameters: Vec<(String, f64)>,
    /// Whether it reached the best objective, by [`evidence::runs_at_best`]'s rule.
    pub at_best: bool,
}

/// How a run is named in every table, plot and page: its method and its start as the
/// terminal table and `result.json` count it, from 0 (`nelder-mead #3`).
pub fn run_label(method: &str, start: usize) -> String {
    format!("{method} #{start}")
}

/// The runs of a finished campaign, from its outcome, in plan order.
pub fn rows(result: &CalibrationOutcome) -> Vec<RunRow> {
    let mut rows: Vec<RunRow> = result
        .runs
        .iter()
        .map(|r| RunRow {
            label: run_label(&r.method, r.start),
            method: r.method.clone(),
            start: r.start,
            evaluations: r.evaluations as u64,
            rounds: r.rounds,
            iterations: r.iterations,
            termination: r.termination.clone(),
            objective: r.objective,
            parameters: result
                .free_parameters
                .iter()
                .filter_map(|p| r.parameters.get(&p.name).map(|v| (p.name.clone(), *v)))
                .collect(),
            at_best: false,
        })
        .collect();
    mark_best(&mut rows);
    rows
}

/// The runs of a campaign that has not finished (running, cancelled, failed): each one's
/// best so far, its points' coordinates named by `free`.
pub fn rows_so_far(runs: &[RunBest], free: &[String]) -> Vec<RunRow> {
    let mut rows: Vec<RunRow> = runs
        .iter()
        .map(|r| RunRow {
            label: run_label(&r.method, r.start),
            method: r.method.clone(),
            start: r.start,
            evaluations: r.evaluations as u64,
            rounds: r.rounds as u64,
            iterations: 0,
            termination: String::new(),
            objective: r.objective,
            parameters: free.iter().cloned().zip(r.point.iter().copied()).collect(),
            at_best: false,
        })
        .collect();
    mark_best(&mut rows);
    rows
}

/// The best point of `rows` (its run's parameters), if any run has one.
pub fn best_parameters(rows: &[RunRow]) -> Vec<(String, f64)> {
    rows.iter()
        .filter(|r| r.objective.is_finite() && !r.parameters.is_empty())
        .min_by(|a, b| a.objective.total_cmp(&b.objective))
        .map(|r| r.parameters.clone())
        .unwrap_or_default()
}

/// Flag the runs within [`evidence::BEST_TOLERANCE`] of the best, by
/// [`evidence::at_best_flags`].
fn mark_best(rows: &mut [RunRow]) {
    let objectives: Vec<f64> = rows.iter().map(|r| r.objective).collect();
    for (r, at) in rows.iter_mut().zip(evidence::at_best_flags(&objectives)) {
        r.at_best = at;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn rows_name_each_run_and_flag_those_at_the_best_by_the_summarys_rule() {
        let result: CalibrationOutcome = serde_json::from_value(json!({
            "free_parameters": [
                {"name": "b", "index": 0, "nominal": 1.0, "min": 0.0, "max": 9.0,
                 "effect": false, "scale": "lin"},
                {"name": "a", "index": 1, "nominal": 1.0, "min": 0.0, "max": 9.0,
                 "effect": false, "scale": "lin"},
            ],
            "runs": [
                {"method": "nelder-mead", "start": 0, "objective": 1.0, "evaluations": 10,
                 "iterations": 5, "termination": "converged", "start_point": {},
                 "parameters": {"a": 1.0, "b": 2.0}},
                {"method": "nelder-mead", "start": 1, "objective": 1.0099, "evaluations": 11,
                 "iterations": 6, "termination": "budget", "start_point": {},
                 "parameters": {"a": 1.5, "b": 2.5}},
                {"method": "lbfgs", "start": 0, "objective": 1.0101, "evaluations": 12,
                 "iterations": 7, "termination": "converged", "start_point": {},
                 "parameters": {"a": 3.0, "b": 4.0}},
            ],
        }))
        .unwrap();
        let rows = rows(&result);
        let labels: Vec<&str> = rows.iter().map(|r| r.label.as_str()).collect();
        assert_eq!(labels, ["nelder-mead #0", "nelder-mead #1", "lbfgs #0"]);
        let at: Vec<bool> = rows.iter().map(|r| r.at_best).collect();
        assert_eq!(at, [true, true, false]);
        let objectives: Vec<f64> = rows.iter().map(|r| r.objective).collect();
        assert_eq!(
            at.iter().filter(|b| **b).count(),
            evidence::runs_at_best(&objectives).count
        );
        assert_eq!(
            rows[2].parameters,
            vec![("b".to_string(), 4.0), ("a".to_string(), 3.0)]
        );
        assert_eq!((rows[1].evaluations, rows[1].iterations), (11, 6));
        assert_eq!(rows[1].termination, "budget");
        assert_eq!(
            best_parameters(&rows),
            vec![("b".to_string(), 2.0), ("a".to_string(), 1.0)]
        );
    }

    #[test]
    fn runs_so_far_skip_those_without_a_point() {
        let runs = vec![
            RunBest {
                method: "nelder-mead".into(),
                start: 0,
                point: vec![0.5],
                objective: 2.0,
                evaluations: 3,
                rounds: 2,
            },
            RunBest {
                method: "nelder-mead".into(),
                start: 1,
                point: vec![],
                objective: f64::INFINITY,
                evaluations: 0,
                rounds: 0,
            },
        ];
        let rows = rows_so_far(&runs, &["k".to_string()]);
        assert!(rows[0].at_best && !rows[1].at_best);
        assert_eq!(best_parameters(&rows), vec![("k".to_string(), 0.5)]);
        assert!(rows[1].parameters.is_empty());
    }
}
