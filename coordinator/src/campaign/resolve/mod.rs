//! Checking a campaign file against the model it names: every section resolved in turn,
//! each mistake reported with the file, the line and the field.

use super::file::{
    default_max_evaluations, default_methods, default_starts, CampaignFile, DiagnosisSection,
    InputEntry, ModelSection, OutputEntry, ParameterEntry, SearchSection, SolverSection,
    WindowSection,
};
use super::user_effects;
use super::{
    Campaign, CampaignError, DiagnosisSettings, Experiment, FreeParameter, InputMapping,
    Interpolation, OutputMapping, OutputScale, Scale, Search,
};
use crate::limits;
use calib_worker::fmu::{self, Interface};
use calib_worker::validate::{self, SolverOverrides};
use calib_worker::{Model, ModelInfo, SolverOptions};
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Where a campaign's text came from, to turn byte offsets into located errors.
pub(super) struct Locator<'a> {
    pub(super) text: &'a str,
    pub(super) path: &'a Path,
}

impl Locator<'_> {
    pub(super) fn line(&self, offset: usize) -> usize {
        let end = offset.min(self.text.len());
        self.text.as_bytes()[..end]
            .iter()
            .filter(|b| **b == b'\n')
            .count()
            + 1
    }

    pub(super) fn error<T>(
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

    /// An error about a whole missing section, which has no line.
    fn unlocated<T>(&self, field: &str, message: &str) -> Result<T, CampaignError> {
        Err(CampaignError {
            file: self.path.to_path_buf(),
            line: None,
            field: field.into(),
            message: message.into(),
        })
    }
}

