//! Discovery on a campaign: the joints of its model, the record from its measurement
//! mapping, and a proposal as a user-defined effect of the campaign (never added to its
//! file), with the terms that duplicate the campaign's own parameters folded into them.

use super::residual::regrid;
use super::{DiscoveredEffect, FurutaJoints, JointModel, Record};
use calib_engine::campaign::Campaign;
use calib_engine::error::{Error, Result};
use calib_engine::measurement::Measurement;

/// The model of `campaign` as joints discovery can invert, at the full parameter vector
/// `params`; `Err` says why discovery is not available for it.
pub fn joint_model(campaign: &Campaign, params: Vec<f64>) -> Result<Box<dyn JointModel>> {
    let name = &campaign.model.info().name;
    if name != "furuta" {
        return Err(Error::InvalidRequest(format!(
            "discovery is not available for model `{name}`: only `furuta` gives its joints' \
             equations of motion (mass matrix, forces, Coulomb levels)"
        )));
    }
    if !campaign.model.user_effects().is_empty() {
        return Err(Error::InvalidRequest(
            "discovery does not take the campaign's own [[effects]] formulas into its \
             inverse dynamics yet: remove them (or fold them into the model's parameters) \
             before discovering"
                .into(),
        ));
    }
    Ok(Box::new(FurutaJoints { params }))
}

/// The record discovery reads: the samples of `measurement` inside `campaign`'s window,
/// the model's angles from the outputs mapped to them, its inputs from the inputs mapped
/// to them (zero where a model input is not driven by the record).
pub fn record_of(
    campaign: &Campaign,
    measurement: &Measurement,
    model: &dyn JointModel,
) -> Result<Record> {
    let (lo, hi) = campaign.window;
    let rows: Vec<usize> = (0..measurement.time.len())
        .filter(|&i| measurement.time[i] >= lo && measurement.time[i] <= hi)
        .collect();
    let column = |measured: &str| -> Option<Vec<f64>> {
        let (_, values) = measurement.columns.iter().find(|(n, _)| n == measured)?;
        Some(rows.iter().map(|&i| values[i]).collect())
    };
    let mut angles = Vec::new();
    for angle in model.state_names().0 {
        let mapped = campaign.outputs.iter().find(|o| o.model == angle);
        let Some(series) = mapped.and_then(|o| column(&o.measured)) else {
            return Err(Error::InvalidRequest(format!(
                "discovery needs the measured angle `{angle}`: map it in [[outputs]] \
                 (model = \"{angle}\") of {}",
                source_of(campaign)
            )));
        };
        angles.push(series);
    }
    let inputs = model
        .input_names()
        .iter()
        .map(|input| {
            let mapped = campaign.inputs.iter().find(|i| &i.model == input);
            mapped
                .and_then(|i| column(&i.measured))
                .unwrap_or_else(|| vec![0.0; rows.len()])
        })
        .collect::<Vec<_>>();
    // A real record's clock is never exactly uniform: on a grid of its own step.
    let time: Vec<f64> = rows.iter().map(|&i| measurement.time[i]).collect();
    let joints = angles.len();
    let series: Vec<Vec<f64>> = angles.into_iter().chain(inputs).collect();
    let (time, mut series, resampled) = regrid(&time, &series).map_err(|e| {
        Error::InvalidRequest(format!("{e} (in the window of {})", source_of(campaign)))
    })?;
    if resampled {
        tracing::info!(
            "discovery: the record's samples are not evenly spaced; interpolated on a uniform grid"
        );
    }
    let inputs = series.split_off(joints);
    Ok(Record {
        time,
        angles: series,
        inputs,
    })
}

fn source_of(campaign: &Campaign) -> String {
    campaign
        .source
        .as_ref()
        .map_or_else(|| "the campaign".into(), |p| p.display().to_string())
}

/// `campaign` with `effect` added as a user-defined effect, its parameters free within the
/// proposal's bounds; the campaign's free parameters start at `start` (clamped to their
/// bounds), the effect's at the proposal's estimates. Windows, search and fixed values are
/// `campaign`'s.
pub fn with_discovered(
    campaign: &Campaign,
    start: &[f64],
    effect: &DiscoveredEffect,
) -> Result<Campaign> {
    let text = format!("{}\n\n{}", campaign.spec.trim_end(), effect.to_toml());
    let path = campaign
        .source
        .clone()
        .unwrap_or_else(|| "campaign.toml".into());
    let parsed = Campaign::parse(&text, &path).map_err(|e| {
        Error::InvalidRequest(format!("the proposal does not fit the campaign: {e}"))
    })?;
    let n = campaign.base.len();
    if parsed.base.len() < n {
        return Err(Error::InvalidRequest(
            "the campaign with the proposal has fewer parameters than without it".into(),
        ));
    }
    let prefix = format!("{}.", effect.name);
    let added: Vec<_> = parsed
        .free
        .iter()
        .filter(|p| p.effect && p.name.starts_with(&prefix))
        .cloned()
        .collect();
    let mut c = parsed;
    c.base[..n].copy_from_slice(&campaign.base);
    c.free = campaign.free.clone();
    for (p, v) in c.free.iter_mut().zip(start) {
        p.nominal = v.clamp(p.min, p.max);
        c.base[p.index] = p.nominal;
    }
    c.free.extend(added);
    c.measurement_file = campaign.measurement_file.clone();
    c.window = campaign.window;
    c.windows = campaign.windows.clone();
    c.stop_time = campaign.stop_time;
    c.search = campaign.search.clone();
    c.search.extra_starts.clear();
    c.diagnosis = campaign.diagnosis.clone();
    Ok(c)
}

