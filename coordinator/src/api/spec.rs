//! The campaign message of the Calibration API and the campaign file it mirrors, both ways:
//! the coordinator writes a file from a message for the one campaign loader; clients
//! (`calib submit`) write a message from a file.

use calib_proto::v1 as pb;
use std::path::Path;
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
    let mut root = Table::new();
    if !c.name.is_empty() {
        root.insert("name".into(), c.name.clone().into());
    }
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
    root.insert("model".into(), model.into());
    let mut measurement = Table::new();
    measurement.insert("file".into(), file.to_string_lossy().into_owned().into());
    measurement.insert("time_column".into(), time_column.into());
    root.insert("measurement".into(), measurement.into());

    let outputs: Vec<Value> = c
        .outputs
        .iter()
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
        .collect();
    root.insert("outputs".into(), outputs.into());
    root.insert("parameters".into(), parameters(&c.parameters).into());
    if !c.effects.is_empty() {
        root.insert("effects".into(), parameters(&c.effects).into());
    }
    if c.window_start != 0.0 || c.window_stop != 0.0 {
        let mut w = Table::new();
        w.insert("start".into(), c.window_start.into());
        w.insert("stop".into(), c.window_stop.into());
        root.insert("window".into(), w.into());
    }
    if let Some(s) = &c.search {
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
        root.insert("search".into(), t.into());
    }
    if c.rtol.is_some() || c.atol.is_some() || c.max_steps.is_some() {
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
        root.insert("solver".into(), t.into());
    }
    if let Some(d) = &c.diagnosis {
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
        root.insert("diagnosis".into(), t.into());
    }
    toml::to_string(&root).map_err(|e| format!("campaign: {e}"))
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
/// FMU (`fmu = "..."`) gets its interface; its `fmu_id` is left for the caller to set.
pub fn campaign_message(text: &str, dataset: &str) -> Result<pb::Campaign, String> {
    let root: toml::Table = text.parse().map_err(|e| format!("{e}"))?;
    let table = |v: Option<&toml::Value>| v.and_then(|v| v.as_table()).cloned().unwrap_or_default();
    let float = |t: &toml::Table, k: &str| {
        t.get(k)
            .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
    };
    let string = |t: &toml::Table, k: &str| {
        t.get(k)
            .and_then(|v| v.as_str())
            .map(str::to_string)
            .unwrap_or_default()
    };
    let uint = |t: &toml::Table, k: &str| t.get(k).and_then(|v| v.as_integer()).map(|i| i as u64);
    let list = |k: &str| -> Vec<toml::Table> {
        root.get(k)
            .and_then(|v| v.as_array())
            .map(|a| a.iter().filter_map(|v| v.as_table().cloned()).collect())
            .unwrap_or_default()
    };
    let parameters = |k: &str| -> Vec<pb::Parameter> {
        list(k)
            .iter()
            .map(|p| pb::Parameter {
                name: string(p, "name"),
                nominal: float(p, "nominal"),
                min: float(p, "min").unwrap_or_default(),
                max: float(p, "max").unwrap_or_default(),
                scale: string(p, "scale"),
            })
            .collect()
    };
    let model = table(root.get("model"));
    let window = table(root.get("window"));
    let solver = table(root.get("solver"));
    let search = root
        .get("search")
        .and_then(|v| v.as_table())
        .map(|s| pb::Search {
            methods: s
                .get("methods")
                .and_then(|v| v.as_array())
                .map(|a| {
                    a.iter()
                        .filter_map(|m| m.as_str().map(str::to_string))
                        .collect()
                })
                .unwrap_or_default(),
            starts: uint(s, "starts"),
            max_evaluations: uint(s, "max_evaluations"),
            seed: uint(s, "seed").unwrap_or_default(),
            screening: uint(s, "screening"),
        });
    Ok(pb::Campaign {
        name: string(&root, "name"),
        model: string(&model, "name"),
        // The FMU itself is named by the id its upload answers, which the caller sets.
        fmu_id: String::new(),
        fmu_interface: string(&model, "interface"),
        stop_time: float(&model, "stop_time").unwrap_or_default(),
        start_time: float(&model, "start_time").unwrap_or_default(),
        step: float(&model, "step"),
        model_parameters: table(model.get("parameters"))
            .iter()
            .filter_map(|(k, v)| {
                v.as_float()
                    .or_else(|| v.as_integer().map(|i| i as f64))
                    .map(|f| (k.clone(), f))
            })
            .collect(),
        dataset_id: dataset.to_string(),
        outputs: list("outputs")
            .iter()
            .map(|o| pb::Output {
                model: string(o, "model"),
                measured: string(o, "measured"),
                weight: float(o, "weight"),
                sigma: float(o, "sigma"),
                scale: string(o, "scale"),
            })
            .collect(),
        parameters: parameters("parameters"),
        effects: parameters("effects"),
        window_start: float(&window, "start").unwrap_or_default(),
        window_stop: float(&window, "stop").unwrap_or_default(),
        search,
        rtol: float(&solver, "rtol"),
        atol: float(&solver, "atol"),
        max_steps: uint(&solver, "max_steps"),
        diagnosis: root.get("diagnosis").and_then(|v| v.as_table()).map(|d| {
            pb::DiagnosisSettings {
                holdout_start: float(d, "holdout_start"),
                holdout_stop: float(d, "holdout_stop"),
                refit: uint(d, "refit"),
                candidates: d
                    .get("candidates")
                    .and_then(|v| v.as_array())
                    .map(|a| {
                        a.iter()
                            .filter_map(|c| c.as_str().map(str::to_string))
                            .collect()
                    })
                    .unwrap_or_default(),
            }
        }),
    })
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
}