pub(super) fn resolve(file: CampaignFile, at: &Locator) -> Result<Campaign, CampaignError> {
    check_counts(&file, at)?;
    let model_span = file.model.span();
    let model_section = file.model.into_inner();
    let model = resolve_model(&model_section, at)?;
    let effects = user_effects::split(file.effects, at)?;
    let model = user_effects::attach(model, &effects.defined, at)?;
    let info = model.info();

    let (mut base, fixed) = resolve_fixed(&model_section, info, at)?;
    let defined_free = user_effects::free_parameters(&effects.defined, info, &fixed, &mut base);
    let shared_free = resolve_free(
        &file.parameters,
        &effects.builtin,
        defined_free,
        &fixed,
        &mut base,
        info,
        "",
        at,
    );
    let mut free = match shared_free {
        // With several experiments, every free parameter may be some experiment's own.
        Err(_) if !file.experiments.is_empty() && file.parameters.is_empty() => Vec::new(),
        other => other?,
    };
    let mut experiments = Vec::new();
    if file.experiments.is_empty() {
        let Some(measurement) = file.measurement else {
            return at.unlocated(
                "measurement",
                "missing [measurement] with the record's `file` (or [[experiments]], one \
                 per record)",
            );
        };
        let outputs = resolve_outputs(&file.outputs, info, "outputs", at)?;
        let inputs = resolve_inputs(&file.inputs, info, "inputs", at)?;
        let windows = resolve_windows(file.window, file.windows, "", at)?;
        let stop_time = resolve_stop_time(
            model_section.stop_time.as_ref(),
            "model.stop_time",
            model_span.clone(),
            windows[windows.len() - 1].1,
            at,
        )?;
        experiments.push(Experiment {
            name: String::new(),
            measurement_file: relative_to(at, measurement.file.get_ref()),
            time_column: measurement.time_column,
            outputs,
            inputs,
            window: hull(&windows),
            windows,
            stop_time,
            base: base.clone(),
        });
    } else {
        if let Some(m) = &file.measurement {
            return at.error(
                m.file.span(),
                "measurement",
                "give one [measurement] or several [[experiments]], not both".into(),
            );
        }
        if let Some(w) = &file.window {
            return at.error(
                w.span(),
                "window",
                "with [[experiments]], each experiment has its own `window`".into(),
            );
        }
        if let Some(w) = &file.windows {
            return at.error(
                w.span(),
                "windows",
                "with [[experiments]], each experiment has its own `windows`".into(),
            );
        }
        if let Err(e) = limits::at_most(file.experiments.len(), MAX_EXPERIMENTS, "experiments") {
            return at.error(file.experiments[MAX_EXPERIMENTS].span(), "experiments", e);
        }
        for (k, entry) in file.experiments.into_iter().enumerate() {
            let span = entry.span();
            let e = entry.into_inner();
            let name = e.name.get_ref().clone();
            let here = format!("experiments[{k}] ({name})");
            if name.is_empty() || name.contains('@') || name.len() > 64 {
                return at.error(
                    e.name.span(),
                    &format!("experiments[{k}].name"),
                    "an experiment's name is 1 to 64 characters, without `@`".into(),
                );
            }
            if experiments.iter().any(|x: &Experiment| x.name == name) {
                return at.error(
                    e.name.span(),
                    &here,
                    "another experiment has this name".into(),
                );
            }
            let outputs = if e.outputs.is_empty() {
                resolve_outputs(&file.outputs, info, "outputs", at)?
            } else {
                resolve_outputs(&e.outputs, info, &format!("{here}.outputs"), at)?
            };
            let inputs = if e.inputs.is_empty() {
                resolve_inputs(&file.inputs, info, "inputs", at)?
            } else {
                resolve_inputs(&e.inputs, info, &format!("{here}.inputs"), at)?
            };
            if e.window.is_none() && e.windows.is_none() {
                return at.error(
                    span,
                    &here,
                    "needs a `window = { start = ..., stop = ... }` or `windows = [[a, b], ...]`"
                        .into(),
                );
            }
            let windows = resolve_windows(e.window, e.windows, &format!("{here}."), at)?;
            let stop_time = resolve_stop_time(
                e.stop_time.as_ref(),
                &format!("{here}.stop_time"),
                span.clone(),
                windows[windows.len() - 1].1,
                at,
            )?;
            let mut own = base.clone();
            let mut own_fixed = fixed.clone();
            for (pname, value) in &e.fixed {
                let field = format!("{here}.fixed.{}", pname.get_ref());
                let index = match validate::parameter(info, pname.get_ref()) {
                    Ok(index) => index,
                    Err(err) => return at.error(pname.span(), &field, err.message),
                };
                if free.iter().any(|f| f.index == index) {
                    return at.error(
                        pname.span(),
                        &field,
                        "is free in the campaign and fixed here: fix it in every experiment \
                         or free it in each"
                            .into(),
                    );
                }
                let v = *value.get_ref();
                if let Err(err) = validate::parameter_value(info, index, v) {
                    return at.error(value.span(), &field, err.message);
                }
                own[index] = v;
                own_fixed.push(index);
            }
            let mut own_free = resolve_free(
                &e.parameters,
                &[],
                Vec::new(),
                &own_fixed,
                &mut own,
                info,
                &format!("{here}."),
                at,
            )
            .or_else(|err| {
                if e.parameters.is_empty() {
                    Ok(Vec::new())
                } else {
                    Err(err)
                }
            })?;
            for (i, p) in own_free.iter_mut().enumerate() {
                if free
                    .iter()
                    .any(|f| f.index == p.index && f.experiment.is_none())
                {
                    return at.error(
                        e.parameters[i].span(),
                        &format!("{here}.parameters[{i}] ({})", p.name),
                        "is free for every experiment already".into(),
                    );
                }
                p.name = format!("{}@{name}", p.name);
                p.experiment = Some(name.clone());
            }
            free.extend(own_free);
            experiments.push(Experiment {
                name,
                measurement_file: relative_to(at, e.file.get_ref()),
                time_column: e.time_column,
                outputs,
                inputs,
                window: hull(&windows),
                windows,
                stop_time,
                base: own,
            });
        }
        if let Err(e) = limits::at_most(
            free.len(),
            limits::MAX_FREE_PARAMETERS,
            "free parameters and effects",
        ) {
            return at.unlocated("parameters", &e);
        }
        if free.is_empty() {
            return at.unlocated(
                "parameters",
                "nothing to calibrate: add at least one [[parameters]] entry, for all \
                 experiments or in one",
            );
        }
    }
    let first = experiments.remove(0);
    let search = resolve_search(file.search, free.len(), at)?;
    let mut solver = resolve_solver(file.solver, model, at)?;
    let earliest = std::iter::once(&first)
        .chain(&experiments)
        .map(|e| e.window.0)
        .fold(f64::INFINITY, f64::min);
    resolve_time_settings(&model_section, model, earliest, &mut solver, at)?;
    let diagnosis = resolve_diagnosis(file.diagnosis, info, at)?;
    let name = resolve_name(file.name, at)?;

    Ok(Campaign {
        name,
        source: Some(at.path.to_path_buf()),
        spec: at.text.to_string(),
        model,
        stop_time: first.stop_time,
        base: first.base,
        free,
        measurement_file: first.measurement_file,
        time_column: first.time_column,
        outputs: first.outputs,
        inputs: first.inputs,
        window: first.window,
        windows: first.windows,
        experiment: first.name,
        more: experiments,
        search,
        solver,
        diagnosis,
    })
}