/// The campaign parameter a term of the library duplicates: the model subtracts the joint's
/// Coulomb friction `F·sign(ω)`, so a term `c·sign(ω)` is that friction off by `−c`.
fn duplicated(function: &str) -> Option<&'static str> {
    match function {
        "sign(armJoint.w)" => Some("armFriction"),
        "sign(pendulumJoint.w)" => Some("pendulumFriction"),
        _ => None,
    }
}

/// What a proposal leaves once the terms that duplicate free parameters of the campaign are
/// folded into them: the effect with the other terms (`None` when nothing is left), the
/// start point with those parameters moved, and the folded terms' functions.
pub fn fold_duplicates(
    campaign: &Campaign,
    start: &[f64],
    effect: &DiscoveredEffect,
) -> (Option<DiscoveredEffect>, Vec<f64>, Vec<String>) {
    let mut start = start.to_vec();
    let mut folded = Vec::new();
    let mut kept = Vec::new();
    for term in &effect.terms {
        let free = duplicated(&term.function)
            .and_then(|name| campaign.free.iter().position(|p| p.name == name));
        match free {
            Some(k) if k < start.len() => {
                start[k] -= term.estimate;
                folded.push(term.function.clone());
            }
            _ => kept.push(term.clone()),
        }
    }
    if folded.is_empty() {
        return (Some(effect.clone()), start, folded);
    }
    if kept.is_empty() {
        return (None, start, folded);
    }
    let formula = kept
        .iter()
        .map(|t| {
            if t.function == "1" {
                t.parameter.clone()
            } else {
                format!("{} * {}", t.parameter, t.function)
            }
        })
        .collect::<Vec<_>>()
        .join(" + ");
    let parameters = effect
        .parameters
        .iter()
        .filter(|p| kept.iter().any(|t| t.parameter == p.name))
        .cloned()
        .collect();
    let effect = DiscoveredEffect {
        formula,
        parameters,
        terms: kept,
        ..effect.clone()
    };
    (Some(effect), start, folded)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::diagnosis::discovery::{EffectParameter, FoundTerm};
    use std::path::Path;

    fn example(name: &str) -> Campaign {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
        Campaign::load(&dir.join(name)).unwrap()
    }

    fn term(parameter: &str, function: &str, estimate: f64) -> FoundTerm {
        FoundTerm {
            function: function.into(),
            parameter: parameter.into(),
            estimate,
            ci_low: estimate - 1e-4,
            ci_high: estimate + 1e-4,
        }
    }

    #[test]
    fn other_models_say_discovery_is_not_available() {
        let c = example("hx.toml");
        let e = joint_model(&c, c.base.clone()).err().unwrap().to_string();
        assert!(e.contains("not available for model `hx"), "{e}");
        assert!(joint_model(&example("furuta.toml"), vec![]).is_ok());
    }

    #[test]
    fn a_sign_term_is_folded_into_the_free_friction() {
        let c = example("furuta.toml");
        let k = c.free.iter().position(|p| p.name == "armFriction").unwrap();
        let start = c.nominal();
        let parameter = |name: &str, nominal: f64| EffectParameter {
            name: name.into(),
            nominal,
            min: nominal - 1e-3,
            max: nominal + 1e-3,
        };
        let effect = DiscoveredEffect {
            name: "discovered.armJoint".into(),
            place: "armJoint".into(),
            formula: "c1 * sign(armJoint.w) + a1 * sin(8 * armJoint.phi)".into(),
            parameters: vec![parameter("c1", -0.002), parameter("a1", 0.006)],
            terms: vec![
                term("c1", "sign(armJoint.w)", -0.002),
                term("a1", "sin(8 * armJoint.phi)", 0.006),
            ],
            harmonics: vec![],
        };
        let (kept, moved, folded) = fold_duplicates(&c, &start, &effect);
        let kept = kept.unwrap();
        assert_eq!(folded, ["sign(armJoint.w)"]);
        assert_eq!(kept.formula, "a1 * sin(8 * armJoint.phi)");
        assert_eq!(kept.parameters.len(), 1);
        assert_eq!(moved[k], start[k] + 0.002);
        // The campaign with the rest: its parameters then the effect's, free.
        let with = with_discovered(&c, &moved, &kept).unwrap();
        let names: Vec<_> = with.free.iter().map(|p| p.name.as_str()).collect();
        assert_eq!(names.last(), Some(&"discovered.armJoint.a1"));
        assert_eq!(with.free.len(), c.free.len() + 1);
        assert_eq!(
            with.base[with.free[k].index],
            moved[k].clamp(c.free[k].min, c.free[k].max)
        );
        assert_eq!(with.window, c.window);
    }
}
