//! Two records fitted together on the page, the second driven by a measured input.

use super::*;

/// Two Furuta records fitted together on the page, the second driven by its measured arm
/// torque (mapped to the model's `armTorque` input, with its own start angle and window)
/// give the values `calib calibrate` gives the same campaign file, bit for bit; the results
/// show each experiment's fits, the driven one's input above them. The Model tab simulates
/// the model driven by the uploaded torque column.
#[test]
fn experiments_with_a_driven_input_on_the_page_give_the_values_of_calib_calibrate() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let swing = common::furuta_record(
        &dir.path().join("swing.csv"),
        std::f64::consts::FRAC_PI_6,
        10.0,
        3,
        None,
    );
    let driven = common::furuta_record(
        &dir.path().join("driven.csv"),
        0.2,
        10.0,
        4,
        Some(&common::arm_torque),
    );
    // The campaign the page is filled in with, as a file.
    let campaign = common::write(
        dir.path(),
        "pair.toml",
        &format!(
            r#"
name = "pair"
[model]
name = "furuta"
[model.parameters]
theta0 = 0.5235987755983
{}{}[[experiments]]
name = "swing"
file = "{}"
time_column = "time_s"
window = {{ start = 0.0, stop = 10.0 }}
[[experiments]]
name = "driven"
file = "{}"
time_column = "time_s"
window = {{ start = 0.0, stop = 10.0 }}
fixed = {{ theta0 = 0.2 }}
inputs = [ {{ model = "armTorque", measured = "motor_torque_Nm", interpolation = "linear" }} ]
[search]
methods = ["nelder-mead"]
starts = 2
max_evaluations = 150
seed = 1
"#,
            common::FURUTA_OUTPUTS,
            common::FURUTA_FRICTIONS,
            swing.display(),
            driven.display()
        ),
    );
    let reference = common::calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--json",
        "--out",
        dir.path().join("out").to_str().unwrap(),
        "--db",
        dir.path().join("cli-db").to_str().unwrap(),
    ]);
    assert!(
        reference.status.success(),
        "{}",
        String::from_utf8_lossy(&reference.stderr)
    );
    let reference_text = String::from_utf8(reference.stdout).unwrap();

    let ui = Ui::start(&dir.path().join("ui-db"));
    let shots = match std::env::var_os("CALIB_SCREENSHOTS") {
        Some(folder) => repo().join(folder),
        None => std::path::PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("screenshots"),
    };
    std::fs::create_dir_all(&shots).unwrap();
    let page = drive(
        "experiments",
        &[
            &ui.url,
            swing.to_str().unwrap(),
            driven.to_str().unwrap(),
            shots.to_str().unwrap(),
        ],
        dir.path(),
    );
    println!("{page:#}");
    // The first record has no torque column to drive the input with.
    assert_eq!(
        page["first_input_choices"],
        serde_json::json!(["", "arm_angle_rad", "pendulum_angle_rad"])
    );
    // The Model tab drives the input by the uploaded column: its plot above the outputs',
    // and an arm that moves otherwise than undriven.
    let model = &page["model"];
    assert_eq!(
        model["driven"][0], "input armTorque driven by motor_torque_Nm",
        "{model}"
    );
    assert!(!model["undriven"].to_string().contains("input"), "{model}");
    assert_eq!(model["arm_differs"], true, "{model}");
    assert_eq!(model["overlaid_previous"], true, "{model}");
    let (arm, pendulum) = common::true_frictions();
    for (name, truth) in [("armFriction", arm), ("pendulumFriction", pendulum)] {
        let expected = best_parameter(&reference_text, name);
        let shown: f64 = page["calibrated"][name].as_str().unwrap().parse().unwrap();
        assert_eq!(
            shown.to_bits(),
            expected.to_bits(),
            "{name}: page {shown} vs calibrate {expected}"
        );
        assert!(
            (shown / truth - 1.0).abs() < 0.02,
            "{name}: {shown} vs {truth}"
        );
    }
    assert!(
        page["status"].as_str().unwrap().contains("finished"),
        "{page}"
    );
    // Each experiment's plots, the driven one's input first.
    let swing_plots = page["groups"]["Experiment swing"].to_string();
    for output in ["armJoint.phi", "pendulumJoint.phi"] {
        assert!(swing_plots.contains(output), "{swing_plots}");
    }
    let driven_plots: Vec<&str> = page["groups"]["Experiment driven"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| c.as_str().unwrap())
        .collect();
    assert_eq!(driven_plots.len(), 3, "{driven_plots:?}");
    assert!(
        driven_plots[0].starts_with("driven: input armTorque"),
        "{driven_plots:?}"
    );
    assert!(page["plots"].to_string().contains("waterfall"), "{page}");
}
