//! The campaign message of the Calibration API and the one campaign type, both ways: the
//! coordinator converts a message into a [`CampaignSpec`], field by field, which the
//! campaign's one resolver checks; clients (`calib submit`) convert a campaign file's spec
//! into a message. No campaign text passes between the two.

use calib_engine::campaign::spec::{
    at, default_max_evaluations, default_methods, default_starts, CampaignSpec, DiagnosisSection,
    EffectEntry, ExperimentEntry, InputEntry, MeasurementSection, ModelSection, OutputEntry,
    ParameterEntry, SearchSection, SolverSection, Spanned, WindowSection,
};
use calib_engine::campaign::{Method, Scale};
use calib_proto::v1 as pb;
use serde::de::IntoDeserializer;
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The campaign of `c`, its measurement the dataset file `file` with its time in
/// `time_column`; or the field that cannot be converted ("campaign.<field>: <what>").
pub fn campaign_spec(
    c: &pb::Campaign,
    file: &Path,
    time_column: &str,
) -> Result<CampaignSpec, String> {
    let record = Record {
        file: file.to_path_buf(),
        time_column: time_column.to_string(),
    };
    campaign_spec_with(c, Some(&record), &[], None)
}

/// A dataset as a campaign names it: its file and time column.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub file: PathBuf,
    pub time_column: String,
}

/// The campaign of `c`: its one record `record` (the dataset `c.dataset_id` names), or, for
/// a campaign of several experiments, `experiments[k]` the record of `c.experiments[k]`;
/// its model the FMU archive at `fmu` when there is one (run through `c.fmu_interface`),
/// else the hosted model `c.model`.
pub fn campaign_spec_with(
    c: &pb::Campaign,
    record: Option<&Record>,
    experiments: &[Record],
    fmu: Option<&Path>,
) -> Result<CampaignSpec, String> {
    if experiments.len() != c.experiments.len() {
        return Err(format!(
            "campaign.experiments: {} experiments for {} records",
            c.experiments.len(),
            experiments.len()
        ));
    }
    let mut effects: Vec<_> = parameters(&c.effects, "effects")?
        .into_iter()
        .map(|p| at(builtin_effect(p.into_inner())))
        .collect();
    effects.extend(
        c.defined_effects
            .iter()
            .map(|e| at(super::defined_effects::entry(e))),
    );
    Ok(CampaignSpec {
        name: Some(c.name.clone()).filter(|n| !n.is_empty()).map(at),
        model: at(model_section(c, fmu)),
        measurement: record.map(|r| MeasurementSection {
            file: at(path_text(&r.file)),
            time_column: r.time_column.clone(),
        }),
        outputs: outputs(&c.outputs),
        inputs: inputs(&c.inputs),
        parameters: parameters(&c.parameters, "parameters")?,
        effects,
        diagnosis: c.diagnosis.as_ref().map(diagnosis_section).transpose()?,
        window: (c.window_start != 0.0 || c.window_stop != 0.0).then(|| {
            at(WindowSection {
                start: c.window_start,
                stop: c.window_stop,
            })
        }),
        windows: (!c.windows.is_empty()).then(|| windows(&c.windows)),
        experiments: c
            .experiments
            .iter()
            .zip(experiments)
            .enumerate()
            .map(|(k, (e, record))| experiment(k, e, record).map(at))
            .collect::<Result<_, _>>()?,
        search: c.search.as_ref().map(search_section).transpose()?,
        solver: (c.rtol.is_some() || c.atol.is_some() || c.max_steps.is_some())
            .then(|| solver_section(c))
            .transpose()?,
    })
}

