//! The model a campaign names (hosted, or an FMU), its fixed values and its solver and time
//! settings.

use super::super::spec::{ModelSection, SolverSection};
use super::super::CampaignError;
use super::Locator;
use calib_model::fmu::{self, Interface};
use calib_model::validate::{self, SolverOverrides};
use calib_model::{Model, ModelInfo, SolverOptions};
use std::path::Path;
use toml::Spanned;

pub(super) fn resolve_model(
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
pub(super) fn resolve_fixed(
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

/// The model's own solver settings, with the campaign's overrides.
pub(super) fn resolve_solver(
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
pub(super) fn resolve_time_settings(
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
