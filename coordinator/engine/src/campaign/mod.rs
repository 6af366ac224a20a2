//! Campaign files: what to calibrate, against which data, how.
//!
//! A campaign is written in TOML (unknown keys are rejected) and resolved against the hosted
//! models before anything runs, so every mistake is reported up front with the file, the
//! line and the field. See docs/campaigns.md for the format.

mod identity;
mod resolve;
pub mod spec;
#[cfg(test)]
mod tests;
mod user_effects;

pub use calib_model::inputs::Interpolation;
use calib_model::{Model, SolverOptions};
pub use resolve::MAX_EXPERIMENTS;
use resolve::{resolve, Locator};
use serde::Deserialize;
pub use spec::{default_methods, CampaignSpec};
use std::fmt;
use std::path::{Path, PathBuf};

/// A mistake in a campaign, located in its file.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub struct CampaignError {
    pub file: PathBuf,
    pub line: Option<usize>,
    pub field: String,
    pub message: String,
}

impl fmt::Display for CampaignError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}", self.file.display())?;
        if let Some(line) = self.line {
            write!(f, ":{line}")?;
        }
        if self.field.is_empty() {
            write!(f, ": {}", self.message)
        } else {
            write!(f, ": `{}`: {}", self.field, self.message)
        }
    }
}

/// The optimisation methods a campaign can ask for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Deserialize, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Method {
    NelderMead,
    Powell,
    DifferentialEvolution,
    LevenbergMarquardt,
    CmaEs,
}

impl Method {
    /// Every method, in the order `--help`, the docs and the benchmarks list them.
    pub const ALL: [Method; 5] = [
        Method::NelderMead,
        Method::Powell,
        Method::DifferentialEvolution,
        Method::LevenbergMarquardt,
        Method::CmaEs,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Method::NelderMead => "nelder-mead",
            Method::Powell => "powell",
            Method::DifferentialEvolution => "differential-evolution",
            Method::LevenbergMarquardt => "levenberg-marquardt",
            Method::CmaEs => "cma-es",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// A parameter the optimisers search over.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FreeParameter {
    pub name: String,
    /// Position in the model's full parameter vector.
    pub index: usize,
    pub nominal: f64,
    pub min: f64,
    pub max: f64,
    /// Whether this is one of the model's effects (absent at 0) rather than a base parameter.
    pub effect: bool,
    /// The scale the optimisers search it on.
    pub scale: Scale,
    /// The experiment it belongs to when it is free in that one alone (its name is then
    /// `<parameter>@<experiment>`); `None`: one value for every experiment.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub experiment: Option<String>,
}

impl FreeParameter {
    /// Whether it is set in the experiment called `experiment`.
    pub fn applies_to(&self, experiment: &str) -> bool {
        self.experiment.as_deref().is_none_or(|e| e == experiment)
    }
}

/// One record of a campaign that fits several together: its file, what is compared and
/// driven, when, and the model values that are its own.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Experiment {
    pub name: String,
    pub measurement_file: PathBuf,
    pub time_column: String,
    pub outputs: Vec<OutputMapping>,
    pub inputs: Vec<InputMapping>,
    /// From the first fitted interval's start to the last one's stop.
    pub window: (f64, f64),
    /// The fitted intervals, disjoint, in time order.
    pub windows: Vec<(f64, f64)>,
    /// End of its simulated horizon (plots).
    pub stop_time: f64,
    /// Its full parameter vector: the campaign's, with its own fixed values and its own
    /// free parameters at their nominal values (the campaign-wide free ones at theirs).
    pub base: Vec<f64>,
}

/// The scale a parameter is searched on, as PEtab's `parameterScale`: starts, simplices,
/// populations, clustering and spreads live in the box of the scaled values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scale {
    /// The value itself (the default).
    #[default]
    Lin,
    /// Its decimal logarithm; needs a lower bound above 0.
    Log10,
}

/// A model output compared with a measured column.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutputMapping {
    pub model: String,
    pub model_index: usize,
    pub measured: String,
    /// `k_i` as written: `weight`, or `1/σ²` from `sigma`.
    pub weight: f64,
    /// How the weight is scaled by the data once the window is known.
    pub scale: OutputScale,
}

/// A model input driven by a measured column (linear between samples, or held).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InputMapping {
    pub model: String,
    pub model_index: usize,
    pub measured: String,
    pub interpolation: Interpolation,
}

