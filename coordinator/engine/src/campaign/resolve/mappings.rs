//! The record's columns mapped to the model: outputs compared (with their weights and
//! scales) and inputs driven.

use super::super::spec::{InputEntry, OutputEntry};
use super::super::{CampaignError, InputMapping, Interpolation, OutputMapping, OutputScale};
use super::Locator;
use crate::limits;
use calib_model::validate;
use calib_model::ModelInfo;
use toml::Spanned;

pub(super) fn resolve_outputs(
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
        let weight = weight(o, &field, at)?;
        let scale = scale(o, &field, at)?;
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

/// An output's weight: `weight` as written, or `1/sigma²`; 1 when neither is given.
fn weight(o: &OutputEntry, field: &str, at: &Locator) -> Result<f64, CampaignError> {
    let weight = match (&o.weight, &o.sigma) {
        (Some(_), Some(sigma)) => {
            return at.error(
                sigma.span(),
                field,
                "give `weight` or `sigma` (weight 1/sigma²), not both".into(),
            );
        }
        (Some(weight), None) => {
            let k = *weight.get_ref();
            if !k.is_finite() || k < 0.0 {
                return at.error(
                    weight.span(),
                    field,
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
                    field,
                    format!("sigma {s} must be a finite number > 0 (the weight is 1/sigma²)"),
                );
            }
            k
        }
        (None, None) => 1.0,
    };
    Ok(weight)
}

/// How an output's weight is scaled by its data.
fn scale(o: &OutputEntry, field: &str, at: &Locator) -> Result<OutputScale, CampaignError> {
    let scale = match &o.scale {
        None => OutputScale::None,
        Some(scale) => match scale.get_ref().as_str() {
            "none" => OutputScale::None,
            "variance" if o.sigma.is_some() => {
                return at.error(
                    scale.span(),
                    field,
                    "scale = \"variance\" sets the output's scale from the data; it \
                     cannot be combined with `sigma`"
                        .into(),
                );
            }
            "variance" => OutputScale::Variance,
            other => {
                return at.error(
                    scale.span(),
                    field,
                    format!("unknown scale `{other}` (known: none, variance)"),
                );
            }
        },
    };
    Ok(scale)
}

pub(super) fn resolve_inputs(
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
