//! The campaign message of the Calibration API and the campaign file it mirrors, both ways:
//! the coordinator writes a file from a message for the one campaign loader; clients
//! (`calib submit`) write a message from a file.

use calib_proto::v1 as pb;
use std::path::{Path, PathBuf};
use toml::{Table, Value};

/// The campaign file of `c`, its measurement the dataset file `file` with its time in
/// `time_column`; or the field that cannot be written as one.
pub fn campaign_file(c: &pb::Campaign, file: &Path, time_column: &str) -> Result<String, String> {
    campaign_file_on(c, file, time_column, None)
}

/// [`campaign_file`], its model the FMU archive at `fmu` when there is one (run through
/// `c.fmu_interface`), else the hosted model `c.model`.
pub fn campaign_file_on(
    c: &pb::Campaign,
    file: &Path,
    time_column: &str,
    fmu: Option<&Path>,
) -> Result<String, String> {
    let record = Record {
        file: file.to_path_buf(),
        time_column: time_column.to_string(),
    };
    campaign_file_with(c, Some(&record), &[], fmu)
}

/// A dataset as a campaign file names it: its file and time column.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    pub file: PathBuf,
    pub time_column: String,
}

/// The campaign file of `c`: its one record `record` (the dataset `c.dataset_id` names), or,
/// for a campaign of several experiments, `experiments[k]` the record of
/// `c.experiments[k]`; its model the FMU archive at `fmu` when there is one.
pub fn campaign_file_with(
    c: &pb::Campaign,
    record: Option<&Record>,
    experiments: &[Record],
    fmu: Option<&Path>,
) -> Result<String, String> {
    if experiments.len() != c.experiments.len() {
        return Err(format!(
            "campaign.experiments: {} experiments for {} records",
            c.experiments.len(),
            experiments.len()
        ));
    }
    let mut root = Table::new();
    if !c.name.is_empty() {
        root.insert("name".into(), c.name.clone().into());
    }
    let model = model_table(c, fmu);
    root.insert("model".into(), model.into());
    if let Some(record) = record {
        let mut measurement = Table::new();
        measurement.insert(
            "file".into(),
            record.file.to_string_lossy().into_owned().into(),
        );
        measurement.insert("time_column".into(), record.time_column.clone().into());
        root.insert("measurement".into(), measurement.into());
    }
    root.insert("outputs".into(), outputs(&c.outputs).into());
    if !c.inputs.is_empty() {
        root.insert("inputs".into(), inputs(&c.inputs).into());
    }
    root.insert("parameters".into(), parameters(&c.parameters).into());
    if !c.effects.is_empty() || !c.defined_effects.is_empty() {
        let mut effects = parameters(&c.effects);
        effects.extend(super::defined_effects::tables(&c.defined_effects));
        root.insert("effects".into(), effects.into());
    }
    if c.window_start != 0.0 || c.window_stop != 0.0 {
        let mut w = Table::new();
        w.insert("start".into(), c.window_start.into());
        w.insert("stop".into(), c.window_stop.into());
        root.insert("window".into(), w.into());
    }
    if !c.windows.is_empty() {
        root.insert("windows".into(), windows(&c.windows).into());
    }
    if !c.experiments.is_empty() {
        let list: Vec<Value> = c
            .experiments
            .iter()
            .zip(experiments)
            .map(|(e, record)| experiment(e, record).into())
            .collect();
        root.insert("experiments".into(), list.into());
    }
    if let Some(search) = &c.search {
        root.insert("search".into(), search_table(search)?.into());
    }
    if c.rtol.is_some() || c.atol.is_some() || c.max_steps.is_some() {
        root.insert("solver".into(), solver_table(c)?.into());
    }
    if let Some(d) = &c.diagnosis {
        root.insert("diagnosis".into(), diagnosis_table(d)?.into());
    }
    toml::to_string(&root).map_err(|e| format!("campaign: {e}"))
}

