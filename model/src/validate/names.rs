//! Names a request uses: the model, its parameters and effects, its outputs. An unknown name
//! gets the nearest known one as a suggestion.

use super::{Invalid, Result};
use crate::{models, EffectSpec, Model, ModelInfo};

/// Similarity (Jaro–Winkler, case-insensitive) above which a known name is suggested.
const SUGGESTION_THRESHOLD: f64 = 0.8;

/// The known name nearest to `name`, if one is near enough to be a likely typo.
fn nearest<'a>(name: &str, known: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    let wanted = name.to_lowercase();
    known
        .into_iter()
        .map(|k| (strsim::jaro_winkler(&wanted, &k.to_lowercase()), k))
        .filter(|(score, _)| *score >= SUGGESTION_THRESHOLD)
        .max_by(|a, b| a.0.total_cmp(&b.0))
        .map(|(_, k)| k)
}

/// "; did you mean `x`?", or how to list the names when none is near.
pub(crate) fn hint<'a>(
    name: &str,
    known: impl IntoIterator<Item = &'a str>,
    listing: &str,
) -> String {
    match nearest(name, known) {
        Some(k) => format!("; did you mean `{k}`?"),
        None => format!(" ({listing})"),
    }
}

/// The hosted model called `name`.
pub fn model(name: &str) -> Result<&'static dyn Model> {
    models::find(name).ok_or_else(|| {
        let known = models::all().iter().map(|m| m.info().name.as_str());
        Invalid::new(format!(
            "unknown model `{name}`{}",
            hint(name, known, "`calib models` lists the hosted models")
        ))
    })
}

fn listing(info: &ModelInfo, what: &str) -> String {
    format!("`calib models {}` lists its {what}", info.name)
}

/// Index of the base parameter or effect `name` in the model's full parameter vector.
pub fn parameter(info: &ModelInfo, name: &str) -> Result<usize> {
    info.parameter_index(name).ok_or_else(|| {
        let known = info
            .parameters
            .iter()
            .map(|p| p.name.as_str())
            .chain(info.effects.iter().map(|e| e.name.as_str()));
        Invalid::new(format!(
            "model `{}` has no parameter `{name}`{}",
            info.name,
            hint(name, known, &listing(info, "parameters and effects"))
        ))
    })
}

/// The effect called `name`.
pub fn effect<'a>(info: &'a ModelInfo, name: &str) -> Result<&'a EffectSpec> {
    info.effect(name).ok_or_else(|| {
        let known = info.effects.iter().map(|e| e.name.as_str());
        Invalid::new(format!(
            "model `{}` has no effect `{name}`{}",
            info.name,
            hint(name, known, &listing(info, "effects"))
        ))
    })
}

/// Index of the input `name`.
pub fn input(info: &ModelInfo, name: &str) -> Result<usize> {
    info.input_index(name).ok_or_else(|| {
        if info.inputs.is_empty() {
            return Invalid::new(format!(
                "model `{}` takes no input, so none can be `{name}`",
                info.name
            ));
        }
        let known = info.inputs.iter().map(|i| i.name.as_str());
        Invalid::new(format!(
            "model `{}` has no input `{name}`{}",
            info.name,
            hint(name, known, &listing(info, "inputs"))
        ))
    })
}

/// Index of the output `name`.
pub fn output(info: &ModelInfo, name: &str) -> Result<usize> {
    info.output_index(name).ok_or_else(|| {
        let known = info.outputs.iter().map(|o| o.name.as_str());
        Invalid::new(format!(
            "model `{}` has no output `{name}`{}",
            info.name,
            hint(name, known, &listing(info, "outputs"))
        ))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn furuta() -> &'static ModelInfo {
        model("furuta").unwrap().info()
    }

    #[test]
    fn a_typo_gets_the_nearest_name_and_not_the_whole_list() {
        let e = parameter(furuta(), "armFrict").unwrap_err();
        assert_eq!(
            e.message,
            "model `furuta` has no parameter `armFrict`; did you mean `armFriction`?"
        );
        let e = parameter(furuta(), "PendulumFriction").unwrap_err();
        assert!(
            e.message.ends_with("did you mean `pendulumFriction`?"),
            "{e}"
        );
        let e = effect(furuta(), "viscous_friction.arn").unwrap_err();
        assert!(
            e.message.ends_with("did you mean `viscous_friction.arm`?"),
            "{e}"
        );
        let e = output(furuta(), "pendulumJoint.ph").unwrap_err();
        assert!(
            e.message.ends_with("did you mean `pendulumJoint.phi`?"),
            "{e}"
        );
        let e = model("furtua").map(|_| ()).unwrap_err();
        assert_eq!(e.message, "unknown model `furtua`; did you mean `furuta`?");
    }

    #[test]
    fn a_name_near_nothing_says_where_the_names_are_listed() {
        let e = parameter(furuta(), "zzz").unwrap_err();
        assert_eq!(
            e.message,
            "model `furuta` has no parameter `zzz` (`calib models furuta` lists its \
             parameters and effects)"
        );
        assert!(!e.message.contains("armFriction"));
    }

    #[test]
    fn known_names_resolve() {
        assert_eq!(parameter(furuta(), "armFriction"), Ok(0));
        assert_eq!(output(furuta(), "armJoint.phi"), Ok(0));
        assert!(effect(furuta(), "coulomb_friction.arm").is_ok());
    }
}
