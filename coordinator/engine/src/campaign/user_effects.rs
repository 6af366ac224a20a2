//! `[[effects]]` entries: a built-in effect made free (`name`, `min`, `max`), or an effect
//! defined by a formula (`formula` with `torque` or `output`, and its `parameters`), which
//! is checked and compiled against the model here and becomes part of it.

use super::resolve::Locator;
use super::spec::{EffectEntry, ParameterEntry};
use super::{CampaignError, FreeParameter, Scale};
use calib_model::user_effects::{self, place_of, UserEffect, UserParameter};
use calib_model::{Model, ModelInfo};
use toml::Spanned;

/// The entries split: built-in effects made free (with their index in the list), and the
/// definitions with whether each parameter is fixed.
pub(super) struct Split {
    pub(super) builtin: Vec<(usize, Spanned<ParameterEntry>)>,
    pub(super) defined: Vec<(usize, Spanned<EffectEntry>)>,
}

/// Sort `[[effects]]` into built-in ones and definitions; a built-in one needs its bounds.
pub(super) fn split(
    entries: Vec<Spanned<EffectEntry>>,
    at: &Locator,
) -> Result<Split, CampaignError> {
    let mut split = Split {
        builtin: Vec::new(),
        defined: Vec::new(),
    };
    for (i, entry) in entries.into_iter().enumerate() {
        let e = entry.get_ref();
        let defines = e.formula.is_some() || e.torque.is_some() || e.output.is_some();
        if defines {
            let field = format!("effects[{i}].formula");
            if e.formula.is_none() {
                return at.error(entry.span(), &field, "the effect needs a `formula`".into());
            }
            for (key, given) in [("min", e.min.is_some()), ("max", e.max.is_some())] {
                if given {
                    return at.error(
                        entry.span(),
                        &format!("effects[{i}].{key}"),
                        "an effect defined by a formula has bounds on each of its \
                         `parameters`, not its own"
                            .into(),
                    );
                }
            }
            split.defined.push((i, entry));
            continue;
        }
        let span = entry.span();
        let e = entry.into_inner();
        let name = e.name.get_ref().clone();
        let (Some(min), Some(max)) = (e.min, e.max) else {
            return at.error(
                span,
                &format!("effects[{i}] ({name})"),
                "needs `min` and `max` (or a `formula` with `torque` or `output` to define \
                 an effect)"
                    .into(),
            );
        };
        if e.parameters.is_some() || e.fixed.is_some() {
            return at.error(
                span,
                &format!("effects[{i}] ({name})"),
                "`parameters` and `fixed` belong to an effect defined by a `formula`".into(),
            );
        }
        let parameter = ParameterEntry {
            name: e.name,
            nominal: e.nominal,
            min,
            max,
            scale: e.scale,
        };
        split.builtin.push((i, Spanned::new(span, parameter)));
    }
    Ok(split)
}

/// The definitions as the model takes them.
fn definitions(
    defined: &[(usize, Spanned<EffectEntry>)],
    at: &Locator,
) -> Result<Vec<UserEffect>, CampaignError> {
    let mut out = Vec::new();
    for (i, entry) in defined {
        let e = entry.get_ref();
        let torque = e.torque.as_ref().map(|s| s.get_ref().as_str());
        let output = e.output.as_ref().map(|s| s.get_ref().as_str());
        let (kind, place) = place_of(*i, torque, output)
            .or_else(|err| at.error(entry.span(), &err.field, err.message))?;
        out.push(UserEffect {
            name: e.name.get_ref().clone(),
            kind,
            place,
            formula: e
                .formula
                .as_ref()
                .map(|f| f.get_ref().clone())
                .unwrap_or_default(),
            parameters: e
                .parameters
                .iter()
                .flatten()
                .map(|p| {
                    let p = p.get_ref();
                    UserParameter {
                        name: p.name.clone(),
                        nominal: p.nominal.unwrap_or(0.0),
                        min: p.min,
                        max: p.max,
                    }
                })
                .collect(),
        });
    }
    Ok(out)
}

/// The line a refusal of the definitions is about: the entry's, or its parameter's.
fn span_of(defined: &[(usize, Spanned<EffectEntry>)], field: &str) -> std::ops::Range<usize> {
    let index = |s: &str| s.split(']').next().and_then(|n| n.parse::<usize>().ok());
    let rest = field.strip_prefix("effects[").unwrap_or("");
    let Some((_, entry)) = index(rest).and_then(|i| defined.iter().find(|(k, _)| *k == i)) else {
        return 0..0;
    };
    let e = entry.get_ref();
    let parameter = rest
        .split_once("parameters[")
        .and_then(|(_, p)| index(p))
        .and_then(|j| e.parameters.as_ref()?.get(j));
    if let Some(p) = parameter {
        return p.span();
    }
    match rest.split_once("].").map(|(_, what)| what) {
        Some("formula") => e.formula.as_ref().map(Spanned::span),
        Some("torque") => e.torque.as_ref().map(Spanned::span),
        Some("output") => e.output.as_ref().map(Spanned::span),
        Some("name") => Some(e.name.span()),
        _ => None,
    }
    .unwrap_or_else(|| entry.span())
}

/// `model` with the defined effects, checked and compiled.
pub(super) fn attach(
    model: &'static dyn Model,
    defined: &[(usize, Spanned<EffectEntry>)],
    at: &Locator,
) -> Result<&'static dyn Model, CampaignError> {
    if defined.is_empty() {
        return Ok(model);
    }
    let effects = definitions(defined, at)?;
    // The model's own mistakes name `effects[k]` by the definition's place among the
    // definitions; the file's list may mix in built-in effects.
    user_effects::attach(model, &effects).or_else(|err| {
        let k: usize = err
            .field
            .strip_prefix("effects[")
            .and_then(|r| r.split(']').next())
            .and_then(|n| n.parse().ok())
            .unwrap_or(0);
        let i = defined.get(k).map_or(k, |(i, _)| *i);
        let field = err
            .field
            .replacen(&format!("effects[{k}]"), &format!("effects[{i}]"), 1);
        at.error(span_of(defined, &field), &field, err.message)
    })
}

/// The defined effects' parameters at their nominal values in `base` (unless fixed in
/// `[model.parameters]`), and those not marked `fixed` as free parameters.
pub(super) fn free_parameters(
    defined: &[(usize, Spanned<EffectEntry>)],
    info: &ModelInfo,
    fixed: &[usize],
    base: &mut [f64],
) -> Vec<FreeParameter> {
    let mut free = Vec::new();
    for (_, entry) in defined {
        let e = entry.get_ref();
        for p in e.parameters.iter().flatten() {
            let p = p.get_ref();
            let name = format!("{}.{}", e.name.get_ref(), p.name);
            let index = info
                .parameter_index(&name)
                .expect("the model has the effect's parameters");
            if fixed.contains(&index) {
                continue;
            }
            let nominal = p.nominal.unwrap_or(0.0);
            base[index] = nominal;
            if p.fixed.or(e.fixed).unwrap_or(false) {
                continue;
            }
            free.push(FreeParameter {
                name,
                index,
                nominal,
                min: p.min,
                max: p.max,
                effect: true,
                scale: Scale::Lin,
                experiment: None,
            });
        }
    }
    free
}