/// The `[model]` table: a built-in model by name or an FMU archive, its times and fixed
/// parameters.
fn model_table(c: &pb::Campaign, fmu: Option<&Path>) -> Table {
    let mut model = Table::new();
    match fmu {
        Some(path) => {
            model.insert("fmu".into(), path.to_string_lossy().into_owned().into());
            if !c.fmu_interface.is_empty() {
                model.insert("interface".into(), c.fmu_interface.clone().into());
            }
        }
        None => {
            model.insert("name".into(), c.model.clone().into());
        }
    }
    if c.stop_time != 0.0 {
        model.insert("stop_time".into(), c.stop_time.into());
    }
    if c.start_time != 0.0 {
        model.insert("start_time".into(), c.start_time.into());
    }
    if let Some(step) = c.step {
        model.insert("step".into(), step.into());
    }
    if !c.model_parameters.is_empty() {
        let fixed: Table = c
            .model_parameters
            .iter()
            .map(|(k, v)| (k.clone(), Value::from(*v)))
            .collect();
        model.insert("parameters".into(), fixed.into());
    }
    model
}

/// The `[search]` table.
fn search_table(s: &pb::Search) -> Result<Table, String> {
    let mut t = Table::new();
    if !s.methods.is_empty() {
        let methods: Vec<Value> = s.methods.iter().map(|m| m.clone().into()).collect();
        t.insert("methods".into(), methods.into());
    }
    if let Some(n) = s.starts {
        t.insert("starts".into(), integer("search.starts", n)?);
    }
    if let Some(n) = s.max_evaluations {
        t.insert(
            "max_evaluations".into(),
            integer("search.max_evaluations", n)?,
        );
    }
    t.insert("seed".into(), integer("search.seed", s.seed)?);
    if let Some(n) = s.screening {
        t.insert("screening".into(), integer("search.screening", n)?);
    }
    if let Some(n) = s.cma_population {
        t.insert(
            "cma_population".into(),
            integer("search.cma_population", n)?,
        );
    }
    Ok(t)
}

/// The `[solver]` table.
fn solver_table(c: &pb::Campaign) -> Result<Table, String> {
    let mut t = Table::new();
    if let Some(v) = c.rtol {
        t.insert("rtol".into(), v.into());
    }
    if let Some(v) = c.atol {
        t.insert("atol".into(), v.into());
    }
    if let Some(n) = c.max_steps {
        t.insert("max_steps".into(), integer("max_steps", n)?);
    }
    Ok(t)
}

/// The `[diagnosis]` table.
fn diagnosis_table(d: &pb::DiagnosisSettings) -> Result<Table, String> {
    let mut t = Table::new();
    if let Some(v) = d.holdout_start {
        t.insert("holdout_start".into(), v.into());
    }
    if let Some(v) = d.holdout_stop {
        t.insert("holdout_stop".into(), v.into());
    }
    if let Some(n) = d.refit {
        t.insert("refit".into(), integer("diagnosis.refit", n)?);
    }
    if !d.candidates.is_empty() {
        let list: Vec<Value> = d.candidates.iter().map(|c| c.clone().into()).collect();
        t.insert("candidates".into(), list.into());
    }
    Ok(t)
}

/// One `[[experiments]]` entry: its record, one `window` or several `windows`.
fn experiment(e: &pb::Experiment, record: &Record) -> Table {
    let mut t = Table::new();
    t.insert("name".into(), e.name.clone().into());
    t.insert(
        "file".into(),
        record.file.to_string_lossy().into_owned().into(),
    );
    t.insert("time_column".into(), record.time_column.clone().into());
    match e.windows.as_slice() {
        // No interval: the campaign's check names the experiment's window missing.
        [] => {}
        [w] => {
            let mut window = Table::new();
            window.insert("start".into(), w.start.into());
            window.insert("stop".into(), w.stop.into());
            t.insert("window".into(), window.into());
        }
        several => {
            t.insert("windows".into(), windows(several).into());
        }
    }
    if e.stop_time != 0.0 {
        t.insert("stop_time".into(), e.stop_time.into());
    }
    if !e.fixed.is_empty() {
        let fixed: Table = e
            .fixed
            .iter()
            .map(|(k, v)| (k.clone(), Value::from(*v)))
            .collect();
        t.insert("fixed".into(), fixed.into());
    }
    if !e.inputs.is_empty() {
        t.insert("inputs".into(), inputs(&e.inputs).into());
    }
    if !e.outputs.is_empty() {
        t.insert("outputs".into(), outputs(&e.outputs).into());
    }
    if !e.parameters.is_empty() {
        t.insert("parameters".into(), parameters(&e.parameters).into());
    }
    t
}

