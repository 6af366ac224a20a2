//! The campaign file as written: the TOML sections, before they are checked against the
//! model ([`super::resolve`]). Spans are kept so that every mistake names its line.

use super::Method;
use serde::Deserialize;
use toml::Spanned;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct CampaignFile {
    pub(super) name: Option<Spanned<String>>,
    pub(super) model: Spanned<ModelSection>,
    /// The one-experiment form's record; or else `[[experiments]]`.
    pub(super) measurement: Option<MeasurementSection>,
    #[serde(default)]
    pub(super) outputs: Vec<Spanned<OutputEntry>>,
    #[serde(default)]
    pub(super) inputs: Vec<Spanned<InputEntry>>,
    #[serde(default)]
    pub(super) parameters: Vec<Spanned<ParameterEntry>>,
    /// Built-in effects made free, and effects defined by a formula.
    #[serde(default)]
    pub(super) effects: Vec<Spanned<EffectEntry>>,
    #[serde(default)]
    pub(super) diagnosis: Option<Spanned<DiagnosisSection>>,
    pub(super) window: Option<Spanned<WindowSection>>,
    /// Disjoint fitted intervals `[[start, stop], ...]`, instead of `[window]`.
    pub(super) windows: Option<Spanned<Vec<[f64; 2]>>>,
    /// Several records fitted together with the same parameters.
    #[serde(default)]
    pub(super) experiments: Vec<Spanned<ExperimentEntry>>,
    #[serde(default)]
    pub(super) search: Option<Spanned<SearchSection>>,
    #[serde(default)]
    pub(super) solver: Option<Spanned<SolverSection>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ModelSection {
    /// A hosted model; or else `fmu`.
    pub(super) name: Option<Spanned<String>>,
    /// The path of an FMU, relative to the campaign file or absolute.
    pub(super) fmu: Option<Spanned<String>>,
    /// How the FMU is run: `"model-exchange"` (default when it has it) or `"co-simulation"`.
    pub(super) interface: Option<Spanned<String>>,
    pub(super) stop_time: Option<Spanned<f64>>,
    /// Where an FMU's simulation starts [s] (default 0).
    pub(super) start_time: Option<Spanned<f64>>,
    /// A Co-Simulation FMU's communication step [s] (default: its DefaultExperiment's).
    pub(super) step: Option<Spanned<f64>>,
    #[serde(default)]
    pub(super) parameters: std::collections::BTreeMap<Spanned<String>, Spanned<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct MeasurementSection {
    pub(super) file: Spanned<String>,
    #[serde(default = "default_time_column")]
    pub(super) time_column: String,
}

pub(super) fn default_time_column() -> String {
    "time".into()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct OutputEntry {
    pub(super) model: Spanned<String>,
    pub(super) measured: String,
    /// `k_i`, default 1; not with `sigma`.
    pub(super) weight: Option<Spanned<f64>>,
    /// The output's uncertainty `σ_i` in its unit: `k_i = 1/σ_i²`.
    pub(super) sigma: Option<Spanned<f64>>,
    /// `"none"` (default) or `"variance"`: `k_i` divided by the measured signal's variance
    /// over the window.
    pub(super) scale: Option<Spanned<String>>,
}

/// One record of several fitted together.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ExperimentEntry {
    pub(super) name: Spanned<String>,
    pub(super) file: Spanned<String>,
    #[serde(default = "default_time_column")]
    pub(super) time_column: String,
    /// Where this experiment's plots end (default: its window's stop).
    pub(super) stop_time: Option<Spanned<f64>>,
    pub(super) window: Option<Spanned<WindowSection>>,
    pub(super) windows: Option<Spanned<Vec<[f64; 2]>>>,
    /// Model values for this experiment alone (a start angle, a set-point).
    #[serde(default)]
    pub(super) fixed: std::collections::BTreeMap<Spanned<String>, Spanned<f64>>,
    /// This experiment's inputs (default: the campaign's `[[inputs]]`).
    #[serde(default)]
    pub(super) inputs: Vec<Spanned<InputEntry>>,
    /// This experiment's outputs (default: the campaign's `[[outputs]]`).
    #[serde(default)]
    pub(super) outputs: Vec<Spanned<OutputEntry>>,
    /// Parameters free in this experiment alone (its unknown start angle, a sensor offset
    /// of one day).
    #[serde(default)]
    pub(super) parameters: Vec<Spanned<ParameterEntry>>,
}

/// A model input driven by a measured column.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct InputEntry {
    pub(super) model: Spanned<String>,
    pub(super) measured: String,
    /// `"linear"` (default) or `"hold"`.
    pub(super) interpolation: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct ParameterEntry {
    pub(super) name: Spanned<String>,
    pub(super) nominal: Option<f64>,
    pub(super) min: f64,
    pub(super) max: f64,
    #[serde(default)]
    pub(super) scale: super::Scale,
}

/// An `[[effects]]` entry: a built-in effect made free (`name`, `min`, `max`, `nominal`,
/// `scale`), or an effect defined by a formula (`name`, `torque` or `output`, `formula`,
/// `parameters`, `fixed`).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct EffectEntry {
    pub(super) name: Spanned<String>,
    pub(super) nominal: Option<f64>,
    pub(super) min: Option<f64>,
    pub(super) max: Option<f64>,
    #[serde(default)]
    pub(super) scale: super::Scale,
    pub(super) torque: Option<Spanned<String>>,
    pub(super) output: Option<Spanned<String>>,
    pub(super) formula: Option<Spanned<String>>,
    pub(super) parameters: Option<Vec<Spanned<UserParameterEntry>>>,
    /// Every parameter of the defined effect held at its nominal value (diagnosis may
    /// still offer it as a candidate).
    pub(super) fixed: Option<bool>,
}

/// A parameter of an effect defined by a formula.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct UserParameterEntry {
    pub(super) name: String,
    pub(super) nominal: Option<f64>,
    pub(super) min: f64,
    pub(super) max: f64,
    pub(super) fixed: Option<bool>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct DiagnosisSection {
    pub(super) holdout_start: Option<f64>,
    pub(super) holdout_stop: Option<f64>,
    pub(super) refit: Option<usize>,
    pub(super) candidates: Option<Vec<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct WindowSection {
    pub(super) start: f64,
    pub(super) stop: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SearchSection {
    #[serde(default = "default_methods")]
    pub(super) methods: Vec<Method>,
    #[serde(default = "default_starts")]
    pub(super) starts: usize,
    #[serde(default = "default_max_evaluations")]
    pub(super) max_evaluations: usize,
    #[serde(default)]
    pub(super) seed: u64,
    pub(super) screening: Option<usize>,
    pub(super) cma_population: Option<usize>,
}

/// The methods of a `[search]` that names none.
pub fn default_methods() -> Vec<Method> {
    vec![Method::NelderMead]
}
pub(super) fn default_starts() -> usize {
    1
}
pub(super) fn default_max_evaluations() -> usize {
    1000
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct SolverSection {
    pub(super) rtol: Option<f64>,
    pub(super) atol: Option<f64>,
    pub(super) max_steps: Option<u64>,
}
