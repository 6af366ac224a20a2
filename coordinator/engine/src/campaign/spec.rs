//! The campaign as written, before it is checked against the model ([`super::resolve`]):
//! the one campaign type of every door. A campaign file deserializes into it (spans kept,
//! so that every mistake names its line); the Calibration API's `Campaign` message is
//! converted into it field by field; and it serializes back to the campaign file a hosted
//! campaign is stored and downloaded as. Built values carry empty spans ([`at`]).

use super::Method;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
pub use toml::Spanned;

/// `value` where no text locates it (a campaign built from a message, not read from a file).
pub fn at<T>(value: T) -> Spanned<T> {
    Spanned::new(0..0, value)
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct CampaignSpec {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<Spanned<String>>,
    pub model: Spanned<ModelSection>,
    /// The one-experiment form's record; or else `[[experiments]]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub measurement: Option<MeasurementSection>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outputs: Vec<Spanned<OutputEntry>>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<Spanned<InputEntry>>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parameters: Vec<Spanned<ParameterEntry>>,
    /// Built-in effects made free, and effects defined by a formula.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub effects: Vec<Spanned<EffectEntry>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diagnosis: Option<Spanned<DiagnosisSection>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub window: Option<Spanned<WindowSection>>,
    /// Disjoint fitted intervals `[[start, stop], ...]`, instead of `[window]`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub windows: Option<Spanned<Vec<[f64; 2]>>>,
    /// Several records fitted together with the same parameters.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub experiments: Vec<Spanned<ExperimentEntry>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search: Option<Spanned<SearchSection>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solver: Option<Spanned<SolverSection>>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ModelSection {
    /// A hosted model; or else `fmu`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub name: Option<Spanned<String>>,
    /// The path of an FMU, relative to the campaign file or absolute.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fmu: Option<Spanned<String>>,
    /// How the FMU is run: `"model-exchange"` (default when it has it) or `"co-simulation"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interface: Option<Spanned<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stop_time: Option<Spanned<f64>>,
    /// Where an FMU's simulation starts [s] (default 0).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub start_time: Option<Spanned<f64>>,
    /// A Co-Simulation FMU's communication step [s] (default: its DefaultExperiment's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub step: Option<Spanned<f64>>,
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub parameters: BTreeMap<Spanned<String>, Spanned<f64>>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct MeasurementSection {
    pub file: Spanned<String>,
    #[serde(default = "default_time_column")]
    pub time_column: String,
}

pub fn default_time_column() -> String {
    "time".into()
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct OutputEntry {
    pub model: Spanned<String>,
    pub measured: String,
    /// `k_i`, default 1; not with `sigma`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub weight: Option<Spanned<f64>>,
    /// The output's uncertainty `σ_i` in its unit: `k_i = 1/σ_i²`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sigma: Option<Spanned<f64>>,
    /// `"none"` (default) or `"variance"`: `k_i` divided by the measured signal's variance
    /// over the window.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub scale: Option<Spanned<String>>,
}

/// One record of several fitted together.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ExperimentEntry {
    pub name: Spanned<String>,
    pub file: Spanned<String>,
    #[serde(default = "default_time_column")]
    pub time_column: String,
    /// Where this experiment's plots end (default: its window's stop).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stop_time: Option<Spanned<f64>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub window: Option<Spanned<WindowSection>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub windows: Option<Spanned<Vec<[f64; 2]>>>,
    /// Model values for this experiment alone (a start angle, a set-point).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub fixed: BTreeMap<Spanned<String>, Spanned<f64>>,
    /// This experiment's inputs (default: the campaign's `[[inputs]]`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<Spanned<InputEntry>>,
    /// This experiment's outputs (default: the campaign's `[[outputs]]`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outputs: Vec<Spanned<OutputEntry>>,
    /// Parameters free in this experiment alone (its unknown start angle, a sensor offset
    /// of one day).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub parameters: Vec<Spanned<ParameterEntry>>,
}

/// A model input driven by a measured column.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct InputEntry {
    pub model: Spanned<String>,
    pub measured: String,
    /// `"linear"` (default) or `"hold"`.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interpolation: Option<Spanned<String>>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ParameterEntry {
    pub name: Spanned<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal: Option<f64>,
    pub min: f64,
    pub max: f64,
    #[serde(default, skip_serializing_if = "is_linear")]
    pub scale: super::Scale,
}

/// An `[[effects]]` entry: a built-in effect made free (`name`, `min`, `max`, `nominal`,
/// `scale`), or an effect defined by a formula (`name`, `torque` or `output`, `formula`,
/// `parameters`, `fixed`).
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct EffectEntry {
    pub name: Spanned<String>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    #[serde(default, skip_serializing_if = "is_linear")]
    pub scale: super::Scale,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub torque: Option<Spanned<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub output: Option<Spanned<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub formula: Option<Spanned<String>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameters: Option<Vec<Spanned<UserParameterEntry>>>,
    /// Every parameter of the defined effect held at its nominal value (diagnosis may
    /// still offer it as a candidate).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fixed: Option<bool>,
}

/// A parameter of an effect defined by a formula.
#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct UserParameterEntry {
    pub name: String,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub nominal: Option<f64>,
    pub min: f64,
    pub max: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fixed: Option<bool>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DiagnosisSection {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub holdout_start: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub holdout_stop: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refit: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub candidates: Option<Vec<String>>,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WindowSection {
    pub start: f64,
    pub stop: f64,
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SearchSection {
    #[serde(default = "default_methods")]
    pub methods: Vec<Method>,
    #[serde(default = "default_starts")]
    pub starts: usize,
    #[serde(default = "default_max_evaluations")]
    pub max_evaluations: usize,
    #[serde(default)]
    pub seed: u64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub screening: Option<usize>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cma_population: Option<usize>,
}

/// Whether a parameter's scale is the default, which its campaign file need not state.
fn is_linear(scale: &super::Scale) -> bool {
    *scale == super::Scale::Lin
}

/// The methods of a `[search]` that names none.
pub fn default_methods() -> Vec<Method> {
    vec![Method::NelderMead]
}
pub fn default_starts() -> usize {
    1
}
pub fn default_max_evaluations() -> usize {
    1000
}

#[derive(Debug, Clone, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SolverSection {
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rtol: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub atol: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub max_steps: Option<u64>,
}

impl CampaignSpec {
    /// The campaign file of this campaign: what a hosted campaign is stored as, and read
    /// back from, and what a client downloads.
    pub fn to_toml(&self) -> Result<String, String> {
        toml::to_string(self).map_err(|e| format!("campaign: {e}"))
    }
}
