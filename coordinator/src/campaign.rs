//! Campaign files: what to calibrate, against which data, how.
//!
//! A campaign is written in TOML (unknown keys are rejected) and resolved against the hosted
//! models before anything runs, so every mistake is reported up front with the file, the
//! line and the field. See README.md for the format.

use calib_worker::{models, Model, SolverOptions};
use serde::Deserialize;
use std::fmt;
use std::path::{Path, PathBuf};
use toml::Spanned;

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
}

impl Method {
    pub fn name(self) -> &'static str {
        match self {
            Method::NelderMead => "nelder-mead",
            Method::Powell => "powell",
            Method::DifferentialEvolution => "differential-evolution",
        }
    }
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

// ---- the file as written ----

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CampaignFile {
    name: Option<String>,
    model: Spanned<ModelSection>,
    measurement: MeasurementSection,
    #[serde(default)]
    outputs: Vec<Spanned<OutputEntry>>,
    #[serde(default)]
    parameters: Vec<Spanned<ParameterEntry>>,
    #[serde(default)]
    effects: Vec<Spanned<ParameterEntry>>,
    #[serde(default)]
    diagnosis: Option<Spanned<DiagnosisSection>>,
    window: Option<Spanned<WindowSection>>,
    #[serde(default)]
    search: Option<Spanned<SearchSection>>,
    #[serde(default)]
    solver: Option<Spanned<SolverSection>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelSection {
    name: Spanned<String>,
    stop_time: Option<Spanned<f64>>,
    #[serde(default)]
    parameters: std::collections::BTreeMap<Spanned<String>, Spanned<f64>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct MeasurementSection {
    file: Spanned<String>,
    #[serde(default = "default_time_column")]
    time_column: String,
}

fn default_time_column() -> String {
    "time".into()
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct OutputEntry {
    model: Spanned<String>,
    measured: String,
    #[serde(default = "one")]
    weight: f64,
}

fn one() -> f64 {
    1.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct ParameterEntry {
    name: Spanned<String>,
    nominal: Option<f64>,
    min: f64,
    max: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DiagnosisSection {
    holdout_start: Option<f64>,
    holdout_stop: Option<f64>,
    refit: Option<usize>,
    candidates: Option<Vec<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct WindowSection {
    start: f64,
    stop: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SearchSection {
    #[serde(default = "default_methods")]
    methods: Vec<Method>,
    #[serde(default = "default_starts")]
    starts: usize,
    #[serde(default = "default_max_evaluations")]
    max_evaluations: usize,
    #[serde(default)]
    seed: u64,
}

fn default_methods() -> Vec<Method> {
    vec![Method::NelderMead]
}
fn default_starts() -> usize {
    1
}
fn default_max_evaluations() -> usize {
    1000
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct SolverSection {
    rtol: Option<f64>,
    atol: Option<f64>,
    max_steps: Option<usize>,
}

// ---- the campaign as resolved ----

/// A parameter the optimisers search over.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct FreeParameter {
    pub name: String,
    /// Position in the model's full parameter vector.
    pub index: usize,
    pub nominal: f64,
    pub min: f64,
    pub max: f64,
    /// Whether this is one of the model's effects (absent at 0) rather than a base parameter.
    pub effect: bool,
}

/// A model output compared with a measured column.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct OutputMapping {
    pub model: String,
    pub model_index: usize,
    pub measured: String,
    pub weight: f64,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Search {
    pub methods: Vec<Method>,
    /// Start points per method: the nominal point, then seeded quasi-random points.
    pub starts: usize,
    /// Evaluation budget of each run (one method from one start).
    pub max_evaluations: usize,
    pub seed: u64,
    /// Further start points (physical values of the free parameters), tried after the
    /// nominal point; set by diagnosis, not by campaign files.
    pub extra_starts: Vec<Vec<f64>>,
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
    pub window: (f64, f64),
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
            .field("window", &self.window)
            .field("search", &self.search)
            .finish()
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
        let locate = Locator { text, path };
        let file: CampaignFile = toml::from_str(text).map_err(|e| CampaignError {
            file: path.to_path_buf(),
            line: e.span().map(|s| locate.line(s.start)),
            field: String::new(),
            message: e.message().trim().to_string(),
        })?;
        resolve(file, &locate)
    }

    /// Nominal values of the free parameters.
    pub fn nominal(&self) -> Vec<f64> {
        self.free.iter().map(|p| p.nominal).collect()
    }

    /// The full parameter vector with the free parameters set to `free_values`.
    pub fn full_parameters(&self, free_values: &[f64]) -> Vec<f64> {
        let mut full = self.base.clone();
        for (p, v) in self.free.iter().zip(free_values) {
            full[p.index] = *v;
        }
        full
    }

    /// A hash of the resolved campaign run on the measurement with content hash
    /// `measurement_hash`: name, model and version, parameters (fixed and free, with bounds
    /// and nominal values), outputs and weights, window, horizon, search and solver
    /// settings. Two campaigns with the same identity compute the same result; the file's
    /// formatting, comments and location do not count.
    pub fn identity(&self, measurement_hash: &[u8; 32]) -> [u8; 32] {
        let info = self.model.info();
        let mut h = blake3::Hasher::new();
        h.update(b"calib.campaign.v1\0");
        let text = |h: &mut blake3::Hasher, s: &str| {
            h.update(&(s.len() as u64).to_le_bytes());
            h.update(s.as_bytes());
        };
        let f64s = |h: &mut blake3::Hasher, v: &[f64]| {
            h.update(&(v.len() as u64).to_le_bytes());
            for x in v {
                h.update(&x.to_bits().to_le_bytes());
            }
        };
        let count = |h: &mut blake3::Hasher, n: usize| {
            h.update(&(n as u64).to_le_bytes());
        };
        text(&mut h, &self.name);
        text(&mut h, &info.name);
        h.update(&info.version.to_le_bytes());
        f64s(&mut h, &self.base);
        f64s(&mut h, &[self.stop_time, self.window.0, self.window.1]);
        count(&mut h, self.free.len());
        for p in &self.free {
            count(&mut h, p.index);
            f64s(&mut h, &[p.nominal, p.min, p.max]);
        }
        h.update(measurement_hash);
        count(&mut h, self.outputs.len());
        for o in &self.outputs {
            count(&mut h, o.model_index);
            text(&mut h, &o.measured);
            f64s(&mut h, &[o.weight]);
        }
        count(&mut h, self.search.methods.len());
        for m in &self.search.methods {
            text(&mut h, m.name());
        }
        count(&mut h, self.search.starts);
        count(&mut h, self.search.max_evaluations);
        h.update(&self.search.seed.to_le_bytes());
        count(&mut h, self.search.extra_starts.len());
        for start in &self.search.extra_starts {
            f64s(&mut h, start);
        }
        f64s(&mut h, &[self.solver.rtol, self.solver.atol]);
        count(&mut h, self.solver.max_steps);
        *h.finalize().as_bytes()
    }
}

struct Locator<'a> {
    text: &'a str,
    path: &'a Path,
}

impl Locator<'_> {
    fn line(&self, offset: usize) -> usize {
        let end = offset.min(self.text.len());
        self.text.as_bytes()[..end]
            .iter()
            .filter(|b| **b == b'\n')
            .count()
            + 1
    }

    fn error<T>(
        &self,
        span: std::ops::Range<usize>,
        field: &str,
        message: String,
    ) -> Result<T, CampaignError> {
        Err(CampaignError {
            file: self.path.to_path_buf(),
            line: Some(self.line(span.start)),
            field: field.to_string(),
            message,
        })
    }
}

fn resolve(file: CampaignFile, at: &Locator) -> Result<Campaign, CampaignError> {
    let model_span = file.model.span();
    let model_section = file.model.into_inner();
    let model_name = model_section.name.get_ref();
    let Some(model) = models::find(model_name) else {
        let known: Vec<_> = models::all()
            .iter()
            .map(|m| m.info().name.clone())
            .collect();
        return at.error(
            model_section.name.span(),
            "model.name",
            format!(
                "unknown model `{model_name}` (hosted: {})",
                known.join(", ")
            ),
        );
    };
    let info = model.info();
    let known_parameters = || {
        let mut names: Vec<&str> = info.parameters.iter().map(|p| p.name.as_str()).collect();
        names.extend(info.effects.iter().map(|e| e.name.as_str()));
        names.join(", ")
    };

    // Fixed overrides.
    let mut base = info.default_vector();
    let mut fixed = Vec::new();
    for (name, value) in &model_section.parameters {
        let field = format!("model.parameters.{}", name.get_ref());
        let Some(index) = info.parameter_index(name.get_ref()) else {
            return at.error(
                name.span(),
                &field,
                format!(
                    "model `{}` has no parameter `{}` (it has: {})",
                    info.name,
                    name.get_ref(),
                    known_parameters()
                ),
            );
        };
        let v = *value.get_ref();
        let (lo, hi) = info.bounds_at(index);
        if !v.is_finite() || v < lo || v > hi {
            return at.error(
                value.span(),
                &field,
                format!("value {v} is outside the admissible range [{lo}, {hi}]"),
            );
        }
        base[index] = v;
        fixed.push(index);
    }

    // Free parameters, then free effects.
    let mut free: Vec<FreeParameter> = Vec::new();
    let sections = [("parameters", &file.parameters), ("effects", &file.effects)];
    for (section, entry, i) in sections.iter().flat_map(|(section, entries)| {
        entries
            .iter()
            .enumerate()
            .map(move |(i, e)| (*section, e, i))
    }) {
        let is_effect = section == "effects";
        let span = entry.span();
        let p = entry.get_ref();
        let name = p.name.get_ref();
        let field = format!("{section}[{i}] ({name})");
        if is_effect && info.effect(name).is_none() {
            let effects: Vec<&str> = info.effects.iter().map(|e| e.name.as_str()).collect();
            return at.error(
                p.name.span(),
                &field,
                format!(
                    "model `{}` has no effect `{name}` (it has: {})",
                    info.name,
                    effects.join(", ")
                ),
            );
        }
        let Some(index) = info.parameter_index(name) else {
            return at.error(
                p.name.span(),
                &field,
                format!(
                    "model `{}` has no parameter `{name}` (it has: {})",
                    info.name,
                    known_parameters()
                ),
            );
        };
        if free.iter().any(|f| f.index == index) {
            return at.error(span, &field, "is listed twice".into());
        }
        if fixed.contains(&index) {
            return at.error(
                span,
                &field,
                "is both fixed in [model.parameters] and free here".into(),
            );
        }
        if !p.min.is_finite() || !p.max.is_finite() {
            return at.error(span, &field, "min and max must be finite numbers".into());
        }
        if p.min >= p.max {
            return at.error(
                span,
                &field,
                format!("min ({}) must be below max ({})", p.min, p.max),
            );
        }
        let (lo, hi) = info.bounds_at(index);
        if p.min < lo || p.max > hi {
            return at.error(
                span,
                &field,
                format!(
                    "bounds [{}, {}] exceed the model's admissible range [{lo}, {hi}]",
                    p.min, p.max
                ),
            );
        }
        let nominal = p
            .nominal
            .unwrap_or(if is_effect { 0.0 } else { base[index] });
        if !nominal.is_finite() || nominal < p.min || nominal > p.max {
            return at.error(
                span,
                &field,
                format!(
                    "nominal {nominal} is outside its bounds [{}, {}]",
                    p.min, p.max
                ),
            );
        }
        base[index] = nominal;
        free.push(FreeParameter {
            name: name.clone(),
            index,
            nominal,
            min: p.min,
            max: p.max,
            effect: is_effect,
        });
    }
    if free.is_empty() {
        return Err(CampaignError {
            file: at.path.to_path_buf(),
            line: None,
            field: "parameters".into(),
            message: "nothing to calibrate: add at least one [[parameters]] or [[effects]] entry"
                .into(),
        });
    }

    // Outputs.
    if file.outputs.is_empty() {
        return Err(CampaignError {
            file: at.path.to_path_buf(),
            line: None,
            field: "outputs".into(),
            message: "no output to compare: add at least one [[outputs]] entry".into(),
        });
    }
    let mut outputs = Vec::new();
    for (i, entry) in file.outputs.iter().enumerate() {
        let o = entry.get_ref();
        let output = o.model.get_ref();
        let field = format!("outputs[{i}] ({output})");
        let Some(model_index) = info.output_index(output) else {
            let known: Vec<_> = info.outputs.iter().map(|o| o.name.as_str()).collect();
            return at.error(
                o.model.span(),
                &field,
                format!(
                    "model `{}` has no output `{output}` (it has: {})",
                    info.name,
                    known.join(", ")
                ),
            );
        };
        if !o.weight.is_finite() || o.weight < 0.0 {
            return at.error(
                entry.span(),
                &field,
                format!("weight {} must be a finite number ≥ 0", o.weight),
            );
        }
        outputs.push(OutputMapping {
            model: output.clone(),
            model_index,
            measured: o.measured.clone(),
            weight: o.weight,
        });
    }

    // Window and horizon.
    let Some(window) = file.window else {
        return Err(CampaignError {
            file: at.path.to_path_buf(),
            line: None,
            field: "window".into(),
            message: "missing [window] with `start` and `stop` (seconds)".into(),
        });
    };
    let (start, stop) = (window.get_ref().start, window.get_ref().stop);
    if !start.is_finite() || !stop.is_finite() || start < 0.0 || start >= stop {
        return at.error(
            window.span(),
            "window",
            format!("start ({start}) must be ≥ 0 and below stop ({stop})"),
        );
    }
    let stop_time = match &model_section.stop_time {
        Some(t) => {
            let v = *t.get_ref();
            if !v.is_finite() || v < stop {
                return at.error(
                    t.span(),
                    "model.stop_time",
                    format!("{v} must be ≥ the window's stop ({stop})"),
                );
            }
            v
        }
        None => stop,
    };
    if stop_time > 1e6 {
        return at.error(
            model_span,
            "model.stop_time",
            format!("{stop_time} s is beyond what calib simulates (1e6 s)"),
        );
    }

    // Search.
    let search = match file.search {
        None => Search {
            methods: default_methods(),
            starts: default_starts(),
            max_evaluations: default_max_evaluations(),
            seed: 0,
            extra_starts: Vec::new(),
        },
        Some(s) => {
            let span = s.span();
            let s = s.into_inner();
            if s.methods.is_empty() {
                return at.error(span, "search.methods", "name at least one method".into());
            }
            if s.starts == 0 {
                return at.error(span, "search.starts", "must be at least 1".into());
            }
            if s.max_evaluations < 2 * (free.len() + 1) {
                return at.error(
                    span,
                    "search.max_evaluations",
                    format!(
                        "{} is too few for {} parameters",
                        s.max_evaluations,
                        free.len()
                    ),
                );
            }
            let mut methods = s.methods;
            let mut seen = Vec::new();
            methods.retain(|m| {
                let first = !seen.contains(m);
                seen.push(*m);
                first
            });
            Search {
                methods,
                starts: s.starts,
                max_evaluations: s.max_evaluations,
                seed: s.seed,
                extra_starts: Vec::new(),
            }
        }
    };

    let mut solver = model.default_options();
    if let Some(s) = file.solver {
        let span = s.span();
        let s = s.into_inner();
        if let Some(rtol) = s.rtol {
            if !(rtol > 0.0 && rtol < 1.0) {
                return at.error(span, "solver.rtol", format!("{rtol} must be in (0, 1)"));
            }
            solver.rtol = rtol;
        }
        if let Some(atol) = s.atol {
            if !(atol > 0.0 && atol.is_finite()) {
                return at.error(span, "solver.atol", format!("{atol} must be > 0"));
            }
            solver.atol = atol;
        }
        if let Some(max_steps) = s.max_steps {
            if max_steps == 0 {
                return at.error(span, "solver.max_steps", "must be at least 1".into());
            }
            solver.max_steps = max_steps;
        }
    }

    let measurement_path = PathBuf::from(file.measurement.file.get_ref());
    let measurement_file = if measurement_path.is_absolute() {
        measurement_path
    } else {
        at.path
            .parent()
            .unwrap_or(Path::new("."))
            .join(measurement_path)
    };

    let mut diagnosis = DiagnosisSettings {
        holdout: None,
        refit: 3,
        candidates: None,
    };
    if let Some(d) = file.diagnosis {
        let span = d.span();
        let d = d.into_inner();
        match (d.holdout_start, d.holdout_stop) {
            (None, None) => {}
            (Some(a), Some(b)) if a.is_finite() && b.is_finite() && 0.0 <= a && a < b => {
                diagnosis.holdout = Some((a, b));
            }
            (Some(a), Some(b)) => {
                return at.error(
                    span,
                    "diagnosis.holdout_start",
                    format!("the held-out window [{a}, {b}] must have 0 ≤ start < stop"),
                );
            }
            _ => {
                return at.error(
                    span,
                    "diagnosis.holdout_start",
                    "give both holdout_start and holdout_stop, or neither".into(),
                );
            }
        }
        if let Some(refit) = d.refit {
            if refit == 0 {
                return at.error(span, "diagnosis.refit", "must be at least 1".into());
            }
            diagnosis.refit = refit;
        }
        if let Some(candidates) = d.candidates {
            if let Some(unknown) = candidates.iter().find(|c| info.effect(c).is_none()) {
                return at.error(
                    span,
                    "diagnosis.candidates",
                    format!("model `{}` has no effect `{unknown}`", info.name),
                );
            }
            diagnosis.candidates = Some(candidates);
        }
    }

    let name = file.name.unwrap_or_else(|| {
        at.path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_else(|| "campaign".into())
    });

    Ok(Campaign {
        name,
        source: Some(at.path.to_path_buf()),
        spec: at.text.to_string(),
        model,
        stop_time,
        base,
        free,
        measurement_file,
        time_column: file.measurement.time_column,
        outputs,
        window: (start, stop),
        search,
        solver,
        diagnosis,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
name = "clean"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
theta0 = 0.5235987755983

[measurement]
file = "data/furuta_clean.csv"
time_column = "time_s"

[[outputs]]
model = "armJoint.phi"
measured = "arm_angle_rad"
weight = 1.0

[[parameters]]
name = "armFriction"
nominal = 0.012
min = 0.0
max = 0.9

[window]
start = 0.0
stop = 40.0

[search]
methods = ["nelder-mead", "powell"]
starts = 3
max_evaluations = 300
seed = 7
"#;

    fn parse(text: &str) -> Result<Campaign, CampaignError> {
        Campaign::parse(text, Path::new("/campaigns/c.toml"))
    }

    #[test]
    fn a_good_campaign_resolves() {
        let c = parse(GOOD).unwrap();
        assert_eq!(c.name, "clean");
        assert_eq!(c.model.info().name, "furuta");
        assert_eq!(c.free[0].index, 0);
        assert_eq!(c.outputs[0].model_index, 0);
        assert_eq!(
            c.measurement_file,
            Path::new("/campaigns/data/furuta_clean.csv")
        );
        assert_eq!(c.search.methods, vec![Method::NelderMead, Method::Powell]);
        assert_eq!(c.window, (0.0, 40.0));
    }

    fn error_for(from: &str, to: &str) -> CampaignError {
        let text = GOOD.replacen(from, to, 1);
        assert_ne!(text, GOOD, "replacement `{from}` not found");
        parse(&text).unwrap_err()
    }

    #[test]
    fn mistakes_are_located() {
        let e = error_for("name = \"furuta\"", "name = \"furuta2\"");
        assert_eq!(e.line, Some(4));
        assert!(e.to_string().contains("unknown model `furuta2`"), "{e}");

        let e = error_for("name = \"armFriction\"", "name = \"armFrction\"");
        assert_eq!(e.line, Some(19), "{e}");
        assert!(e.message.contains("no parameter `armFrction`"), "{e}");

        let e = error_for("model = \"armJoint.phi\"", "model = \"arm.phi\"");
        assert!(e.message.contains("no output `arm.phi`"), "{e}");

        let e = error_for("nominal = 0.012", "nominal = 1.5");
        assert!(e.message.contains("outside its bounds"), "{e}");

        let e = error_for("min = 0.0\nmax = 0.9", "min = 0.5\nmax = 0.5");
        assert!(e.message.contains("must be below max"), "{e}");

        let e = error_for("seed = 7", "seed = 7\ncolour = 3");
        assert!(e.message.contains("unknown field `colour`"), "{e}");
        assert_eq!(e.line, Some(33), "{e}");

        let e = error_for("\"powell\"", "\"simplex\"");
        assert!(e.message.contains("simplex"), "{e}");

        let e = error_for("theta0 = 0.5235987755983", "theta1 = 0.5");
        assert!(e.message.contains("no parameter `theta1`"), "{e}");

        let e = error_for("start = 0.0\nstop = 40.0", "start = 10.0\nstop = 5.0");
        assert_eq!(e.field, "window");
    }
}
