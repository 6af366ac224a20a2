use super::*;

const TWO_EXPERIMENTS: &str = include_str!("testdata/two_experiments.json");

#[test]
fn result_json_reads_and_writes_back_byte_for_byte() {
    // Every field result.json has held, in its order, infinities written null.
    let outcome: CalibrationOutcome = serde_json::from_str(TWO_EXPERIMENTS).unwrap();
    assert_eq!(outcome.to_json_text(), TWO_EXPERIMENTS.trim_end());
    assert_eq!(outcome.runs[3].objective, f64::INFINITY);
    assert_eq!(outcome.clusters[2].kind, Stop::Failures);
    assert_eq!(
        outcome.best.at_bound.get("theta0@b"),
        Some(&Some(Bound::Max))
    );
    assert_eq!(outcome.best.at_bound.get("pendulumFriction"), Some(&None));
    assert_eq!(
        outcome.experiments[1].rms.names().next(),
        Some("pendulumJoint.phi")
    );
    assert_eq!(outcome.free_parameters[1].experiment.as_deref(), Some("b"));
}

#[test]
fn a_result_stored_before_the_version_field_reads_as_version_one() {
    let mut value: serde_json::Value = serde_json::from_str(TWO_EXPERIMENTS).unwrap();
    value.as_object_mut().unwrap().shift_remove("version");
    let outcome: CalibrationOutcome = serde_json::from_value(value).unwrap();
    assert_eq!(outcome.version, VERSION);
    let text = outcome.to_json_text();
    assert!(
        text.starts_with("{\n  \"version\": 1,\n  \"campaign\""),
        "{text}"
    );
}

#[test]
fn optional_parts_are_left_out_when_empty() {
    let mut outcome: CalibrationOutcome = serde_json::from_str(TWO_EXPERIMENTS).unwrap();
    outcome.inputs.clear();
    outcome.experiments.clear();
    outcome.window.windows.clear();
    let value = serde_json::to_value(&outcome).unwrap();
    for absent in ["inputs", "experiments"] {
        assert!(value.get(absent).is_none(), "{absent}");
    }
    assert!(value["window"].get("windows").is_none());
    assert_eq!(value["window"]["samples"], 4002);
}

#[test]
fn derived_figures_follow_the_summarys_rules() {
    let outcome: CalibrationOutcome = serde_json::from_str(TWO_EXPERIMENTS).unwrap();
    assert_eq!(outcome.at_best(), [true, false, true, false]);
    assert_eq!(
        outcome.at_best().iter().filter(|b| **b).count(),
        outcome.runs_at_best.count
    );
    assert_eq!(outcome.best_index(), 0);
    assert_eq!(outcome.from_store(), 812 - 790);
    assert_eq!(outcome.outputs(), ["armJoint.phi", "pendulumJoint.phi"]);
}

#[test]
fn a_name_given_twice_keeps_its_place_and_takes_the_last_value() {
    let named: Named<f64> = [("a".to_string(), 1.0), ("b".into(), 2.0), ("a".into(), 3.0)]
        .into_iter()
        .collect();
    assert_eq!(
        serde_json::to_string(&named).unwrap(),
        r#"{"a":3.0,"b":2.0}"#
    );
    assert_eq!(named.len(), 2);
}
