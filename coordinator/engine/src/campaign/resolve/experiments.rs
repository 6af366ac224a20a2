//! The records a campaign fits: one `[measurement]` with its `[window]`, or several
//! `[[experiments]]`, each with its file, windows, outputs and inputs (the campaign's unless
//! it lists its own), and values fixed or free in it alone.

use super::super::spec::{
    ExperimentEntry, InputEntry, MeasurementSection, ModelSection, OutputEntry, WindowSection,
};
use super::super::{CampaignError, Experiment, FreeParameter};
use super::mappings::{resolve_inputs, resolve_outputs};
use super::parameters::resolve_free;
use super::windows::{resolve_stop_time, resolve_windows};
use super::{hull, relative_to, Locator};
use crate::limits;
use calib_model::validate;
use calib_model::ModelInfo;
use toml::Spanned;

/// Most experiments one campaign fits together.
pub const MAX_EXPERIMENTS: usize = 64;

/// What every experiment starts from: the model, the campaign's outputs and inputs, its
/// parameter vector and the indices it fixed.
pub(super) struct Shared<'a> {
    pub(super) info: &'a ModelInfo,
    pub(super) outputs: &'a [Spanned<OutputEntry>],
    pub(super) inputs: &'a [Spanned<InputEntry>],
    pub(super) base: &'a [f64],
    pub(super) fixed: &'a [usize],
}

/// Where the one record of a campaign without `[[experiments]]` and its fitted intervals
/// come from.
pub(super) struct Record {
    pub(super) measurement: Option<MeasurementSection>,
    pub(super) window: Option<Spanned<WindowSection>>,
    pub(super) windows: Option<Spanned<Vec<[f64; 2]>>>,
}

/// The one record of a campaign without `[[experiments]]`; `model_span` locates a bad
/// `model.stop_time`.
pub(super) fn single(
    record: Record,
    model: &ModelSection,
    model_span: std::ops::Range<usize>,
    shared: &Shared,
    at: &Locator,
) -> Result<Experiment, CampaignError> {
    let Some(measurement) = record.measurement else {
        return at.unlocated(
            "measurement",
            "missing [measurement] with the record's `file` (or [[experiments]], one \
             per record)",
        );
    };
    let outputs = resolve_outputs(shared.outputs, shared.info, "outputs", at)?;
    let inputs = resolve_inputs(shared.inputs, shared.info, "inputs", at)?;
    let windows = resolve_windows(record.window, record.windows, "", at)?;
    let stop_time = resolve_stop_time(
        model.stop_time.as_ref(),
        "model.stop_time",
        model_span,
        windows[windows.len() - 1].1,
        at,
    )?;
    Ok(Experiment {
        name: String::new(),
        measurement_file: relative_to(at, measurement.file.get_ref()),
        time_column: measurement.time_column,
        outputs,
        inputs,
        window: hull(&windows),
        windows,
        stop_time,
        base: shared.base.to_vec(),
    })
}

