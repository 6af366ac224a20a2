//! Checking a campaign file against the model it names: every section resolved in turn,
//! each mistake reported with the file, the line and the field.

mod diagnosis;
mod experiments;
mod mappings;
mod model;
mod parameters;
mod search;
mod windows;

use super::spec::{CampaignSpec, ParameterEntry};
use super::user_effects;
use super::{Campaign, CampaignError, FreeParameter};
use crate::limits;
use calib_model::ModelInfo;
use diagnosis::resolve_diagnosis;
pub use experiments::MAX_EXPERIMENTS;
use experiments::{Record, Shared};
use model::{resolve_fixed, resolve_model, resolve_solver, resolve_time_settings};
use parameters::resolve_free;
use search::resolve_search;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// Where a campaign came from, to turn byte offsets into located errors: the text of a
/// campaign file, or none for a campaign built from a message (its errors name a field, no
/// line).
pub(super) struct Locator<'a> {
    pub(super) text: Option<&'a str>,
    pub(super) path: &'a Path,
}

impl Locator<'_> {
    pub(super) fn line(&self, offset: usize) -> Option<usize> {
        let text = self.text?;
        let end = offset.min(text.len());
        Some(
            text.as_bytes()[..end]
                .iter()
                .filter(|b| **b == b'\n')
                .count()
                + 1,
        )
    }

    pub(super) fn error<T>(
        &self,
        span: std::ops::Range<usize>,
        field: &str,
        message: String,
    ) -> Result<T, CampaignError> {
        Err(CampaignError {
            file: self.path.to_path_buf(),
            line: self.line(span.start),
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

/// The campaign `file` resolved against the model it names; `at` locates its mistakes;
/// `spec` is its campaign file's text, which the campaign keeps.
pub(super) fn resolve(
    file: CampaignSpec,
    at: &Locator,
    spec: String,
) -> Result<Campaign, CampaignError> {
    check_counts(&file, at)?;
    let model_span = file.model.span();
    let model_section = file.model.into_inner();
    let model = resolve_model(&model_section, at)?;
    let effects = user_effects::split(file.effects, at)?;
    let model = user_effects::attach(model, &effects.defined, at)?;
    let info = model.info();

    let (mut base, fixed) = resolve_fixed(&model_section, info, at)?;
    let mut free = campaign_free(
        &file.parameters,
        !file.experiments.is_empty(),
        &effects,
        &fixed,
        &mut base,
        info,
        at,
    )?;
    let shared = Shared {
        info,
        outputs: &file.outputs,
        inputs: &file.inputs,
        base: &base,
        fixed: &fixed,
    };
    let record = Record {
        measurement: file.measurement,
        window: file.window,
        windows: file.windows,
    };
    let mut experiments = if file.experiments.is_empty() {
        vec![experiments::single(
            record,
            &model_section,
            model_span,
            &shared,
            at,
        )?]
    } else {
        experiments::several(file.experiments, &record, &mut free, &shared, at)?
    };
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
        spec,
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

/// The free parameters and effects of every experiment: `[[parameters]]`, then built-in
/// and defined `[[effects]]`, at their nominal values in `base`; none when the campaign has
/// `[[experiments]]` (`several`) and lists no `[[parameters]]` (each experiment may free its
/// own).
fn campaign_free(
    parameters: &[Spanned<ParameterEntry>],
    several: bool,
    effects: &user_effects::Split,
    fixed: &[usize],
    base: &mut [f64],
    info: &ModelInfo,
    at: &Locator,
) -> Result<Vec<FreeParameter>, CampaignError> {
    let defined_free = user_effects::free_parameters(&effects.defined, info, fixed, base);
    let shared_free = resolve_free(
        parameters,
        &effects.builtin,
        defined_free,
        fixed,
        base,
        info,
        "",
        at,
    );
    match shared_free {
        // With several experiments, every free parameter may be some experiment's own.
        Err(_) if several && parameters.is_empty() => Ok(Vec::new()),
        other => other,
    }
}

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
fn check_counts(file: &CampaignSpec, at: &Locator) -> Result<(), CampaignError> {
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