/// Most experiments one campaign fits together.
pub const MAX_EXPERIMENTS: usize = 64;

/// A path written in the campaign, relative to the campaign file's folder unless absolute.
fn relative_to(at: &Locator, written: &str) -> PathBuf {
    let path = PathBuf::from(written);
    if path.is_absolute() {
        path
    } else {
        at.path.parent().unwrap_or(Path::new(".")).join(path)
    }
}

/// The span from the first window's start to the last one's stop.
fn hull(windows: &[(f64, f64)]) -> (f64, f64) {
    (windows[0].0, windows[windows.len() - 1].1)
}

/// The campaign's name (the file's stem when it names none), held to
/// [`limits::campaign_name`]: it becomes the folder of the results.
fn resolve_name(name: Option<Spanned<String>>, at: &Locator) -> Result<String, CampaignError> {
    let (name, span) = match name {
        Some(name) => {
            let span = name.span();
            (name.into_inner(), Some(span))
        }
        None => (
            at.path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| "campaign".into()),
            None,
        ),
    };
    match (limits::campaign_name(&name), span) {
        (Ok(()), _) => Ok(name),
        (Err(e), Some(span)) => at.error(span, "name", e),
        (Err(e), None) => at.unlocated(
            "name",
            &format!("the file's name {e}; name the campaign with `name = \"...\"`"),
        ),
    }
}

/// The lists of a campaign held to their limits, before any of them is resolved.
fn check_counts(file: &CampaignFile, at: &Locator) -> Result<(), CampaignError> {
    let free = file.parameters.len() + file.effects.len();
    if let Err(e) = limits::at_most(
        free,
        limits::MAX_FREE_PARAMETERS,
        "free parameters and effects",
    ) {
        let span = file
            .parameters
            .iter()
            .map(|p| p.span())
            .chain(file.effects.iter().map(|e| e.span()))
            .nth(limits::MAX_FREE_PARAMETERS);
        return match span {
            Some(span) => at.error(span, "parameters", e),
            None => at.unlocated("parameters", &e),
        };
    }
    if let Err(e) = limits::at_most(file.outputs.len(), limits::MAX_OUTPUTS, "outputs") {
        let span = file.outputs[limits::MAX_OUTPUTS].span();
        return at.error(span, "outputs", e);
    }
    Ok(())
}

