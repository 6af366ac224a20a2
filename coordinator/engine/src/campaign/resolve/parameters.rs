//! The free parameters: `[[parameters]]` and built-in `[[effects]]` entries, each checked
//! against the model, its bounds and what else the campaign frees or fixes.

use super::super::spec::ParameterEntry;
use super::super::{CampaignError, FreeParameter, Scale};
use super::Locator;
use calib_model::validate;
use calib_model::ModelInfo;
use toml::Spanned;

/// Free parameters, then free effects (`effects`: each with its place in the file's
/// list), each set to its nominal value in `base`, then the parameters of effects defined
/// by a formula (`defined`, set already).
#[allow(clippy::too_many_arguments)]
pub(super) fn resolve_free(
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
        let p = entry.get_ref();
        let name = p.name.get_ref();
        let field = format!("{prefix}{section}[{i}] ({name})");
        let taken = Taken {
            free: &free,
            defined: &defined,
            fixed,
        };
        let index = index_of(entry, is_effect, &field, taken, info, at)?;
        let nominal = nominal_of(entry, index, is_effect, &field, base, info, at)?;
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

/// What a parameter cannot be freed by an entry for: listed already, free as a parameter
/// of its defined effect, or fixed.
struct Taken<'a> {
    free: &'a [FreeParameter],
    defined: &'a [FreeParameter],
    fixed: &'a [usize],
}

/// The model's index of the parameter (or effect) `entry` frees.
fn index_of(
    entry: &Spanned<ParameterEntry>,
    is_effect: bool,
    field: &str,
    taken: Taken,
    info: &ModelInfo,
    at: &Locator,
) -> Result<usize, CampaignError> {
    let span = entry.span();
    let p = entry.get_ref();
    let name = p.name.get_ref();
    if is_effect {
        if let Err(e) = validate::effect(info, name) {
            return at.error(p.name.span(), field, e.message);
        }
    }
    let index = match validate::parameter(info, name) {
        Ok(index) => index,
        Err(e) => return at.error(p.name.span(), field, e.message),
    };
    if taken.free.iter().any(|f| f.index == index) {
        return at.error(span, field, "is listed twice".into());
    }
    if taken.defined.iter().any(|f| f.index == index) {
        return at.error(
            span,
            field,
            "is free as a parameter of its effect already (mark it `fixed = true` there \
             to hold it)"
                .into(),
        );
    }
    if taken.fixed.contains(&index) {
        return at.error(
            span,
            field,
            "is both fixed in [model.parameters] and free here".into(),
        );
    }
    Ok(index)
}

/// The nominal value of the free parameter at `index` (the entry's, else 0 for an effect
/// and the value in `base` for a parameter), within the entry's bounds, which must suit the
/// model and its scale.
fn nominal_of(
    entry: &Spanned<ParameterEntry>,
    index: usize,
    is_effect: bool,
    field: &str,
    base: &[f64],
    info: &ModelInfo,
    at: &Locator,
) -> Result<f64, CampaignError> {
    let span = entry.span();
    let p = entry.get_ref();
    if let Err(e) = validate::bounds(info, index, p.min, p.max) {
        return at.error(span, field, e.message);
    }
    if p.scale == Scale::Log10 && p.min <= 0.0 {
        return at.error(
            span,
            field,
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
            field,
            format!(
                "nominal {nominal} is outside its bounds [{}, {}]",
                p.min, p.max
            ),
        );
    }
    Ok(nominal)
}
