//! Effects defined by a formula in the Campaign message (`defined_effects`) and in the
//! campaign (`[[effects]]` entries with a `formula`), both ways. In the campaign they follow
//! the built-in effects made free (`effects`), in the message's order.

use calib_engine::campaign::spec::{at, EffectEntry, UserParameterEntry};
use calib_engine::campaign::Scale;
use calib_proto::v1 as pb;

/// Whether an `[[effects]]` entry defines an effect (rather than freeing a built-in one):
/// the loader's rule.
pub fn is_defined(entry: &EffectEntry) -> bool {
    entry.formula.is_some() || entry.torque.is_some() || entry.output.is_some()
}

/// The `[[effects]]` entry of a definition.
pub fn entry(e: &pb::DefinedEffect) -> EffectEntry {
    let place = |s: &String| Some(s.clone()).filter(|s| !s.is_empty()).map(at);
    EffectEntry {
        name: at(e.name.clone()),
        nominal: None,
        min: None,
        max: None,
        scale: Scale::default(),
        torque: place(&e.torque),
        output: place(&e.output),
        formula: Some(at(e.formula.clone())),
        parameters: Some(
            e.parameters
                .iter()
                .map(|p| {
                    at(UserParameterEntry {
                        name: p.name.clone(),
                        nominal: p.nominal,
                        min: p.min,
                        max: p.max,
                        fixed: p.fixed.then_some(true),
                    })
                })
                .collect(),
        ),
        fixed: e.fixed.then_some(true),
    }
}

/// The message of an entry that defines an effect ([`is_defined`]).
pub fn message(e: &EffectEntry) -> pb::DefinedEffect {
    let text = |s: &Option<toml::Spanned<String>>| {
        s.as_ref().map(|s| s.get_ref().clone()).unwrap_or_default()
    };
    pb::DefinedEffect {
        name: e.name.get_ref().clone(),
        torque: text(&e.torque),
        output: text(&e.output),
        formula: text(&e.formula),
        parameters: e
            .parameters
            .iter()
            .flatten()
            .map(|p| {
                let p = p.get_ref();
                pb::DefinedEffectParameter {
                    name: p.name.clone(),
                    nominal: p.nominal,
                    min: p.min,
                    max: p.max,
                    fixed: p.fixed.unwrap_or(false),
                }
            })
            .collect(),
        fixed: e.fixed.unwrap_or(false),
    }
}

/// The effects an `[[effects]]` block defines (what discovery proposes, as it prints it).
pub fn from_block(text: &str) -> Result<Vec<pb::DefinedEffect>, String> {
    #[derive(serde::Deserialize)]
    struct Block {
        #[serde(default)]
        effects: Vec<EffectEntry>,
    }
    let block: Block = toml::from_str(text).map_err(|e| format!("{e}"))?;
    Ok(block
        .effects
        .iter()
        .filter(|e| is_defined(e))
        .map(message)
        .collect())
}

/// A field of the campaign file's `[[effects]]` as the message names it: the entries past
/// the built-in effects of `c` are its `defined_effects` ("effects[2].formula" of a
/// campaign with one built-in effect is "defined_effects[1].formula"); other fields as
/// they are.
pub fn message_field(c: &pb::Campaign, field: &str) -> String {
    let Some(rest) = field.strip_prefix("effects[") else {
        return field.to_string();
    };
    let Some((index, tail)) = rest.split_once(']') else {
        return field.to_string();
    };
    match index.parse::<usize>() {
        Ok(k) if k >= c.effects.len() => {
            format!("defined_effects[{}]{tail}", k - c.effects.len())
        }
        _ => field.to_string(),
    }
}