/// The `entries` of `[[experiments]]` (the campaign's own record and window must be absent),
/// their own free parameters added to `free`, which must then hold something within the
/// limit.
pub(super) fn several(
    entries: Vec<Spanned<ExperimentEntry>>,
    record: &Record,
    free: &mut Vec<FreeParameter>,
    shared: &Shared,
    at: &Locator,
) -> Result<Vec<Experiment>, CampaignError> {
    if let Some(m) = &record.measurement {
        return at.error(
            m.file.span(),
            "measurement",
            "give one [measurement] or several [[experiments]], not both".into(),
        );
    }
    if let Some(w) = &record.window {
        return at.error(
            w.span(),
            "window",
            "with [[experiments]], each experiment has its own `window`".into(),
        );
    }
    if let Some(w) = &record.windows {
        return at.error(
            w.span(),
            "windows",
            "with [[experiments]], each experiment has its own `windows`".into(),
        );
    }
    if let Err(e) = limits::at_most(entries.len(), MAX_EXPERIMENTS, "experiments") {
        return at.error(entries[MAX_EXPERIMENTS].span(), "experiments", e);
    }
    let mut experiments = Vec::new();
    for (k, entry) in entries.into_iter().enumerate() {
        let experiment = experiment(k, entry, &experiments, free, shared, at)?;
        experiments.push(experiment);
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
    Ok(experiments)
}

/// The `k`-th experiment, after the `earlier` ones; its own free parameters are added to
/// `free`.
fn experiment(
    k: usize,
    entry: Spanned<ExperimentEntry>,
    earlier: &[Experiment],
    free: &mut Vec<FreeParameter>,
    shared: &Shared,
    at: &Locator,
) -> Result<Experiment, CampaignError> {
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
    if earlier.iter().any(|x: &Experiment| x.name == name) {
        return at.error(
            e.name.span(),
            &here,
            "another experiment has this name".into(),
        );
    }
    let outputs = if e.outputs.is_empty() {
        resolve_outputs(shared.outputs, shared.info, "outputs", at)?
    } else {
        resolve_outputs(&e.outputs, shared.info, &format!("{here}.outputs"), at)?
    };
    let inputs = if e.inputs.is_empty() {
        resolve_inputs(shared.inputs, shared.info, "inputs", at)?
    } else {
        resolve_inputs(&e.inputs, shared.info, &format!("{here}.inputs"), at)?
    };
    if e.window.is_none() && e.windows.is_none() {
        return at.error(
            span,
            &here,
            "needs a `window = { start = ..., stop = ... }` or `windows = [[a, b], ...]`".into(),
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
    let (mut base, fixed) = own_fixed(&e.fixed, &here, free, shared, at)?;
    let alone = own_free(
        &e.parameters,
        &name,
        &here,
        &fixed,
        &mut base,
        free,
        shared.info,
        at,
    )?;
    free.extend(alone);
    Ok(Experiment {
        name,
        measurement_file: relative_to(at, e.file.get_ref()),
        time_column: e.time_column,
        outputs,
        inputs,
        window: hull(&windows),
        windows,
        stop_time,
        base,
    })
}

/// An experiment's parameter vector with its own `fixed` values (none of them free in
/// the whole campaign), and every index fixed in it.
fn own_fixed(
    fixed: &std::collections::BTreeMap<Spanned<String>, Spanned<f64>>,
    here: &str,
    free: &[FreeParameter],
    shared: &Shared,
    at: &Locator,
) -> Result<(Vec<f64>, Vec<usize>), CampaignError> {
    let mut own = shared.base.to_vec();
    let mut own_fixed = shared.fixed.to_vec();
    for (pname, value) in fixed {
        let field = format!("{here}.fixed.{}", pname.get_ref());
        let index = match validate::parameter(shared.info, pname.get_ref()) {
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
        if let Err(err) = validate::parameter_value(shared.info, index, v) {
            return at.error(value.span(), &field, err.message);
        }
        own[index] = v;
        own_fixed.push(index);
    }
    Ok((own, own_fixed))
}

/// The free parameters of the experiment `name` alone (`parameters`), named
/// `<parameter>@<name>`, at their nominal values in `own`; none may be free in every
/// experiment already.
#[allow(clippy::too_many_arguments)]
fn own_free(
    parameters: &[Spanned<super::super::spec::ParameterEntry>],
    name: &str,
    here: &str,
    own_fixed: &[usize],
    own: &mut [f64],
    free: &[FreeParameter],
    info: &ModelInfo,
    at: &Locator,
) -> Result<Vec<FreeParameter>, CampaignError> {
    let mut own_free = resolve_free(
        parameters,
        &[],
        Vec::new(),
        own_fixed,
        own,
        info,
        &format!("{here}."),
        at,
    )
    .or_else(|err| {
        if parameters.is_empty() {
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
                parameters[i].span(),
                &format!("{here}.parameters[{i}] ({})", p.name),
                "is free for every experiment already".into(),
            );
        }
        p.name = format!("{}@{name}", p.name);
        p.experiment = Some(name.to_string());
    }
    Ok(own_free)
}