/// Scaling of an output's weight by its measured data, so that outputs in different units
/// weigh alike (an NRMSE-type objective).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum OutputScale {
    /// `k_i` as given.
    #[default]
    None,
    /// `k_i / var(w_i)`, the variance of the measured signal over the window:
    /// `k_i Σ_t (y − w)² / var(w)` is `k_i N NRMSE²` with the error normalised by the
    /// signal's standard deviation.
    Variance,
}

impl OutputScale {
    pub fn name(self) -> &'static str {
        match self {
            OutputScale::None => "none",
            OutputScale::Variance => "variance",
        }
    }
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Search {
    pub methods: Vec<Method>,
    /// Start points per method: the nominal point, then seeded quasi-random points.
    pub starts: usize,
    /// Evaluation budget of each run (one method from one start).
    pub max_evaluations: usize,
    pub seed: u64,
    /// Points of the screening batch that places the starts after the nominal one; `None`
    /// for the default ([`crate::optim::screening::default_count`]), 0 for plain
    /// quasi-random starts.
    pub screening: Option<usize>,
    /// Smallest population of CMA-ES (`cma_population`; `4 + ⌊3 ln n⌋` when larger). Unset:
    /// differential evolution's, `max(15, 10 n)`, so that a generation is a round as full as
    /// one of differential evolution: on workers, a round costs the same wall time whether it
    /// holds 6 points or 20, and the larger population needs fewer of them.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cma_population: Option<usize>,
    /// Further start points (physical values of the free parameters), tried after the
    /// nominal point; set by diagnosis, not by campaign files.
    pub extra_starts: Vec<Vec<f64>>,
    /// Stop each run once its objective stops moving; set by diagnosis for its refits,
    /// not by campaign files.
    #[serde(skip)]
    pub stall: Option<Stall>,
}

/// A campaign checked against the model it names.
#[derive(Clone)]
pub struct Campaign {
    pub name: String,
    /// The campaign file, when the campaign came from one.
    pub source: Option<PathBuf>,
    /// The campaign's text as written (the store keeps it to resume the campaign).
    pub spec: String,
    pub model: &'static dyn Model,
    /// End of the simulated horizon (plots run to it; the fit uses the window).
    pub stop_time: f64,
    /// The full parameter vector: model defaults, then the campaign's fixed values, with the
    /// free parameters at their nominal values.
    pub base: Vec<f64>,
    pub free: Vec<FreeParameter>,
    pub measurement_file: PathBuf,
    pub time_column: String,
    pub outputs: Vec<OutputMapping>,
    /// Model inputs driven by measured columns of the same file.
    pub inputs: Vec<InputMapping>,
    /// From the first fitted interval's start to the last one's stop.
    pub window: (f64, f64),
    /// The fitted intervals, disjoint, in time order (one: the window).
    pub windows: Vec<(f64, f64)>,
    /// The name of the first experiment when the campaign lists `[[experiments]]` (its
    /// record is `measurement_file`, its settings the fields above); empty for the
    /// one-record form.
    pub experiment: String,
    /// The further experiments fitted with the same parameters.
    pub more: Vec<Experiment>,
    pub search: Search,
    pub solver: SolverOptions,
    pub diagnosis: DiagnosisSettings,
}

/// How `calib diagnose` treats a campaign.
#[derive(Debug, Clone, PartialEq, Default, serde::Serialize)]
pub struct DiagnosisSettings {
    /// Held-out window [s]; default: the data after the fitted window, or else the last
    /// fifth of the window (which is then not fitted).
    pub holdout: Option<(f64, f64)>,
    /// How many of the best-ranked candidates are refitted (alone, and in pairs).
    pub refit: usize,
    /// Restrict the candidates to these effects (default: every effect the model has).
    pub candidates: Option<Vec<String>>,
}

impl fmt::Debug for Campaign {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Campaign")
            .field("name", &self.name)
            .field("model", &self.model.info().name)
            .field("free", &self.free)
            .field("outputs", &self.outputs)
            .field("inputs", &self.inputs)
            .field("window", &self.window)
            .field("search", &self.search)
            .finish()
    }
}

/// The key of a campaign file a deserialiser's path names, as campaigns name fields
/// (`search.screening`, `parameters[0].name`); the wrappers that keep positions are not keys.
fn field_of(path: &serde_path_to_error::Path) -> String {
    use serde_path_to_error::Segment;
    let mut field = String::new();
    for segment in path.iter() {
        match segment {
            Segment::Seq { index } => field.push_str(&format!("[{index}]")),
            Segment::Map { key } | Segment::Enum { variant: key } => {
                if key.starts_with("$__serde_spanned") {
                    continue;
                }
                if !field.is_empty() {
                    field.push('.');
                }
                field.push_str(key);
            }
            Segment::Unknown => {}
        }
    }
    field
}