/// The `[model]` section: a built-in model by name or an FMU archive, its times and fixed
/// values.
fn model_section(c: &pb::Campaign, fmu: Option<&Path>) -> ModelSection {
    let (name, fmu, interface) = match fmu {
        Some(path) => (
            None,
            Some(at(path_text(path))),
            Some(c.fmu_interface.clone())
                .filter(|i| !i.is_empty())
                .map(at),
        ),
        None => (Some(at(c.model.clone())), None, None),
    };
    ModelSection {
        name,
        fmu,
        interface,
        stop_time: Some(c.stop_time).filter(|t| *t != 0.0).map(at),
        start_time: Some(c.start_time).filter(|t| *t != 0.0).map(at),
        step: c.step.map(at),
        parameters: values(&c.model_parameters),
    }
}

fn path_text(path: &Path) -> String {
    path.to_string_lossy().into_owned()
}

/// A map of fixed values as the spec holds it.
fn values<'a>(
    map: impl IntoIterator<Item = (&'a String, &'a f64)>,
) -> BTreeMap<Spanned<String>, Spanned<f64>> {
    map.into_iter()
        .map(|(k, v)| (at(k.clone()), at(*v)))
        .collect()
}

/// The `[search]` section; a method, starts or budget the spec cannot hold is refused.
fn search_section(s: &pb::Search) -> Result<Spanned<SearchSection>, String> {
    // No method named is the file's default: the campaign's checks refuse it where a search
    // runs; an analysis, which runs none, takes the campaign as it is.
    let methods = if s.methods.is_empty() {
        default_methods()
    } else {
        s.methods
            .iter()
            .enumerate()
            .map(|(k, m)| named::<Method>(m, &format!("search.methods[{k}]")))
            .collect::<Result<_, _>>()?
    };
    Ok(at(SearchSection {
        methods,
        starts: match s.starts {
            Some(n) => integer("search.starts", n)?,
            None => default_starts(),
        },
        max_evaluations: match s.max_evaluations {
            Some(n) => integer("search.max_evaluations", n)?,
            None => default_max_evaluations(),
        },
        seed: integer::<u64>("search.seed", s.seed)?,
        screening: s
            .screening
            .map(|n| integer("search.screening", n))
            .transpose()?,
        cma_population: s
            .cma_population
            .map(|n| integer("search.cma_population", n))
            .transpose()?,
    }))
}

/// The `[solver]` section.
fn solver_section(c: &pb::Campaign) -> Result<Spanned<SolverSection>, String> {
    Ok(at(SolverSection {
        rtol: c.rtol,
        atol: c.atol,
        max_steps: c.max_steps.map(|n| integer("max_steps", n)).transpose()?,
    }))
}

/// The `[diagnosis]` section.
fn diagnosis_section(d: &pb::DiagnosisSettings) -> Result<Spanned<DiagnosisSection>, String> {
    Ok(at(DiagnosisSection {
        holdout_start: d.holdout_start,
        holdout_stop: d.holdout_stop,
        refit: d.refit.map(|n| integer("diagnosis.refit", n)).transpose()?,
        candidates: (!d.candidates.is_empty()).then(|| d.candidates.clone()),
    }))
}

/// Experiment `k`: its record, one `window` or several `windows`.
fn experiment(k: usize, e: &pb::Experiment, record: &Record) -> Result<ExperimentEntry, String> {
    let (window, windows) = match e.windows.as_slice() {
        // No interval: the campaign's check names the experiment's window missing.
        [] => (None, None),
        [w] => (
            Some(at(WindowSection {
                start: w.start,
                stop: w.stop,
            })),
            None,
        ),
        several => (None, Some(windows(several))),
    };
    Ok(ExperimentEntry {
        name: at(e.name.clone()),
        file: at(path_text(&record.file)),
        time_column: record.time_column.clone(),
        stop_time: Some(e.stop_time).filter(|t| *t != 0.0).map(at),
        window,
        windows,
        fixed: values(&e.fixed),
        inputs: inputs(&e.inputs),
        outputs: outputs(&e.outputs),
        parameters: parameters(&e.parameters, &format!("experiments[{k}].parameters"))?,
    })
}

