//! What a calibration found, as one typed value: built once where the calibration ends
//! ([`CalibrationOutcome::of`]), kept as is in the store, written as `result.json` by
//! serializing it, rendered by the report (terminal table, plots), carried field by field
//! by the Calibration API and read back by `calib submit` and the web app.
//!
//! The serialized form is `result.json`: its field names and order are this module's, so a
//! field added to a struct here is a field added to the file. Version [`VERSION`] is the
//! layout `calib` wrote before the file carried a version; a result stored without one
//! reads as that version.

mod named;

pub use named::{Entry, Named};

use crate::campaign::{FreeParameter, InputMapping};
use crate::evidence::{self, Bound, RunsAtBest};
use crate::optim::multistart::Stop;
use serde::{Deserialize, Deserializer, Serialize};

/// Version of the layout of [`CalibrationOutcome`] (`result.json`'s `"version"`).
pub const VERSION: u32 = 1;

fn version() -> u32 {
    VERSION
}

/// A finished calibration: `result.json`, field for field.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct CalibrationOutcome {
    #[serde(default = "version")]
    pub version: u32,
    pub campaign: String,
    pub model: String,
    pub model_version: u32,
    /// The measurement file (the first experiment's, with several).
    pub measurement: String,
    pub window: WindowSummary,
    pub free_parameters: Vec<FreeParameter>,
    #[serde(deserialize_with = "infinite_if_null")]
    pub nominal_objective: f64,
    /// Root mean square error per output at the nominal point.
    pub nominal_rms: Named<f64>,
    pub best: Best,
    /// Evaluations the optimisers asked for (the nominal point and the screening batch
    /// included).
    pub evaluations: u64,
    /// Batches of evaluations waited for one after another: the nominal point, the
    /// screening batch, then per group of concurrent runs its longest run's rounds.
    #[serde(default)]
    pub rounds: u64,
    /// Points simulated, points answered from the cache or the store (repeats and the best
    /// point scored again included), simulations that failed.
    pub simulated: u64,
    pub cached: u64,
    pub failed: u64,
    /// Every method × start, in plan order.
    pub runs: Vec<Run>,
    /// The minima the runs found (and the runs that stalled), best first.
    pub clusters: Vec<Minimum>,
    pub runs_at_best: RunsAtBest,
    pub spread: Spread,
    pub elapsed_seconds: f64,
    /// Model inputs driven by measured columns; none: absent from `result.json`.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<InputMapping>,
    /// Each experiment's share of the fit, when the campaign fits several records.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub experiments: Vec<ExperimentFit>,
}

/// The fitted time window.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct WindowSummary {
    pub start: f64,
    pub stop: f64,
    /// Samples compared (of every experiment, with several).
    pub samples: usize,
    /// The fitted intervals, when there are more than one.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub windows: Vec<(f64, f64)>,
}

/// The best run's point and how well it fits.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct Best {
    pub parameters: Named<f64>,
    #[serde(deserialize_with = "infinite_if_null")]
    pub objective: f64,
    pub method: String,
    pub start: usize,
    /// Sum of squared errors and root mean square error per output.
    pub sse: Named<f64>,
    pub rms: Named<f64>,
    /// The bound of its range each parameter sits on, if any ([`evidence::at_bound`]).
    pub at_bound: Named<Option<Bound>>,
}

/// One run: one method from one start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Run {
    pub method: String,
    /// Index of its start (0 is the nominal point).
    pub start: usize,
    #[serde(default)]
    pub start_point: Named<f64>,
    /// Its best point.
    pub parameters: Named<f64>,
    #[serde(deserialize_with = "infinite_if_null")]
    pub objective: f64,
    pub evaluations: usize,
    /// Batches of evaluations it sent and waited for, one after another.
    #[serde(default)]
    pub rounds: u64,
    #[serde(default)]
    pub iterations: u64,
    #[serde(default)]
    pub termination: String,
    #[serde(default = "minimum")]
    pub stop: Stop,
    #[serde(default)]
    pub restarts: usize,
}