/// A refusal of the campaign's loader ("campaign.<field>: <what>") with its field as the
/// message names it ([`message_field`]).
pub fn refusal_in_message_fields(c: &pb::Campaign, status: tonic::Status) -> tonic::Status {
    let Some((field, what)) = status
        .message()
        .strip_prefix("campaign.")
        .and_then(|rest| rest.split_once(": "))
    else {
        return status;
    };
    let named = message_field(c, field);
    if named == field {
        return status;
    }
    tonic::Status::new(status.code(), format!("campaign.{named}: {what}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_block_reads_into_messages_and_back_into_the_same_entries() {
        let block = r#"
[[effects]]
name = "cogging.arm"
torque = "armJoint"
formula = "a * sin(k * armJoint.phi)"
parameters = [ { name = "a", nominal = 0.006, min = -0.02, max = 0.02 },
               { name = "k", nominal = 8, min = 1, max = 40, fixed = true } ]
[[effects]]
name = "viscous_friction.arm"
min = 0.0
max = 0.1
"#;
        let defined = from_block(block).unwrap();
        assert_eq!(defined.len(), 1, "the built-in effect is not a definition");
        let e = &defined[0];
        assert_eq!((e.torque.as_str(), e.output.as_str()), ("armJoint", ""));
        assert_eq!(e.parameters[0].nominal, Some(0.006));
        assert_eq!(e.parameters[1].nominal, Some(8.0));
        assert!(e.parameters[1].fixed && !e.parameters[0].fixed && !e.fixed);
        #[derive(serde::Serialize)]
        struct Block {
            effects: Vec<EffectEntry>,
        }
        let block = Block {
            effects: defined.iter().map(entry).collect(),
        };
        assert_eq!(
            from_block(&toml::to_string(&block).unwrap()).unwrap(),
            defined
        );
    }

    /// A campaign file's built-in and defined effects travel through the message (as
    /// `calib submit` sends them) into a campaign file that resolves to the same campaign.
    #[test]
    fn defined_effects_survive_the_message() {
        use crate::api::spec::{campaign_message, campaign_spec};
        use calib_engine::campaign::Campaign;
        use std::path::Path;
        let text = r#"
[model]
name = "furuta"
[measurement]
file = "/data/x.csv"
time_column = "time"
[window]
start = 0.0
stop = 10.0
[[outputs]]
model = "armJoint.phi"
measured = "arm"
[[parameters]]
name = "armFriction"
min = 0.0
max = 0.9
[[effects]]
name = "viscous_friction.arm"
min = 0.0
max = 0.1
[[effects]]
name = "cogging.arm"
torque = "armJoint"
formula = "a * sin(k * armJoint.phi)"
parameters = [ { name = "a", nominal = 0.001, min = -0.02, max = 0.02 },
               { name = "k", nominal = 8, min = 1, max = 40, fixed = true } ]
"#;
        let message = campaign_message(text, "d").unwrap();
        assert_eq!(message.effects.len(), 1);
        assert_eq!(message.defined_effects.len(), 1);
        assert_eq!(
            message.defined_effects[0].formula,
            "a * sin(k * armJoint.phi)"
        );
        let spec = campaign_spec(&message, Path::new("/data/x.csv"), "time").unwrap();
        let back = Campaign::from_spec(spec, Path::new("/srv/c.toml")).unwrap();
        let file = back.spec.clone();
        let original = Campaign::parse(text, Path::new("/c/x.toml")).unwrap();
        assert_eq!(back.free, original.free);
        assert_eq!(back.base, original.base);
        assert_eq!(
            back.model.user_effects(),
            original.model.user_effects(),
            "the same definitions"
        );
        assert_eq!(campaign_message(&file, "d").unwrap(), message);
    }

    #[test]
    fn fields_past_the_built_in_effects_are_the_defined_ones() {
        let c = pb::Campaign {
            effects: vec![pb::Parameter::default()],
            ..Default::default()
        };
        assert_eq!(message_field(&c, "effects[0].min"), "effects[0].min");
        assert_eq!(
            message_field(&c, "effects[2].parameters[1].nominal"),
            "defined_effects[1].parameters[1].nominal"
        );
        assert_eq!(message_field(&c, "window_stop"), "window_stop");
    }
}