fn windows(list: &[pb::Window]) -> Spanned<Vec<[f64; 2]>> {
    at(list.iter().map(|w| [w.start, w.stop]).collect())
}

fn outputs(list: &[pb::Output]) -> Vec<Spanned<OutputEntry>> {
    list.iter()
        .map(|o| {
            at(OutputEntry {
                model: at(o.model.clone()),
                measured: o.measured.clone(),
                weight: o.weight.map(at),
                sigma: o.sigma.map(at),
                scale: Some(o.scale.clone()).filter(|s| !s.is_empty()).map(at),
            })
        })
        .collect()
}

fn inputs(list: &[pb::Input]) -> Vec<Spanned<InputEntry>> {
    list.iter()
        .map(|i| {
            at(InputEntry {
                model: at(i.model.clone()),
                measured: i.measured.clone(),
                interpolation: Some(i.interpolation.clone())
                    .filter(|s| !s.is_empty())
                    .map(at),
            })
        })
        .collect()
}

/// The parameters of `list`, `field` naming the list in errors.
fn parameters(list: &[pb::Parameter], field: &str) -> Result<Vec<Spanned<ParameterEntry>>, String> {
    list.iter()
        .enumerate()
        .map(|(k, p)| {
            let scale = match p.scale.as_str() {
                "" => Scale::default(),
                scale => named::<Scale>(scale, &format!("{field}[{k}].scale"))?,
            };
            Ok(at(ParameterEntry {
                name: at(p.name.clone()),
                nominal: p.nominal,
                min: p.min,
                max: p.max,
                scale,
            }))
        })
        .collect()
}

/// A built-in effect made free, as its `[[effects]]` entry.
fn builtin_effect(p: ParameterEntry) -> EffectEntry {
    EffectEntry {
        name: p.name,
        nominal: p.nominal,
        min: Some(p.min),
        max: Some(p.max),
        scale: p.scale,
        torque: None,
        output: None,
        formula: None,
        parameters: None,
        fixed: None,
    }
}

/// `name` read as the campaign file reads it (`Method`, `Scale`), or the refusal naming
/// `field` in the campaign file's words.
fn named<T: for<'de> Deserialize<'de>>(name: &str, field: &str) -> Result<T, String> {
    T::deserialize(name.into_deserializer())
        .map_err(|e: serde::de::value::Error| format!("campaign.{field}: {e}"))
}

/// `n` as the spec holds it; what a campaign file cannot hold (past `i64`) is refused.
fn integer<T: TryFrom<u64>>(field: &str, n: u64) -> Result<T, String> {
    i64::try_from(n)
        .ok()
        .and_then(|_| T::try_from(n).ok())
        .ok_or_else(|| format!("campaign.{field}: {n} is too large"))
}

/// The Calibration API's campaign message for a campaign file's text, on dataset `dataset`.
/// The file has been resolved already, so its shape is known to be right. A campaign on an
/// FMU (`fmu = "..."`) gets its interface; its `fmu_id` is left for the caller to set. The
/// datasets of `[[experiments]]` are left empty: see [`campaign_message_on`].
pub fn campaign_message(text: &str, dataset: &str) -> Result<pb::Campaign, String> {
    campaign_message_on(text, dataset, &[])
}

/// [`campaign_message`], the k-th `[[experiments]]` entry on dataset `experiments[k]` (empty
/// past the list's end).
pub fn campaign_message_on(
    text: &str,
    dataset: &str,
    experiments: &[String],
) -> Result<pb::Campaign, String> {
    let spec = CampaignSpec::parse(text, Path::new("campaign.toml")).map_err(|e| e.to_string())?;
    Ok(message_of(&spec, dataset, experiments))
}