fn minimum() -> Stop {
    Stop::Minimum
}

/// Runs whose best points coincide (a minimum), or every run that stalled one way.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Minimum {
    #[serde(deserialize_with = "infinite_if_null")]
    pub objective: f64,
    pub parameters: Named<f64>,
    /// Indices into the runs.
    pub runs: Vec<usize>,
    pub kind: Stop,
    /// Smallest and largest value of each parameter over its runs.
    #[serde(default)]
    pub extent: Named<(f64, f64)>,
}

/// How far the runs that reached the best objective spread.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct Spread {
    pub runs_within_1_percent: usize,
    pub parameters: Named<Range>,
}

/// Smallest and largest value of a parameter (`+∞` and `−∞` over no run).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Range {
    #[serde(deserialize_with = "infinite_if_null")]
    pub min: f64,
    #[serde(deserialize_with = "negative_infinite_if_null")]
    pub max: f64,
}

/// One experiment of a campaign that fits several records.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct ExperimentFit {
    pub name: String,
    pub measurement: String,
    pub windows: Vec<(f64, f64)>,
    pub samples: usize,
    pub inputs: Vec<ExperimentInput>,
    pub sse: Named<f64>,
    pub rms: Named<f64>,
    pub nominal_rms: Named<f64>,
    /// Its weighted share of the best objective.
    #[serde(deserialize_with = "infinite_if_null")]
    pub objective: f64,
}

/// An input of an experiment driven by a measured column.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(default)]
pub struct ExperimentInput {
    pub model: String,
    pub measured: String,
    /// `linear` or `hold`.
    pub interpolation: String,
}

impl CalibrationOutcome {
    /// The best run's index in `runs` (the first run when none matches).
    pub fn best_index(&self) -> usize {
        self.runs
            .iter()
            .position(|r| r.method == self.best.method && r.start == self.best.start)
            .unwrap_or(0)
    }

    /// Whether each run reached the best objective, by [`evidence::runs_at_best`]'s rule
    /// (over the runs with a finite objective).
    pub fn at_best(&self) -> Vec<bool> {
        let objectives: Vec<f64> = self.runs.iter().map(|r| r.objective).collect();
        evidence::at_best_flags(&objectives)
    }

    /// Evaluations answered from the store: `evaluations − simulated`. (`cached` counts
    /// every answer from the store, also those to points a run looked at ahead of asking
    /// for them and the best point scored again for its plots, so it is larger by those.)
    pub fn from_store(&self) -> u64 {
        self.evaluations.saturating_sub(self.simulated)
    }

    /// The outputs compared, in the campaign's order (the names of `best.rms`).
    pub fn outputs(&self) -> Vec<String> {
        self.best.rms.names().map(str::to_string).collect()
    }

    /// `result.json`'s text (pretty-printed, without the final newline).
    pub fn to_json_text(&self) -> String {
        serde_json::to_string_pretty(self).expect("an outcome is plain data")
    }
}

/// The name `result.json` gives a run's [`Stop`].
pub fn stop_name(stop: Stop) -> &'static str {
    match stop {
        Stop::Minimum => "minimum",
        Stop::Plateau => "plateau",
        Stop::Failures => "failures",
    }
}

/// The [`Stop`] named `name` ([`stop_name`]); a minimum for anything else.
pub fn stop_named(name: &str) -> Stop {
    match name {
        "plateau" => Stop::Plateau,
        "failures" => Stop::Failures,
        _ => Stop::Minimum,
    }
}

/// JSON has no infinity: a non-finite number is written `null`, read back as `+∞` (an
/// objective or an error no point reached).
fn infinite_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}

/// As [`infinite_if_null`], for the largest of no value: `−∞`.
fn negative_infinite_if_null<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::NEG_INFINITY))
}

#[cfg(test)]
mod tests;