fn resolve_model(
    section: &ModelSection,
    at: &Locator,
) -> Result<&'static dyn Model, CampaignError> {
    let interface = match &section.interface {
        None => None,
        Some(i) => match i.get_ref().as_str() {
            "model-exchange" => Some(Interface::ModelExchange),
            "co-simulation" => Some(Interface::CoSimulation),
            other => {
                return at.error(
                    i.span(),
                    "model.interface",
                    format!("unknown interface `{other}`: \"model-exchange\" or \"co-simulation\""),
                )
            }
        },
    };
    match (&section.name, &section.fmu) {
        (Some(name), None) => {
            if let Some(i) = &section.interface {
                return at.error(
                    i.span(),
                    "model.interface",
                    "applies to an FMU (`fmu = \"...\"`), not to a hosted model".into(),
                );
            }
            match validate::model(name.get_ref()) {
                Ok(model) => Ok(model),
                Err(e) => at.error(name.span(), "model.name", e.message),
            }
        }
        (None, Some(fmu)) => {
            let path = Path::new(fmu.get_ref());
            let path = if path.is_absolute() {
                path.to_path_buf()
            } else {
                at.path.parent().unwrap_or(Path::new(".")).join(path)
            };
            match fmu::open(&path, interface) {
                Ok(model) => Ok(model),
                Err(e) => at.error(fmu.span(), "model.fmu", format!("{}: {e}", path.display())),
            }
        }
        (Some(name), Some(_)) => at.error(
            name.span(),
            "model",
            "name a hosted model (`name`) or an FMU (`fmu`), not both".into(),
        ),
        (None, None) => at.unlocated(
            "model",
            "name a hosted model (`name = \"furuta\"`) or an FMU (`fmu = \"Model.fmu\"`)",
        ),
    }
}

/// The model defaults with the campaign's fixed values, and the indices it fixed.
fn resolve_fixed(
    section: &ModelSection,
    info: &ModelInfo,
    at: &Locator,
) -> Result<(Vec<f64>, Vec<usize>), CampaignError> {
    let mut base = info.default_vector();
    let mut fixed = Vec::new();
    for (name, value) in &section.parameters {
        let field = format!("model.parameters.{}", name.get_ref());
        let index = match validate::parameter(info, name.get_ref()) {
            Ok(index) => index,
            Err(e) => return at.error(name.span(), &field, e.message),
        };
        let v = *value.get_ref();
        if let Err(e) = validate::parameter_value(info, index, v) {
            return at.error(value.span(), &field, e.message);
        }
        base[index] = v;
        fixed.push(index);
    }
    Ok((base, fixed))
}