/// A deserialiser's message with any number it quotes shortened (`1e308`, not its 309
/// digits) and Rust's integer type names said in words.
fn readable_type_error(message: &str) -> String {
    let mut out = message.to_string();
    if let Some(start) = out.find("floating point `") {
        let from = start + "floating point `".len();
        if let Some(len) = out[from..].find('`') {
            let number = &out[from..from + len];
            if let Ok(v) = number.parse::<f64>() {
                let short = if v.fract() == 0.0 && v.abs() < 1e6 {
                    format!("{v}")
                } else {
                    format!("{v:e}")
                };
                out.replace_range(from..from + len, &short);
            }
        }
    }
    for (rust, words) in [
        ("expected usize", "expected a whole number"),
        ("expected u64", "expected a whole number"),
        ("expected u32", "expected a whole number"),
        ("expected u16", "expected a whole number"),
        ("expected i64", "expected a whole number"),
    ] {
        if out.ends_with(rust) {
            out.replace_range(out.len() - rust.len().., words);
        }
    }
    out
}

impl CampaignSpec {
    /// Read campaign text, not yet checked against its model; `path` locates errors.
    pub fn parse(text: &str, path: &Path) -> Result<CampaignSpec, CampaignError> {
        let locate = Locator {
            text: Some(text),
            path,
        };
        let error = |e: toml::de::Error, field: String| CampaignError {
            file: path.to_path_buf(),
            line: e.span().and_then(|s| locate.line(s.start)),
            field,
            message: readable_type_error(e.message().trim()),
        };
        let document = toml::Deserializer::parse(text).map_err(|e| error(e, String::new()))?;
        serde_path_to_error::deserialize(document).map_err(|e| {
            let field = field_of(e.path());
            error(e.into_inner(), field)
        })
    }
}

impl Campaign {
    /// Read and resolve a campaign file.
    pub fn load(path: &Path) -> Result<Campaign, CampaignError> {
        let text = std::fs::read_to_string(path).map_err(|e| CampaignError {
            file: path.to_path_buf(),
            line: None,
            field: String::new(),
            message: format!("cannot read campaign file: {e}"),
        })?;
        Self::parse(&text, path)
    }

    /// Resolve campaign text; `path` locates errors and relative measurement files.
    pub fn parse(text: &str, path: &Path) -> Result<Campaign, CampaignError> {
        let spec = CampaignSpec::parse(text, path)?;
        let locate = Locator {
            text: Some(text),
            path,
        };
        resolve(spec, &locate, text.to_string())
    }

    /// Resolve `spec`, a campaign built rather than read (from a message of the Calibration
    /// API): its errors name the field, with no line; `path` is where it is said to be, and
    /// what relative files are relative to. It keeps its campaign file
    /// ([`CampaignSpec::to_toml`]), which parses back to the same campaign.
    pub fn from_spec(spec: CampaignSpec, path: &Path) -> Result<Campaign, CampaignError> {
        let text = spec.to_toml().map_err(|message| CampaignError {
            file: path.to_path_buf(),
            line: None,
            field: String::new(),
            message,
        })?;
        resolve(spec, &Locator { text: None, path }, text)
    }

    /// Nominal values of the free parameters.
    pub fn nominal(&self) -> Vec<f64> {
        self.free.iter().map(|p| p.nominal).collect()
    }

    /// The full parameter vector of the first experiment with the free parameters set to
    /// `free_values` (another experiment's own free parameters left out).
    pub fn full_parameters(&self, free_values: &[f64]) -> Vec<f64> {
        let mut full = self.base.clone();
        for (p, v) in self.free.iter().zip(free_values) {
            if p.applies_to(&self.experiment) {
                full[p.index] = *v;
            }
        }
        full
    }

    /// Every experiment: the first (from the campaign's own fields), then the others.
    pub fn experiments(&self) -> Vec<Experiment> {
        let first = Experiment {
            name: self.experiment.clone(),
            measurement_file: self.measurement_file.clone(),
            time_column: self.time_column.clone(),
            outputs: self.outputs.clone(),
            inputs: self.inputs.clone(),
            window: self.window,
            windows: self.windows.clone(),
            stop_time: self.stop_time,
            base: self.base.clone(),
        };
        std::iter::once(first)
            .chain(self.more.iter().cloned())
            .collect()
    }
}

/// Stop a run once its best objective has not fallen by more than `relative` (of itself)
/// over the last `window` evaluations: the objective has stopped moving, and the rest of
/// the budget would buy nothing a report can see (the optimisers' budget applies it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stall {
    pub window: u64,
    pub relative: f64,
}