fn windows(list: &[pb::Window]) -> Vec<Value> {
    list.iter()
        .map(|w| Value::Array(vec![w.start.into(), w.stop.into()]))
        .collect()
}

fn outputs(list: &[pb::Output]) -> Vec<Value> {
    list.iter()
        .map(|o| {
            let mut t = Table::new();
            t.insert("model".into(), o.model.clone().into());
            t.insert("measured".into(), o.measured.clone().into());
            if let Some(w) = o.weight {
                t.insert("weight".into(), w.into());
            }
            if let Some(s) = o.sigma {
                t.insert("sigma".into(), s.into());
            }
            if !o.scale.is_empty() {
                t.insert("scale".into(), o.scale.clone().into());
            }
            t.into()
        })
        .collect()
}

fn inputs(list: &[pb::Input]) -> Vec<Value> {
    list.iter()
        .map(|i| {
            let mut t = Table::new();
            t.insert("model".into(), i.model.clone().into());
            t.insert("measured".into(), i.measured.clone().into());
            if !i.interpolation.is_empty() {
                t.insert("interpolation".into(), i.interpolation.clone().into());
            }
            t.into()
        })
        .collect()
}

fn parameters(list: &[pb::Parameter]) -> Vec<Value> {
    list.iter()
        .map(|p| {
            let mut t = Table::new();
            t.insert("name".into(), p.name.clone().into());
            if let Some(n) = p.nominal {
                t.insert("nominal".into(), n.into());
            }
            t.insert("min".into(), p.min.into());
            t.insert("max".into(), p.max.into());
            if !p.scale.is_empty() {
                t.insert("scale".into(), p.scale.clone().into());
            }
            t.into()
        })
        .collect()
}

fn integer(field: &str, n: u64) -> Result<Value, String> {
    i64::try_from(n)
        .map(Value::from)
        .map_err(|_| format!("campaign.{field}: {n} is too large"))
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
    let root: toml::Table = text.parse().map_err(|e| format!("{e}"))?;
    let list = |k: &str| tables(&root, k);
    let parameters = |k: &str| parameter_messages(&tables(&root, k));
    let model = table(root.get("model"));
    let window = table(root.get("window"));
    let solver = table(root.get("solver"));
    let search = root
        .get("search")
        .and_then(|v| v.as_table())
        .map(search_message);
    Ok(pb::Campaign {
        name: string(&root, "name"),
        model: string(&model, "name"),
        // The FMU itself is named by the id its upload answers, which the caller sets.
        fmu_id: String::new(),
        fmu_interface: string(&model, "interface"),
        stop_time: float(&model, "stop_time").unwrap_or_default(),
        start_time: float(&model, "start_time").unwrap_or_default(),
        step: float(&model, "step"),
        model_parameters: numbers(&table(model.get("parameters"))),
        dataset_id: if root.contains_key("experiments") {
            String::new()
        } else {
            dataset.to_string()
        },
        outputs: output_messages(&list("outputs")),
        inputs: input_messages(&list("inputs")),
        parameters: parameters("parameters"),
        effects: parameter_messages(
            &list("effects")
                .into_iter()
                .filter(|e| !super::defined_effects::is_defined(e))
                .collect::<Vec<_>>(),
        ),
        defined_effects: super::defined_effects::messages(&list("effects")),
        window_start: float(&window, "start").unwrap_or_default(),
        window_stop: float(&window, "stop").unwrap_or_default(),
        windows: window_messages(root.get("windows")),
        experiments: list("experiments")
            .iter()
            .enumerate()
            .map(|(k, e)| experiment_message(e, experiments.get(k)))
            .collect(),
        search,
        rtol: float(&solver, "rtol"),
        atol: float(&solver, "atol"),
        max_steps: uint(&solver, "max_steps"),
        diagnosis: root
            .get("diagnosis")
            .and_then(|v| v.as_table())
            .map(diagnosis_message),
    })
}