/// The message of `spec`, on dataset `dataset` (its experiments' on `experiments`).
pub fn message_of(spec: &CampaignSpec, dataset: &str, experiments: &[String]) -> pb::Campaign {
    let model = spec.model.get_ref();
    let window = spec.window.as_ref().map(|w| w.get_ref());
    let solver = spec.solver.as_ref().map(|s| s.get_ref());
    let (effects, defined): (Vec<_>, Vec<_>) = spec
        .effects
        .iter()
        .map(|e| e.get_ref())
        .partition(|e| !super::defined_effects::is_defined(e));
    pb::Campaign {
        name: text_of(&spec.name),
        model: text_of(&model.name),
        // The FMU itself is named by the id its upload answers, which the caller sets.
        fmu_id: String::new(),
        fmu_interface: text_of(&model.interface),
        stop_time: number_of(&model.stop_time).unwrap_or_default(),
        start_time: number_of(&model.start_time).unwrap_or_default(),
        step: number_of(&model.step),
        model_parameters: value_map(&model.parameters),
        dataset_id: if spec.experiments.is_empty() {
            dataset.to_string()
        } else {
            String::new()
        },
        outputs: output_messages(&spec.outputs),
        inputs: input_messages(&spec.inputs),
        parameters: parameter_messages(spec.parameters.iter().map(|p| p.get_ref())),
        effects: effects
            .iter()
            .map(|e| pb::Parameter {
                name: e.name.get_ref().clone(),
                nominal: e.nominal,
                min: e.min.unwrap_or_default(),
                max: e.max.unwrap_or_default(),
                scale: scale_name(e.scale),
            })
            .collect(),
        defined_effects: defined
            .into_iter()
            .map(super::defined_effects::message)
            .collect(),
        window_start: window.map_or(0.0, |w| w.start),
        window_stop: window.map_or(0.0, |w| w.stop),
        windows: window_messages(&spec.windows),
        experiments: spec
            .experiments
            .iter()
            .enumerate()
            .map(|(k, e)| experiment_message(e.get_ref(), experiments.get(k)))
            .collect(),
        search: spec.search.as_ref().map(|s| search_message(s.get_ref())),
        rtol: solver.and_then(|s| s.rtol),
        atol: solver.and_then(|s| s.atol),
        max_steps: solver.and_then(|s| s.max_steps),
        diagnosis: spec.diagnosis.as_ref().map(|d| {
            let d = d.get_ref();
            pb::DiagnosisSettings {
                holdout_start: d.holdout_start,
                holdout_stop: d.holdout_stop,
                refit: d.refit.map(|n| n as u64),
                candidates: d.candidates.clone().unwrap_or_default(),
            }
        }),
    }
}

/// A spec's `[search]` as its message (a file's default methods stated: the API refuses an
/// empty list).
fn search_message(s: &SearchSection) -> pb::Search {
    pb::Search {
        methods: s.methods.iter().map(|m| m.name().to_string()).collect(),
        starts: Some(s.starts as u64),
        max_evaluations: Some(s.max_evaluations as u64),
        seed: s.seed,
        screening: s.screening.map(|n| n as u64),
        cma_population: s.cma_population.map(|n| n as u64),
    }
}

/// One experiment as its message, its record the dataset `dataset` names.
fn experiment_message(e: &ExperimentEntry, dataset: Option<&String>) -> pb::Experiment {
    let mut windows = window_messages(&e.windows);
    if let Some(w) = &e.window {
        let w = w.get_ref();
        windows.insert(
            0,
            pb::Window {
                start: w.start,
                stop: w.stop,
            },
        );
    }
    pb::Experiment {
        name: e.name.get_ref().clone(),
        dataset_id: dataset.cloned().unwrap_or_default(),
        windows,
        stop_time: number_of(&e.stop_time).unwrap_or_default(),
        fixed: value_map(&e.fixed),
        inputs: input_messages(&e.inputs),
        outputs: output_messages(&e.outputs),
        parameters: parameter_messages(e.parameters.iter().map(|p| p.get_ref())),
    }
}