/// Free parameters, then free effects (`effects`: each with its place in the file's
/// list), each set to its nominal value in `base`, then the parameters of effects defined
/// by a formula (`defined`, set already).
#[allow(clippy::too_many_arguments)]
fn resolve_free(
    parameters: &[Spanned<ParameterEntry>],
    effects: &[(usize, Spanned<ParameterEntry>)],
    defined: Vec<FreeParameter>,
    fixed: &[usize],
    base: &mut [f64],
    info: &ModelInfo,
    prefix: &str,
    at: &Locator,
) -> Result<Vec<FreeParameter>, CampaignError> {
    let mut free: Vec<FreeParameter> = Vec::new();
    let entries = parameters
        .iter()
        .enumerate()
        .map(|(i, e)| ("parameters", e, i))
        .chain(effects.iter().map(|(i, e)| ("effects", e, *i)));
    for (section, entry, i) in entries {
        let is_effect = section == "effects";
        let span = entry.span();
        let p = entry.get_ref();
        let name = p.name.get_ref();
        let field = format!("{prefix}{section}[{i}] ({name})");
        if is_effect {
            if let Err(e) = validate::effect(info, name) {
                return at.error(p.name.span(), &field, e.message);
            }
        }
        let index = match validate::parameter(info, name) {
            Ok(index) => index,
            Err(e) => return at.error(p.name.span(), &field, e.message),
        };
        if free.iter().any(|f| f.index == index) {
            return at.error(span, &field, "is listed twice".into());
        }
        if defined.iter().any(|f| f.index == index) {
            return at.error(
                span,
                &field,
                "is free as a parameter of its effect already (mark it `fixed = true` there \
                 to hold it)"
                    .into(),
            );
        }
        if fixed.contains(&index) {
            return at.error(
                span,
                &field,
                "is both fixed in [model.parameters] and free here".into(),
            );
        }
        if let Err(e) = validate::bounds(info, index, p.min, p.max) {
            return at.error(span, &field, e.message);
        }
        if p.scale == Scale::Log10 && p.min <= 0.0 {
            return at.error(
                span,
                &field,
                format!(
                    "scale = \"log10\" needs min above 0 (it is {}); search a range from 0 \
                     with scale = \"lin\" (the default), which screens small values \
                     logarithmically, or set min to the smallest value that matters",
                    p.min
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
            scale: p.scale,
            experiment: None,
        });
    }
    free.extend(defined);
    if free.is_empty() {
        return at.unlocated(
            "parameters",
            "nothing to calibrate: add at least one [[parameters]] or [[effects]] entry",
        );
    }
    Ok(free)
}

fn resolve_outputs(
    entries: &[Spanned<OutputEntry>],
    info: &ModelInfo,
    list: &str,
    at: &Locator,
) -> Result<Vec<OutputMapping>, CampaignError> {
    if entries.is_empty() {
        return at.unlocated(
            list,
            "no output to compare: add at least one [[outputs]] entry",
        );
    }
    if let Err(e) = limits::at_most(entries.len(), limits::MAX_OUTPUTS, "outputs") {
        return at.error(entries[limits::MAX_OUTPUTS].span(), list, e);
    }
    let mut outputs = Vec::new();
    for (i, entry) in entries.iter().enumerate() {
        let o = entry.get_ref();
        let output = o.model.get_ref();
        let field = format!("{list}[{i}] ({output})");
        let model_index = match validate::output(info, output) {
            Ok(index) => index,
            Err(e) => return at.error(o.model.span(), &field, e.message),
        };
        let weight = match (&o.weight, &o.sigma) {
            (Some(_), Some(sigma)) => {
                return at.error(
                    sigma.span(),
                    &field,
                    "give `weight` or `sigma` (weight 1/sigma²), not both".into(),
                );
            }
            (Some(weight), None) => {
                let k = *weight.get_ref();
                if !k.is_finite() || k < 0.0 {
                    return at.error(
                        weight.span(),
                        &field,
                        format!("weight {k} must be a finite number ≥ 0"),
                    );
                }
                k
            }
            (None, Some(sigma)) => {
                let s = *sigma.get_ref();
                let k = 1.0 / (s * s);
                if !(s > 0.0 && k.is_finite() && k > 0.0) {
                    return at.error(
                        sigma.span(),
                        &field,
                        format!("sigma {s} must be a finite number > 0 (the weight is 1/sigma²)"),
                    );
                }
                k
            }
            (None, None) => 1.0,
        };
        let scale = match &o.scale {
            None => OutputScale::None,
            Some(scale) => match scale.get_ref().as_str() {
                "none" => OutputScale::None,
                "variance" if o.sigma.is_some() => {
                    return at.error(
                        scale.span(),
                        &field,
                        "scale = \"variance\" sets the output's scale from the data; it \
                         cannot be combined with `sigma`"
                            .into(),
                    );
                }
                "variance" => OutputScale::Variance,
                other => {
                    return at.error(
                        scale.span(),
                        &field,
                        format!("unknown scale `{other}` (known: none, variance)"),
                    );
                }
            },
        };
        outputs.push(OutputMapping {
            model: output.clone(),
            model_index,
            measured: o.measured.clone(),
            weight,
            scale,
        });
    }
    Ok(outputs)
}

fn resolve_inputs(
    entries: &[Spanned<InputEntry>],
    info: &ModelInfo,
    list: &str,
    at: &Locator,
) -> Result<Vec<InputMapping>, CampaignError> {
    let mut inputs: Vec<InputMapping> = Vec::new();
    for (i, entry) in entries.iter().enumerate() {
        let e = entry.get_ref();
        let input = e.model.get_ref();
        let field = format!("{list}[{i}] ({input})");
        let model_index = match validate::input(info, input) {
            Ok(index) => index,
            Err(err) => return at.error(e.model.span(), &field, err.message),
        };
        if inputs.iter().any(|m| m.model_index == model_index) {
            return at.error(entry.span(), &field, "is driven twice".into());
        }
        let interpolation = match &e.interpolation {
            None => Interpolation::Linear,
            Some(s) => match s.get_ref().as_str() {
                "linear" => Interpolation::Linear,
                "hold" => Interpolation::Hold,
                other => {
                    return at.error(
                        s.span(),
                        &field,
                        format!("unknown interpolation `{other}` (known: linear, hold)"),
                    )
                }
            },
        };
        inputs.push(InputMapping {
            model: input.clone(),
            model_index,
            measured: e.measured.clone(),
            interpolation,
        });
    }
    Ok(inputs)
}

/// The fitted intervals: one `window` table or a `windows` list of disjoint `[start, stop]`
/// pairs in increasing order (`prefix` places the keys, e.g. "experiments[1] (swing).").
fn resolve_windows(
    window: Option<Spanned<WindowSection>>,
    windows: Option<Spanned<Vec<[f64; 2]>>>,
    prefix: &str,
    at: &Locator,
) -> Result<Vec<(f64, f64)>, CampaignError> {
    let check = |start: f64, stop: f64, span, field: &str| {
        if !start.is_finite() || !stop.is_finite() || start < 0.0 || start >= stop {
            return at.error(
                span,
                field,
                format!("start ({start}) must be ≥ 0 and below stop ({stop})"),
            );
        }
        Ok(())
    };
    match (window, windows) {
        (Some(w), None) => {
            let (start, stop) = (w.get_ref().start, w.get_ref().stop);
            check(start, stop, w.span(), &format!("{prefix}window"))?;
            Ok(vec![(start, stop)])
        }
        (None, Some(list)) => {
            let field = format!("{prefix}windows");
            let span = list.span();
            let list = list.into_inner();
            if list.is_empty() {
                return at.error(span, &field, "lists no interval".into());
            }
            if let Err(e) = limits::at_most(list.len(), limits::MAX_WINDOWS, "fitted intervals") {
                return at.error(span, &field, e);
            }
            let mut out: Vec<(f64, f64)> = Vec::with_capacity(list.len());
            for (k, [start, stop]) in list.into_iter().enumerate() {
                check(start, stop, span.clone(), &format!("{field}[{k}]"))?;
                if let Some(&(_, before)) = out.last() {
                    if start < before {
                        return at.error(
                            span,
                            &format!("{field}[{k}]"),
                            format!(
                                "[{start}, {stop}] starts before the previous interval ends \
                                 ({before}): list disjoint intervals in time order"
                            ),
                        );
                    }
                }
                out.push((start, stop));
            }
            Ok(out)
        }
        (Some(w), Some(_)) => at.error(
            w.span(),
            &format!("{prefix}window"),
            "give `window` or `windows`, not both".into(),
        ),
        (None, None) => at.unlocated(
            &format!("{prefix}window"),
            "missing [window] with `start` and `stop` (seconds), or `windows = [[start, stop], \
             ...]`",
        ),
    }
}

fn resolve_stop_time(
    stop_time: Option<&Spanned<f64>>,
    field: &str,
    section_span: std::ops::Range<usize>,
    window_stop: f64,
    at: &Locator,
) -> Result<f64, CampaignError> {
    let stop_time = match stop_time {
        Some(t) => {
            let v = *t.get_ref();
            if !v.is_finite() || v < window_stop {
                return at.error(
                    t.span(),
                    field,
                    format!("{v} must be ≥ the window's stop ({window_stop})"),
                );
            }
            v
        }
        None => window_stop,
    };
    if let Err(e) = validate::stop_time(stop_time) {
        return at.error(section_span, field, e.message);
    }
    Ok(stop_time)
}

fn resolve_search(
    section: Option<Spanned<SearchSection>>,
    free: usize,
    at: &Locator,
) -> Result<Search, CampaignError> {
    let Some(s) = section else {
        return Ok(Search {
            methods: default_methods(),
            starts: default_starts(),
            max_evaluations: default_max_evaluations(),
            seed: 0,
            screening: None,
            cma_population: None,
            extra_starts: Vec::new(),
            stall: None,
        });
    };
    let span = s.span();
    let s = s.into_inner();
    if s.methods.is_empty() {
        return at.error(span, "search.methods", "name at least one method".into());
    }
    if s.starts == 0 {
        return at.error(span, "search.starts", "must be at least 1".into());
    }
    for (field, value, limit, what) in [
        ("search.starts", s.starts, limits::MAX_STARTS, "starts"),
        (
            "search.max_evaluations",
            s.max_evaluations,
            limits::MAX_EVALUATIONS,
            "evaluations per run",
        ),
        (
            "search.screening",
            s.screening.unwrap_or(0),
            limits::MAX_SCREENING,
            "screening points",
        ),
    ] {
        if let Err(e) = limits::at_most(value, limit, what) {
            return at.error(span, field, e);
        }
    }
    if let Some(population) = s.cma_population {
        if population < 2 || population > s.max_evaluations {
            return at.error(
                span,
                "search.cma_population",
                format!(
                    "{population} must lie between 2 and max_evaluations ({})",
                    s.max_evaluations
                ),
            );
        }
    }
    if s.max_evaluations < 2 * (free + 1) {
        return at.error(
            span,
            "search.max_evaluations",
            format!("{} is too few for {free} parameters", s.max_evaluations),
        );
    }
    let mut methods = s.methods;
    let mut seen = Vec::new();
    methods.retain(|m| {
        let first = !seen.contains(m);
        seen.push(*m);
        first
    });
    Ok(Search {
        methods,
        starts: s.starts,
        max_evaluations: s.max_evaluations,
        seed: s.seed,
        screening: s.screening,
        cma_population: s.cma_population,
        extra_starts: Vec::new(),
        stall: None,
    })
}

/// The model's own solver settings, with the campaign's overrides.
fn resolve_solver(
    section: Option<Spanned<SolverSection>>,
    model: &dyn Model,
    at: &Locator,
) -> Result<SolverOptions, CampaignError> {
    let Some(section) = section else {
        return Ok(model.default_options());
    };
    let span = section.span();
    let s = section.into_inner();
    let overrides = SolverOverrides {
        rtol: s.rtol,
        atol: s.atol,
        max_steps: s.max_steps,
        ..Default::default()
    };
    match validate::solver_options(model, overrides) {
        Ok(solver) => Ok(solver),
        Err((option, e)) => at.error(span, &format!("solver.{option}"), e.message),
    }
}

/// The model section's `start_time` and `step` (an FMU's start, a Co-Simulation FMU's
/// communication step) into the solver options.
fn resolve_time_settings(
    section: &ModelSection,
    model: &dyn Model,
    window_start: f64,
    solver: &mut SolverOptions,
    at: &Locator,
) -> Result<(), CampaignError> {
    if let Some(t) = &section.start_time {
        let v = *t.get_ref();
        solver.start_time = match validate::start_time(model, v) {
            Ok(v) => v,
            Err(e) => return at.error(t.span(), "model.start_time", e.message),
        };
        if v > window_start {
            return at.error(
                t.span(),
                "model.start_time",
                format!("{v} must be ≤ the window's start ({window_start})"),
            );
        }
    }
    if let Some(h) = &section.step {
        solver.communication_step = match validate::communication_step(model, *h.get_ref()) {
            Ok(v) => Some(v),
            Err(e) => return at.error(h.span(), "model.step", e.message),
        };
    }
    Ok(())
}

fn resolve_diagnosis(
    section: Option<Spanned<DiagnosisSection>>,
    info: &ModelInfo,
    at: &Locator,
) -> Result<DiagnosisSettings, CampaignError> {
    let mut diagnosis = DiagnosisSettings {
        holdout: None,
        refit: 3,
        candidates: None,
    };
    let Some(d) = section else {
        return Ok(diagnosis);
    };
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
        if let Err(e) = limits::at_most(refit, limits::MAX_REFIT, "refitted candidates") {
            return at.error(span, "diagnosis.refit", e);
        }
        diagnosis.refit = refit;
    }
    if let Some(candidates) = d.candidates {
        if let Err(e) = limits::at_most(candidates.len(), limits::MAX_CANDIDATES, "candidates") {
            return at.error(span, "diagnosis.candidates", e);
        }
        if let Some(e) = candidates
            .iter()
            .find_map(|c| validate::effect(info, c).err())
        {
            return at.error(span, "diagnosis.candidates", e.message);
        }
        diagnosis.candidates = Some(candidates);
    }
    Ok(diagnosis)
}