/// A file's `[search]` as its message.
fn search_message(s: &Table) -> pb::Search {
    pb::Search {
        // A file's [search] without `methods` takes its documented default, which the
        // message states: the API refuses an empty list.
        methods: strings(s, "methods").unwrap_or_else(|| {
            calib_engine::campaign::default_methods()
                .iter()
                .map(|m| m.name().to_string())
                .collect()
        }),
        starts: uint(s, "starts"),
        max_evaluations: uint(s, "max_evaluations"),
        seed: uint(s, "seed").unwrap_or_default(),
        screening: uint(s, "screening"),
        cma_population: uint(s, "cma_population"),
    }
}

/// One `[[experiments]]` entry as its message, its record the dataset `dataset` names.
fn experiment_message(e: &Table, dataset: Option<&String>) -> pb::Experiment {
    let mut windows = window_messages(e.get("windows"));
    if let Some(w) = e.get("window").and_then(|v| v.as_table()) {
        windows.insert(
            0,
            pb::Window {
                start: float(w, "start").unwrap_or_default(),
                stop: float(w, "stop").unwrap_or_default(),
            },
        );
    }
    pb::Experiment {
        name: string(e, "name"),
        dataset_id: dataset.cloned().unwrap_or_default(),
        windows,
        stop_time: float(e, "stop_time").unwrap_or_default(),
        fixed: numbers(&table(e.get("fixed"))),
        inputs: input_messages(&tables(e, "inputs")),
        outputs: output_messages(&tables(e, "outputs")),
        parameters: parameter_messages(&tables(e, "parameters")),
    }
}

/// A file's `[diagnosis]` as its message.
fn diagnosis_message(d: &Table) -> pb::DiagnosisSettings {
    pb::DiagnosisSettings {
        holdout_start: float(d, "holdout_start"),
        holdout_stop: float(d, "holdout_stop"),
        refit: uint(d, "refit"),
        candidates: strings(d, "candidates").unwrap_or_default(),
    }
}

/// The table at `v`, or an empty one.
fn table(v: Option<&toml::Value>) -> Table {
    v.and_then(|v| v.as_table()).cloned().unwrap_or_default()
}

fn uint(t: &Table, k: &str) -> Option<u64> {
    t.get(k).and_then(|v| v.as_integer()).map(|i| i as u64)
}

fn float(t: &Table, k: &str) -> Option<f64> {
    t.get(k)
        .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
}

fn string(t: &Table, k: &str) -> String {
    t.get(k)
        .and_then(|v| v.as_str())
        .map(str::to_string)
        .unwrap_or_default()
}

/// The strings of the array `k` of `t`, others left out; `None` when `k` is no array, so
/// each caller picks its own default.
fn strings(t: &Table, k: &str) -> Option<Vec<String>> {
    t.get(k).and_then(|v| v.as_array()).map(|a| {
        a.iter()
            .filter_map(|v| v.as_str().map(str::to_string))
            .collect()
    })
}

/// The tables of the array `k` of `t` (`[[outputs]]`, an experiment's `inputs = [...]`).
fn tables(t: &Table, k: &str) -> Vec<Table> {
    t.get(k)
        .and_then(|v| v.as_array())
        .map(|a| a.iter().filter_map(|v| v.as_table().cloned()).collect())
        .unwrap_or_default()
}

/// A table of numbers (fixed values) as a map.
fn numbers<M: FromIterator<(String, f64)>>(t: &Table) -> M {
    t.iter()
        .filter_map(|(k, v)| {
            v.as_float()
                .or_else(|| v.as_integer().map(|i| i as f64))
                .map(|f| (k.clone(), f))
        })
        .collect()
}

fn parameter_messages(list: &[Table]) -> Vec<pb::Parameter> {
    list.iter()
        .map(|p| pb::Parameter {
            name: string(p, "name"),
            nominal: float(p, "nominal"),
            min: float(p, "min").unwrap_or_default(),
            max: float(p, "max").unwrap_or_default(),
            scale: string(p, "scale"),
        })
        .collect()
}

fn output_messages(list: &[Table]) -> Vec<pb::Output> {
    list.iter()
        .map(|o| pb::Output {
            model: string(o, "model"),
            measured: string(o, "measured"),
            weight: float(o, "weight"),
            sigma: float(o, "sigma"),
            scale: string(o, "scale"),
        })
        .collect()
}

