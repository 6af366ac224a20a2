//! Effects defined by a formula in the Campaign message (`defined_effects`) and in the
//! campaign file (`[[effects]]` entries with a `formula`), both ways. In the file they follow
//! the built-in effects made free (`effects`), in the message's order.

use calib_proto::v1 as pb;
use toml::{Table, Value};

/// Whether an `[[effects]]` entry defines an effect (rather than freeing a built-in one):
/// the loader's rule.
pub fn is_defined(entry: &Table) -> bool {
    ["formula", "torque", "output"]
        .iter()
        .any(|k| entry.contains_key(*k))
}

/// The `[[effects]]` entries of `list`.
pub fn tables(list: &[pb::DefinedEffect]) -> Vec<Value> {
    list.iter().map(|e| Value::Table(table(e))).collect()
}

fn table(e: &pb::DefinedEffect) -> Table {
    let mut t = Table::new();
    t.insert("name".into(), e.name.clone().into());
    if !e.torque.is_empty() {
        t.insert("torque".into(), e.torque.clone().into());
    }
    if !e.output.is_empty() {
        t.insert("output".into(), e.output.clone().into());
    }
    t.insert("formula".into(), e.formula.clone().into());
    let parameters: Vec<Value> = e
        .parameters
        .iter()
        .map(|p| {
            let mut t = Table::new();
            t.insert("name".into(), p.name.clone().into());
            if let Some(n) = p.nominal {
                t.insert("nominal".into(), n.into());
            }
            t.insert("min".into(), p.min.into());
            t.insert("max".into(), p.max.into());
            if p.fixed {
                t.insert("fixed".into(), true.into());
            }
            Value::Table(t)
        })
        .collect();
    t.insert("parameters".into(), parameters.into());
    if e.fixed {
        t.insert("fixed".into(), true.into());
    }
    t
}

/// The messages of the entries of `list` that define an effect ([`is_defined`]).
pub fn messages(list: &[Table]) -> Vec<pb::DefinedEffect> {
    list.iter()
        .filter(|t| is_defined(t))
        .map(|t| pb::DefinedEffect {
            name: string(t, "name"),
            torque: string(t, "torque"),
            output: string(t, "output"),
            formula: string(t, "formula"),
            parameters: t
                .get("parameters")
                .and_then(Value::as_array)
                .map(|a| {
                    a.iter()
                        .filter_map(Value::as_table)
                        .map(|p| pb::DefinedEffectParameter {
                            name: string(p, "name"),
                            nominal: float(p, "nominal"),
                            min: float(p, "min").unwrap_or_default(),
                            max: float(p, "max").unwrap_or_default(),
                            fixed: flag(p, "fixed"),
                        })
                        .collect()
                })
                .unwrap_or_default(),
            fixed: flag(t, "fixed"),
        })
        .collect()
}

/// The effects an `[[effects]]` block defines (what discovery proposes, as it prints it).
pub fn from_block(text: &str) -> Result<Vec<pb::DefinedEffect>, String> {
    let root: Table = text.parse().map_err(|e| format!("{e}"))?;
    let entries: Vec<Table> = root
        .get("effects")
        .and_then(Value::as_array)
        .map(|a| a.iter().filter_map(Value::as_table).cloned().collect())
        .unwrap_or_default();
    Ok(messages(&entries))
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

fn string(t: &Table, k: &str) -> String {
    t.get(k)
        .and_then(Value::as_str)
        .map(str::to_string)
        .unwrap_or_default()
}

fn float(t: &Table, k: &str) -> Option<f64> {
    t.get(k)
        .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|i| i as f64)))
}

fn flag(t: &Table, k: &str) -> bool {
    t.get(k).and_then(Value::as_bool).unwrap_or(false)
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
        let mut root = Table::new();
        root.insert("effects".into(), tables(&defined).into());
        assert_eq!(
            from_block(&toml::to_string(&root).unwrap()).unwrap(),
            defined
        );
    }

    /// A campaign file's built-in and defined effects travel through the message (as
    /// `calib submit` sends them) into a campaign file that resolves to the same campaign.
    #[test]
    fn defined_effects_survive_the_message() {
        use crate::api::spec::{campaign_file, campaign_message};
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
        let file = campaign_file(&message, Path::new("/data/x.csv"), "time").unwrap();
        let back = Campaign::parse(&file, Path::new("/srv/c.toml")).unwrap();
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