fn text_of(v: &Option<Spanned<String>>) -> String {
    v.as_ref().map(|s| s.get_ref().clone()).unwrap_or_default()
}

fn number_of(v: &Option<Spanned<f64>>) -> Option<f64> {
    v.as_ref().map(|n| *n.get_ref())
}

fn value_map<M: FromIterator<(String, f64)>>(map: &BTreeMap<Spanned<String>, Spanned<f64>>) -> M {
    map.iter()
        .map(|(k, v)| (k.get_ref().clone(), *v.get_ref()))
        .collect()
}

/// A parameter's scale as the message names it: the default (linear) as no name.
fn scale_name(scale: Scale) -> String {
    match scale {
        Scale::Lin => String::new(),
        Scale::Log10 => "log10".into(),
    }
}

fn parameter_messages<'a>(list: impl Iterator<Item = &'a ParameterEntry>) -> Vec<pb::Parameter> {
    list.map(|p| pb::Parameter {
        name: p.name.get_ref().clone(),
        nominal: p.nominal,
        min: p.min,
        max: p.max,
        scale: scale_name(p.scale),
    })
    .collect()
}

fn output_messages(list: &[Spanned<OutputEntry>]) -> Vec<pb::Output> {
    list.iter()
        .map(|o| {
            let o = o.get_ref();
            pb::Output {
                model: o.model.get_ref().clone(),
                measured: o.measured.clone(),
                weight: number_of(&o.weight),
                sigma: number_of(&o.sigma),
                scale: text_of(&o.scale),
            }
        })
        .collect()
}

fn input_messages(list: &[Spanned<InputEntry>]) -> Vec<pb::Input> {
    list.iter()
        .map(|i| {
            let i = i.get_ref();
            pb::Input {
                model: i.model.get_ref().clone(),
                measured: i.measured.clone(),
                interpolation: text_of(&i.interpolation),
            }
        })
        .collect()
}