fn input_messages(list: &[Table]) -> Vec<pb::Input> {
    list.iter()
        .map(|i| pb::Input {
            model: string(i, "model"),
            measured: string(i, "measured"),
            interpolation: string(i, "interpolation"),
        })
        .collect()
}

/// `[[a, b], ...]` as windows.
fn window_messages(v: Option<&Value>) -> Vec<pb::Window> {
    v.and_then(|v| v.as_array())
        .map(|a| {
            a.iter()
                .filter_map(|pair| {
                    let pair = pair.as_array()?;
                    let number =
                        |v: &Value| v.as_float().or_else(|| v.as_integer().map(|i| i as f64));
                    Some(pb::Window {
                        start: number(pair.first()?)?,
                        stop: number(pair.get(1)?)?,
                    })
                })
                .collect()
        })
        .unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An FMU campaign's start time and communication step travel through the message and
    /// back into the file the coordinator loads.
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
        let file = campaign_file_on(
            &message,
            Path::new("/data/x.csv"),
            "time",
            Some(Path::new("/fmus/v.fmu")),
        )
        .unwrap();
        let back: Table = file.parse().unwrap();
        let model = back["model"].as_table().unwrap();
        assert_eq!(model["start_time"].as_float(), Some(2.0));
        assert_eq!(model["step"].as_float(), Some(0.01));
        let plain = campaign_message("[model]\nname = \"furuta\"\n", "d").unwrap();
        let file = campaign_file(&plain, Path::new("/data/x.csv"), "time").unwrap();
        let back: Table = file.parse().unwrap();
        let model = back["model"].as_table().unwrap();
        assert!(!model.contains_key("start_time") && !model.contains_key("step"));
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
    }

    /// Inputs, disjoint windows and experiments travel through the message and back into a
    /// campaign file that resolves to the same campaign.
    #[test]
    fn inputs_windows_and_experiments_survive_the_message() {
        let text = r#"
name = "two"
[model]
name = "furuta"
[[outputs]]
model = "armJoint.phi"
measured = "arm"
[[inputs]]
model = "armTorque"
measured = "u"
interpolation = "hold"
[[parameters]]
name = "armFriction"
min = 0.0
max = 0.9
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
"#;
        let ids = ["a".repeat(64), "b".repeat(64)];
        let message = campaign_message_on(text, "ignored", &ids).unwrap();
        assert_eq!(
            message.dataset_id, "",
            "the experiments name their datasets"
        );
        assert_eq!(message.inputs[0].interpolation, "hold");
        let [swing, driven] = &message.experiments[..] else {
            panic!("two experiments: {:?}", message.experiments);
        };
        assert_eq!(
            (swing.dataset_id.as_str(), swing.stop_time),
            (&*ids[0], 25.0)
        );
        assert_eq!(swing.fixed.get("theta0"), Some(&0.5));
        assert_eq!(swing.inputs[0].interpolation, "linear");
        let windows: Vec<(f64, f64)> = driven.windows.iter().map(|w| (w.start, w.stop)).collect();
        assert_eq!(windows, [(0.0, 1.0), (2.0, 10.0)]);
        assert_eq!(driven.outputs[0].sigma, Some(0.01));
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
        let file = campaign_file_with(&message, None, &records, None).unwrap();
        let at = Path::new("/srv/submitted.toml");
        let back = calib_engine::campaign::Campaign::parse(&file, at).unwrap();
        let original =
            calib_engine::campaign::Campaign::parse(text, Path::new("/c/x.toml")).unwrap();
        assert_eq!(back.free, original.free);
        assert_eq!(back.inputs, original.inputs);
        assert_eq!(back.base, original.base);
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
        // The message itself survives the round trip.
        assert_eq!(campaign_message_on(&file, "", &ids).unwrap(), message);
        // So do disjoint windows of one record.
        let one = "windows = [[0.0, 5.0], [10.0, 40.0]]\n[model]\nname = \"furuta\"\n";
        let message = campaign_message(one, "d").unwrap();
        assert_eq!(message.windows.len(), 2);
        let file = campaign_file(&message, Path::new("/data/x.csv"), "time").unwrap();
        assert_eq!(campaign_message(&file, "d").unwrap(), message);
        assert!(campaign_file_with(&message, None, &records, None).is_err());
    }
}
