//! Campaign files: what to calibrate, against which data, how.
//!
//! A campaign is written in TOML (unknown keys are rejected) and resolved against the hosted
//! models before anything runs, so every mistake is reported up front with the file, the
//! line and the field. See docs/campaigns.md for the format.

mod file;
mod resolve;
mod user_effects;

use calib_worker::content_hash::ContentHasher;
pub use calib_worker::inputs::Interpolation;
use calib_worker::{Model, SolverOptions};
pub use file::default_methods;
pub use resolve::MAX_EXPERIMENTS;
use resolve::{resolve, Locator};
use serde::Deserialize;
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
    /// Smallest population of CMA-ES (`cma_population`); its default `4 + ⌊3 ln n⌋` when
    /// larger or unset.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub cma_population: Option<usize>,
    /// Further start points (physical values of the free parameters), tried after the
    /// nominal point; set by diagnosis, not by campaign files.
    pub extra_starts: Vec<Vec<f64>>,
    /// Stop each run once its objective stops moving; set by diagnosis for its refits,
    /// not by campaign files.
    #[serde(skip)]
    pub stall: Option<crate::optim::budget::Stall>,
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
        let file: file::CampaignFile = toml::from_str(text).map_err(|e| CampaignError {
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

    /// A hash of the resolved campaign run on the measurement with content hash
    /// `measurement_hash`: name, model and version, parameters (fixed and free, with bounds
    /// and nominal values), outputs and weights, window, horizon, search and solver
    /// settings. Two campaigns with the same identity compute the same result; the file's
    /// formatting, comments and location do not count.
    pub fn identity(&self, measurement_hash: &[u8; 32]) -> [u8; 32] {
        let info = self.model.info();
        let mut h = ContentHasher::new(b"calib.campaign.v1\0");
        h.text(&self.name)
            .text(&info.name)
            .bytes(&info.version.to_le_bytes())
            .series(&self.base)
            .series(&[self.stop_time, self.window.0, self.window.1])
            .count(self.free.len());
        for p in &self.free {
            h.count(p.index).series(&[p.nominal, p.min, p.max]);
        }
        h.bytes(measurement_hash).count(self.outputs.len());
        for o in &self.outputs {
            h.count(o.model_index)
                .text(&o.measured)
                .series(&[o.weight])
                .text(o.scale.name());
        }
        // Inputs, when mapped, change what is simulated; a campaign without them keeps the
        // identity it always had. So do several windows, experiments and parameters free in
        // one experiment alone.
        hash_inputs(&mut h, &self.inputs);
        calib_worker::user_effects::hash_into(&mut h, self.model.user_effects());
        if self.windows.len() > 1 {
            h.text("windows").count(self.windows.len());
            for w in &self.windows {
                h.series(&[w.0, w.1]);
            }
        }
        if !self.more.is_empty() || !self.experiment.is_empty() {
            h.text("experiments")
                .text(&self.experiment)
                .count(self.more.len());
            for e in &self.more {
                h.text(&e.name)
                    .text(&e.measurement_file.to_string_lossy())
                    .text(&e.time_column)
                    .series(&e.base)
                    .series(&[e.stop_time])
                    .count(e.windows.len());
                for w in &e.windows {
                    h.series(&[w.0, w.1]);
                }
                h.count(e.outputs.len());
                for o in &e.outputs {
                    h.count(o.model_index)
                        .text(&o.measured)
                        .series(&[o.weight])
                        .text(o.scale.name());
                }
                h.count(e.inputs.len());
                hash_inputs(&mut h, &e.inputs);
            }
            for p in &self.free {
                h.text(p.experiment.as_deref().unwrap_or(""));
            }
        }
        h.count(self.search.methods.len());
        for m in &self.search.methods {
            h.text(m.name());
        }
        h.count(self.search.starts)
            .count(self.search.max_evaluations)
            .bytes(&self.search.seed.to_le_bytes())
            .count(self.search.extra_starts.len());
        for start in &self.search.extra_starts {
            h.series(start);
        }
        h.series(&[self.solver.rtol, self.solver.atol])
            .count(self.solver.max_steps);
        // The start and the communication step, when set, change what is simulated; a
        // run without them keeps the fingerprint it always had.
        if self.solver.start_time != 0.0 || self.solver.communication_step.is_some() {
            h.text("time settings").series(&[
                self.solver.start_time,
                self.solver.communication_step.unwrap_or(0.0),
            ]);
        }
        h.finish()
    }
}

fn hash_inputs(h: &mut ContentHasher, inputs: &[InputMapping]) {
    if !inputs.is_empty() {
        h.text("inputs").count(inputs.len());
        for i in inputs {
            h.count(i.model_index)
                .text(&i.measured)
                .text(i.interpolation.as_str());
        }
    }
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
        let lm = parse(&GOOD.replacen("\"powell\"", "\"levenberg-marquardt\"", 1)).unwrap();
        assert_eq!(
            lm.search.methods,
            vec![Method::NelderMead, Method::LevenbergMarquardt]
        );
    }

    #[test]
    fn cma_es_and_its_population_are_accepted_and_a_wrong_method_lists_it() {
        let text = GOOD.replace(
            "methods = [\"nelder-mead\", \"powell\"]",
            "methods = [\"cma-es\"]\ncma_population = 32",
        );
        let c = parse(&text).unwrap();
        assert_eq!(c.search.methods, vec![Method::CmaEs]);
        assert_eq!(c.search.cma_population, Some(32));
        assert_eq!(Method::CmaEs.name(), "cma-es");
        let e = error_for("\"powell\"]", "\"cma\"]");
        assert!(e.message.contains("`cma-es`"), "{e}");
        let e = error_for("seed = 7", "seed = 7\ncma_population = 1");
        assert_eq!(e.field, "search.cma_population", "{e}");
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
        // The error lists the methods there are.
        assert!(e.message.contains("`levenberg-marquardt`"), "{e}");

        let e = error_for("theta0 = 0.5235987755983", "theta1 = 0.5");
        assert!(e.message.contains("no parameter `theta1`"), "{e}");

        let e = error_for("start = 0.0\nstop = 40.0", "start = 10.0\nstop = 5.0");
        assert_eq!(e.field, "window");
    }

    #[test]
    fn solver_options_are_held_to_the_workers_limits() {
        let with = |solver: &str| format!("{GOOD}[solver]\n{solver}\n");
        let solver_line = GOOD.lines().count() + 1;
        let c = parse(&with("max_steps = 10000000\nrtol = 1e-6")).unwrap();
        assert_eq!((c.solver.max_steps, c.solver.rtol), (10_000_000, 1e-6));
        for (lines, field) in [
            ("max_steps = 10000001", "solver.max_steps"),
            ("max_steps = 0", "solver.max_steps"),
            ("rtol = 0.5", "solver.rtol"),
            ("atol = 0.0", "solver.atol"),
        ] {
            let e = parse(&with(lines)).unwrap_err();
            assert_eq!(e.field, field, "{lines}: {e}");
            assert!(
                e.line.is_some_and(|l| l >= solver_line),
                "{lines}: {e} (the [solver] table is on line {solver_line})"
            );
        }
    }

    #[test]
    fn a_start_time_and_a_communication_step_apply_to_fmus_only() {
        let c = parse(GOOD).unwrap();
        assert_eq!(
            (c.solver.start_time, c.solver.communication_step),
            (0.0, None)
        );
        for (setting, field) in [
            ("start_time = 1.0", "model.start_time"),
            ("start_time = -1.0", "model.start_time"),
            ("step = 0.001", "model.step"),
        ] {
            let e = error_for("stop_time = 40.0", &format!("stop_time = 40.0\n{setting}"));
            assert_eq!(e.field, field, "{setting}: {e}");
            assert_eq!(e.line, Some(6), "{setting}: {e}");
        }
        let e = error_for("stop_time = 40.0", "stop_time = 40.0\nstep = 0.001");
        assert!(e.message.contains("Co-Simulation FMU"), "{e}");
        // A start of 0 is every model's.
        let c = parse(&GOOD.replacen("stop_time = 40.0", "stop_time = 40.0\nstart_time = 0.0", 1))
            .unwrap();
        assert_eq!(c.solver.start_time, 0.0);
    }

    #[test]
    fn numbers_that_size_memory_are_held_to_the_limits_naming_the_field() {
        let search_line = GOOD.lines().position(|l| l == "[search]").unwrap() + 1;
        for (from, to, field, limit) in [
            ("starts = 3", "starts = 1000000000", "search.starts", "1000"),
            ("starts = 3", "starts = 1001", "search.starts", "1000"),
            (
                "seed = 7",
                "seed = 7\nscreening = 1000000000000",
                "search.screening",
                "65535",
            ),
            (
                "max_evaluations = 300",
                "max_evaluations = 1000001",
                "search.max_evaluations",
                "1000000",
            ),
        ] {
            let e = error_for(from, to);
            assert_eq!(e.field, field, "{e}");
            assert!(e.message.contains(limit), "{e}");
            assert!(e.line.is_some_and(|l| l >= search_line), "{e}");
        }
        let c = parse(&GOOD.replacen("starts = 3", "starts = 1000", 1)).unwrap();
        assert_eq!(c.search.starts, crate::limits::MAX_STARTS);

        let output = "[[outputs]]\nmodel = \"armJoint.phi\"\nmeasured = \"a\"\n";
        let e = parse(&format!("{GOOD}{}", output.repeat(32))).unwrap_err();
        assert_eq!(e.field, "outputs", "{e}");
        assert!(e.message.contains("33 is more than the 32"), "{e}");
        let parameter = "[[parameters]]\nname = \"armFriction\"\nmin = 0.0\nmax = 0.9\n";
        let e = parse(&format!("{GOOD}{}", parameter.repeat(64))).unwrap_err();
        assert_eq!(e.field, "parameters", "{e}");
        assert!(e.message.contains("65 is more than the 64"), "{e}");
        let e = parse(&format!("{GOOD}[diagnosis]\nrefit = 11\n")).unwrap_err();
        assert_eq!(e.field, "diagnosis.refit", "{e}");
    }

    #[test]
    fn a_name_that_is_not_one_folder_name_is_refused() {
        for name in ["../../x", "/abs/x", "a/b", "..", ".calib-db", "a\\b"] {
            let e = error_for("name = \"clean\"", &format!("name = \"{name}\""));
            assert_eq!((e.field.as_str(), e.line), ("name", Some(2)), "{name}: {e}");
        }
        let long = "n".repeat(1_000_000);
        let e = error_for("name = \"clean\"", &format!("name = \"{long}\""));
        assert_eq!(e.field, "name");
        assert!(e.to_string().len() < 1000, "the name is echoed whole");
        // A file's stem names a campaign that names none, under the same rule.
        let unnamed = GOOD.replacen("name = \"clean\"\n", "", 1);
        let c = Campaign::parse(&unnamed, Path::new("/campaigns/rig 2.toml")).unwrap();
        assert_eq!(c.name, "rig 2");
        let e = Campaign::parse(&unnamed, Path::new("/campaigns/.hidden.toml")).unwrap_err();
        assert_eq!(e.field, "name", "{e}");
    }

    #[test]
    fn unknown_names_suggest_the_nearest() {
        let e = error_for("name = \"armFriction\"", "name = \"armfriction\"");
        assert!(e.message.ends_with("did you mean `armFriction`?"), "{e}");
        assert!(!e.message.contains("pend_Izz"), "{e}");
        let e = error_for("model = \"armJoint.phi\"", "model = \"armJoint.ph\"");
        assert!(e.message.ends_with("did you mean `armJoint.phi`?"), "{e}");
        let e = error_for("name = \"furuta\"", "name = \"furtua\"");
        assert!(e.message.ends_with("did you mean `furuta`?"), "{e}");
        assert_eq!(e.line, Some(4));
    }

    #[test]
    fn inputs_are_resolved_against_the_model() {
        let input = "[[inputs]]\nmodel = \"armTorque\"\nmeasured = \"u\"\n";
        let c = parse(&format!("{GOOD}{input}")).unwrap();
        assert_eq!(c.inputs[0].model_index, 0);
        assert_eq!(c.inputs[0].interpolation, Interpolation::Linear);
        assert_ne!(
            c.identity(&[0; 32]),
            parse(GOOD).unwrap().identity(&[0; 32])
        );
        let held = parse(&format!("{GOOD}{input}interpolation = \"hold\"\n")).unwrap();
        assert_eq!(held.inputs[0].interpolation, Interpolation::Hold);
        assert_ne!(held.identity(&[0; 32]), c.identity(&[0; 32]));

        let line = GOOD.lines().count() + 2;
        let e = parse(&format!("{GOOD}{}", input.replace("armTorque", "armTorqe"))).unwrap_err();
        assert_eq!(e.field, "inputs[0] (armTorqe)");
        assert_eq!(e.line, Some(line), "{e}");
        assert!(e.message.ends_with("did you mean `armTorque`?"), "{e}");
        let e = parse(&format!("{GOOD}{input}interpolation = \"cubic\"\n")).unwrap_err();
        assert!(e.message.contains("unknown interpolation `cubic`"), "{e}");
        let e = parse(&format!("{GOOD}{input}{input}")).unwrap_err();
        assert!(e.message.contains("driven twice"), "{e}");
    }

    const EXPERIMENTS: &str = r#"
name = "two"
[model]
name = "furuta"
[[outputs]]
model = "armJoint.phi"
measured = "arm"
[[parameters]]
name = "armFriction"
min = 0.0
max = 0.9
[[experiments]]
name = "swing"
file = "swing.csv"
window = { start = 0.0, stop = 20.0 }
fixed = { theta0 = 0.5 }
[[experiments]]
name = "driven"
file = "/data/driven.csv"
time_column = "t"
windows = [[0.0, 1.0], [2.0, 10.0]]
inputs = [ { model = "armTorque", measured = "u" } ]
[[experiments.parameters]]
name = "theta0"
nominal = 1.0
min = 0.0
max = 3.2
"#;

    #[test]
    fn experiments_share_the_free_parameters_and_keep_their_own() {
        let c = parse(EXPERIMENTS).unwrap();
        assert_eq!(c.experiment, "swing");
        assert_eq!(c.measurement_file, Path::new("/campaigns/swing.csv"));
        assert_eq!(c.windows, vec![(0.0, 20.0)]);
        let theta0 = c.model.info().parameter_index("theta0").unwrap();
        assert_eq!(c.base[theta0], 0.5);
        assert!(c.inputs.is_empty());
        let driven = &c.more[0];
        assert_eq!(driven.name, "driven");
        assert_eq!(driven.windows, vec![(0.0, 1.0), (2.0, 10.0)]);
        assert_eq!(driven.window, (0.0, 10.0));
        assert_eq!(driven.inputs[0].measured, "u");
        assert_eq!(driven.outputs[0].measured, "arm");
        assert_eq!(driven.base[theta0], 1.0);
        let names: Vec<&str> = c.free.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names, ["armFriction", "theta0@driven"]);
        // The first experiment's vector leaves the other's own parameter alone.
        assert_eq!(c.full_parameters(&[0.1, 2.0])[theta0], 0.5);

        for (from, to, field) in [
            (
                "name = \"driven\"",
                "name = \"swing\"",
                "experiments[1] (swing)",
            ),
            (
                "name = \"theta0\"\nnominal = 1.0\nmin = 0.0\nmax = 3.2",
                "name = \"armFriction\"\nmin = 0.0\nmax = 0.5",
                "experiments[1] (driven).parameters[0] (armFriction)",
            ),
            (
                "nominal = 1.0",
                "nominal = 5.0",
                "experiments[1] (driven).parameters[0] (theta0)",
            ),
            (
                "[2.0, 10.0]]",
                "[0.5, 10.0]]",
                "experiments[1] (driven).windows[1]",
            ),
            (
                "theta0 = 0.5",
                "thetaO = 0.5",
                "experiments[0] (swing).fixed.thetaO",
            ),
            (
                "model = \"armTorque\"",
                "model = \"armTorq\"",
                "experiments[1] (driven).inputs[0] (armTorq)",
            ),
        ] {
            let e = parse(&EXPERIMENTS.replacen(from, to, 1)).unwrap_err();
            assert_eq!(e.field, field, "{to}: {e}");
            assert!(e.line.is_some(), "{e}");
        }
        let both = format!("{EXPERIMENTS}[measurement]\nfile = \"m.csv\"\n");
        let e = parse(&both).unwrap_err();
        assert!(e.message.contains("not both"), "{e}");
    }

    #[test]
    fn disjoint_windows_in_the_one_record_form() {
        let c = parse(
            &GOOD
                .replacen("[window]\nstart = 0.0\nstop = 40.0", "", 1)
                .replacen(
                    "name = \"clean\"",
                    "name = \"clean\"\nwindows = [[0.0, 5.0], [10.0, 40.0]]",
                    1,
                ),
        )
        .unwrap();
        assert_eq!(c.windows, vec![(0.0, 5.0), (10.0, 40.0)]);
        assert_eq!(c.window, (0.0, 40.0));
        assert_ne!(
            c.identity(&[0; 32]),
            parse(GOOD).unwrap().identity(&[0; 32])
        );
    }

    /// A client's campaign cannot make the objective test each sample against a million
    /// intervals, nor an experiment compare more outputs than a campaign may.
    #[test]
    fn windows_and_an_experiments_outputs_are_bounded() {
        let windows: Vec<String> = (0..=crate::limits::MAX_WINDOWS)
            .map(|k| format!("[{}.0, {}.5]", k, k))
            .collect();
        let text = GOOD
            .replacen("[window]\nstart = 0.0\nstop = 40.0", "", 1)
            .replacen(
                "name = \"clean\"",
                &format!("name = \"clean\"\nwindows = [{}]", windows.join(", ")),
                1,
            );
        let e = parse(&text).unwrap_err();
        assert_eq!(e.field, "windows", "{e}");
        assert!(e.message.contains("1001 is more than the 1000"), "{e}");
        let output = "{ model = \"armJoint.phi\", measured = \"arm\" }";
        let outputs = vec![output; crate::limits::MAX_OUTPUTS + 1].join(", ");
        let text = EXPERIMENTS.replacen(
            "inputs = [",
            &format!("outputs = [{outputs}]\ninputs = ["),
            1,
        );
        let e = parse(&text).unwrap_err();
        assert_eq!(e.field, "experiments[1] (driven).outputs", "{e}");
        assert!(e.message.contains("33 is more than the 32"), "{e}");
    }

    #[test]
    fn output_weights_sigmas_and_scales() {
        let with = |lines: &str| GOOD.replacen("weight = 1.0", lines, 1);
        let c = parse(&with("sigma = 0.5")).unwrap();
        assert_eq!(c.outputs[0].weight, 4.0);
        assert_eq!(c.outputs[0].scale, OutputScale::None);
        let c = parse(&with("weight = 2.0\nscale = \"variance\"")).unwrap();
        assert_eq!(c.outputs[0].weight, 2.0);
        assert_eq!(c.outputs[0].scale, OutputScale::Variance);
        let c = parse(&with("")).unwrap();
        assert_eq!(c.outputs[0].weight, 1.0);
        assert_ne!(
            parse(&with("scale = \"variance\""))
                .unwrap()
                .identity(&[0; 32]),
            parse(&with("")).unwrap().identity(&[0; 32])
        );

        for (lines, message) in [
            ("sigma = 0.0", "sigma 0 must be a finite number > 0"),
            ("sigma = -2.0", "sigma -2 must be a finite number > 0"),
            ("sigma = 1e-200", "must be a finite number > 0"),
            ("weight = 1.0\nsigma = 2.0", "not both"),
            (
                "sigma = 2.0\nscale = \"variance\"",
                "cannot be combined with `sigma`",
            ),
            ("scale = \"range\"", "unknown scale `range`"),
            ("weight = -1.0", "weight -1 must be"),
        ] {
            let e = parse(&with(lines)).unwrap_err();
            assert!(e.message.contains(message), "{lines}: {e}");
            assert_eq!(e.field, "outputs[0] (armJoint.phi)", "{lines}");
            // The offending key is on line 16 or 17 of the file.
            assert!(matches!(e.line, Some(16 | 17)), "{lines}: {e}");
        }
    }
}