fn window_messages(windows: &Option<Spanned<Vec<[f64; 2]>>>) -> Vec<pb::Window> {
    windows
        .as_ref()
        .map(|w| {
            w.get_ref()
                .iter()
                .map(|[start, stop]| pb::Window {
                    start: *start,
                    stop: *stop,
                })
                .collect()
        })
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use calib_engine::campaign::Campaign;

    /// An FMU campaign's start time and communication step travel through the message into
    /// the campaign, and into the campaign file it is stored as.
    #[test]
    fn an_fmus_start_time_and_step_survive_the_message() {
        let text = r#"
[model]
fmu = "VanDerPol.fmu"
interface = "co-simulation"
stop_time = 5.0
start_time = 2.0
step = 0.01
"#;
        let message = campaign_message(text, "d").unwrap();
        assert_eq!((message.start_time, message.step), (2.0, Some(0.01)));
        let record = Record {
            file: "/data/x.csv".into(),
            time_column: "time".into(),
        };
        let fmu = Path::new("/fmus/v.fmu");
        let spec = campaign_spec_with(&message, Some(&record), &[], Some(fmu)).unwrap();
        let model = spec.model.get_ref();
        assert_eq!(number_of(&model.start_time), Some(2.0));
        assert_eq!(number_of(&model.step), Some(0.01));
        assert_eq!(text_of(&model.fmu), "/fmus/v.fmu");
        let back = CampaignSpec::parse(&spec.to_toml().unwrap(), Path::new("c.toml")).unwrap();
        assert_eq!(number_of(&back.model.get_ref().step), Some(0.01));
        let plain = campaign_message("[model]\nname = \"furuta\"\n", "d").unwrap();
        let spec = campaign_spec(&plain, Path::new("/data/x.csv"), "time").unwrap();
        let model = spec.model.get_ref();
        assert!(model.start_time.is_none() && model.step.is_none());
    }

    /// A campaign file's `[search]` without `methods` keeps its documented default, stated in
    /// the message (the API refuses an empty list); one without `[search]` sends none.
    #[test]
    fn a_files_default_methods_are_stated_in_the_message() {
        let file = "[model]\nname = \"furuta\"\n[search]\nstarts = 2\n";
        let message = campaign_message(file, "d").unwrap();
        let search = message.search.unwrap();
        assert_eq!(search.methods, ["nelder-mead"]);
        assert_eq!(search.starts, Some(2));
        let stated = "[model]\nname = \"furuta\"\n[search]\nmethods = [\"powell\"]\n";
        let message = campaign_message(stated, "d").unwrap();
        assert_eq!(message.search.unwrap().methods, ["powell"]);
        let none = campaign_message("[model]\nname = \"furuta\"\n", "d").unwrap();
        assert_eq!(none.search, None);
        // A message naming no method takes the default, as a file without `methods` does
        // (SubmitCampaign refuses it before; an analysis runs no search).
        let mut empty = none.clone();
        empty.search = Some(pb::Search::default());
        let spec = campaign_spec(&empty, Path::new("/data/x.csv"), "time").unwrap();
        assert_eq!(spec.search.unwrap().get_ref().methods, default_methods());
    }

    /// What the spec cannot hold is refused naming the message's field: an unknown method
    /// or scale, a number past what a campaign file holds.
    #[test]
    fn a_message_the_spec_cannot_hold_is_refused_at_its_field() {
        let record = Path::new("/data/x.csv");
        let mut message = campaign_message("[model]\nname = \"furuta\"\n", "d").unwrap();
        message.search = Some(pb::Search {
            methods: vec!["nelder-mead".into(), "simplex".into()],
            ..Default::default()
        });
        let error = campaign_spec(&message, record, "time").unwrap_err();
        assert!(error.starts_with("campaign.search.methods[1]: "), "{error}");
        assert!(error.contains("simplex"), "{error}");
        message.search = Some(pb::Search {
            methods: vec!["powell".into()],
            screening: Some(u64::MAX),
            ..Default::default()
        });
        let error = campaign_spec(&message, record, "time").unwrap_err();
        assert!(error.starts_with("campaign.search.screening: "), "{error}");
        message.search = None;
        message.parameters = vec![pb::Parameter {
            name: "armFriction".into(),
            min: 0.0,
            max: 1.0,
            scale: "log2".into(),
            ..Default::default()
        }];
        let error = campaign_spec(&message, record, "time").unwrap_err();
        assert!(
            error.starts_with("campaign.parameters[0].scale: "),
            "{error}"
        );
    }

    /// Inputs, disjoint windows, experiments and effects travel through the message into a
    /// campaign that resolves to the campaign of the file; the campaign file it keeps reads
    /// back to the same campaign and to the same message.
    #[test]
    fn a_campaign_file_through_the_message_resolves_to_the_same_campaign() {
        let text = r#"
name = "two"
[model]
name = "furuta"
[[outputs]]
model = "armJoint.phi"
measured = "arm"
scale = "variance"
[[inputs]]
model = "armTorque"
measured = "u"
interpolation = "hold"
[[parameters]]
name = "armFriction"
min = 1e-4
max = 0.9
scale = "log10"
[[effects]]
name = "viscous_friction.pendulum"
min = 0.0
max = 0.1
[[effects]]
name = "cogging.arm"
torque = "armJoint"
formula = "a * sin(8 * armJoint.phi)"
parameters = [ { name = "a", nominal = 0.001, min = -0.02, max = 0.02 } ]
[[experiments]]
name = "swing"
file = "swing.csv"
window = { start = 0.0, stop = 20.0 }
stop_time = 25.0
fixed = { theta0 = 0.5 }
inputs = [ { model = "armTorque", measured = "u", interpolation = "linear" } ]
[[experiments]]
name = "driven"
file = "/data/driven.csv"
time_column = "t"
windows = [[0.0, 1.0], [2.0, 10.0]]
outputs = [ { model = "pendulumJoint.phi", measured = "pendulum", sigma = 0.01 } ]
[[experiments.parameters]]
name = "theta0"
nominal = 1.0
min = 0.0
max = 3.2
[search]
methods = ["nelder-mead", "cma-es"]
starts = 3
max_evaluations = 200
seed = 7
cma_population = 12
[solver]
rtol = 1e-7
max_steps = 50000
[diagnosis]
holdout_start = 20.0
holdout_stop = 25.0
refit = 2
candidates = ["viscous_friction.arm"]
"#;
        let ids = ["a".repeat(64), "b".repeat(64)];
        let message = campaign_message_on(text, "ignored", &ids).unwrap();
        assert_eq!(
            message.dataset_id, "",
            "the experiments name their datasets"
        );
        assert_eq!(message.inputs[0].interpolation, "hold");
        assert_eq!(message.parameters[0].scale, "log10");
        assert_eq!(
            (message.effects.len(), message.defined_effects.len()),
            (1, 1)
        );
        let [swing, driven] = &message.experiments[..] else {
            panic!("two experiments: {:?}", message.experiments);
        };
        assert_eq!(
            (swing.dataset_id.as_str(), swing.stop_time),
            (&*ids[0], 25.0)
        );
        assert_eq!(swing.fixed.get("theta0"), Some(&0.5));
        let windows: Vec<(f64, f64)> = driven.windows.iter().map(|w| (w.start, w.stop)).collect();
        assert_eq!(windows, [(0.0, 1.0), (2.0, 10.0)]);
        assert_eq!(driven.parameters[0].nominal, Some(1.0));

        let records = [
            Record {
                file: "/srv/datasets/a.csv".into(),
                time_column: "time".into(),
            },
            Record {
                file: "/srv/datasets/b.csv".into(),
                time_column: "t".into(),
            },
        ];
        let spec = campaign_spec_with(&message, None, &records, None).unwrap();
        let at = Path::new("/srv/submitted.toml");
        let built = Campaign::from_spec(spec, at).unwrap();
        let original = Campaign::parse(text, Path::new("/c/x.toml")).unwrap();
        let stored = Campaign::parse(&built.spec, at).unwrap();
        for back in [&built, &stored] {
            assert_eq!(back.free, original.free);
            assert_eq!(back.inputs, original.inputs);
            assert_eq!(back.outputs, original.outputs);
            assert_eq!(back.base, original.base);
            assert_eq!(back.search, original.search);
            assert_eq!(back.solver, original.solver);
            assert_eq!(back.diagnosis, original.diagnosis);
            assert_eq!(back.model.user_effects(), original.model.user_effects());
            assert_eq!(back.measurement_file, Path::new("/srv/datasets/a.csv"));
            let (b, o) = (&back.more[0], &original.more[0]);
            assert_eq!(
                (&b.windows, &b.outputs, &b.inputs, &b.base, b.stop_time),
                (&o.windows, &o.outputs, &o.inputs, &o.base, o.stop_time)
            );
            assert_eq!(
                (b.measurement_file.as_path(), b.time_column.as_str()),
                (Path::new("/srv/datasets/b.csv"), "t")
            );
        }
        // The campaign file it keeps gives back the message.
        assert_eq!(campaign_message_on(&built.spec, "", &ids).unwrap(), message);
        // So do disjoint windows of one record.
        let one = "windows = [[0.0, 5.0], [10.0, 40.0]]\n[model]\nname = \"furuta\"\n";
        let message = campaign_message(one, "d").unwrap();
        assert_eq!(message.windows.len(), 2);
        let spec = campaign_spec(&message, Path::new("/data/x.csv"), "time").unwrap();
        let file = spec.to_toml().unwrap();
        assert_eq!(campaign_message(&file, "d").unwrap(), message);
        assert!(campaign_spec_with(&message, None, &records, None).is_err());
    }
}
