//! Advice that holds at the fit: `calib sensitivity` calls a parameter fixable only when it is
//! negligible both over its bounds (Sobol, Morris) and at the calibration's best point (the
//! local sensitivity of each output), and names the output that keeps it in.

use crate::common::*;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// `examples/furuta_viscous_arm.toml` (both frictions on linear [0, 0.9]) in `dir`, its record
/// read where the repository keeps it.
fn viscous_arm_campaign(dir: &Path) -> PathBuf {
    let text = std::fs::read_to_string(repo().join("examples/furuta_viscous_arm.toml"))
        .unwrap()
        .replace(
            "file = \"data/",
            &format!("file = \"{}/", repo().join("examples/data").display()),
        );
    assert!(text.contains("min = 0.0\nmax = 0.9"));
    write(dir, "furuta_viscous_arm.toml", &text)
}

fn sensitivity(campaign: &Path, db: &Path, out: &Path, extra: &[&str]) -> Value {
    let mut args = vec![
        "sensitivity",
        campaign.to_str().unwrap(),
        "--method",
        "sobol",
        "--samples",
        "128",
        "--db",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend_from_slice(extra);
    json_of(&calib(&args))
}

fn parameter<'a>(json: &'a Value, name: &str) -> &'a Value {
    json["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == name)
        .unwrap_or_else(|| panic!("{name} in {json}"))
}

/// Over linear bounds [0, 0.9] the arm sticks at every sampled point: the arm friction's total
/// index is 0 on the objective and on both outputs, and the box alone would call it fixable.
/// At the calibrated point the arm swings, and its friction is what the arm's angle hangs on.
#[test]
fn a_friction_negligible_over_linear_bounds_is_kept_for_the_arm_at_the_fit() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = viscous_arm_campaign(dir.path());
    let (db, out) = (dir.path().join("db"), dir.path().join("out"));

    // Before any calibration: the bounds alone.
    let over_box = sensitivity(&campaign, &db, &out, &[]);
    assert!(over_box["at_fit"].is_null(), "{}", over_box["at_fit"]);
    let arm = parameter(&over_box, "armFriction");
    assert!(arm["total"].as_f64().unwrap() < 0.01, "{arm}");
    for output in ["armJoint.phi", "pendulumJoint.phi"] {
        let total = arm["outputs"][output]["total"].as_f64().unwrap();
        assert!(total < 0.01, "{output}: {total}");
    }
    assert_eq!(over_box["fixable"], serde_json::json!(["armFriction"]));

    // Calibrate with the same store: its result is recorded there, and the next analysis
    // takes the local sensitivities at its best point.
    let result = calibrate_json(&campaign, &db, &out, &[]);
    let best = result["best"]["parameters"]["armFriction"]
        .as_f64()
        .unwrap();
    assert!(
        (best - 0.0101).abs() < 0.002,
        "armFriction at the fit {best}"
    );
    let at_fit = sensitivity(&campaign, &db, &out, &[]);
    println!("{}", at_fit["conclusion"]);
    assert_eq!(at_fit["at_fit"]["parameters"]["armFriction"], best);
    assert_eq!(at_fit["at_fit"]["simulated"], 4);
    let arm = parameter(&at_fit, "armFriction");
    let local = arm["at_fit"]["outputs"]["armJoint.phi"].as_f64().unwrap();
    assert!(
        local > 0.05,
        "armFriction's local index on armJoint.phi: {local}"
    );
    assert_eq!(arm["kept_at_fit"], "armJoint.phi");
    assert_eq!(arm["kept_for"], Value::Null, "not kept over the bounds");
    // The global indices are the store's, unchanged.
    assert_eq!(arm["total"], parameter(&over_box, "armFriction")["total"]);
    assert_eq!(at_fit["evaluations"]["simulated"], 0);
    assert_eq!(at_fit["fixable"], serde_json::json!([]));
    let conclusion = at_fit["conclusion"].as_str().unwrap();
    assert!(
        conclusion.starts_with("No parameter can be held fixed")
            && conclusion.contains("armFriction is kept for armJoint.phi at the fit"),
        "{conclusion}"
    );
    // The local indices of each quantity are shares: they sum to 1.
    for q in ["armJoint.phi", "pendulumJoint.phi"] {
        let sum: f64 = ["armFriction", "pendulumFriction"]
            .iter()
            .map(|p| {
                parameter(&at_fit, p)["at_fit"]["outputs"][q]
                    .as_f64()
                    .unwrap()
            })
            .sum();
        assert!((sum - 1.0).abs() < 1e-9, "{q}: {sum}");
    }

    // The same from the result file; and `--no-fit` judges over the bounds alone.
    let file = out.join("furuta_viscous_arm/result.json");
    let from_file = sensitivity(&campaign, &db, &out, &["--at", file.to_str().unwrap()]);
    assert_eq!(from_file["parameters"], at_fit["parameters"]);
    assert_eq!(from_file["at_fit"]["source"], file.to_str().unwrap());
    let without = sensitivity(&campaign, &db, &out, &["--no-fit"]);
    assert_eq!(without["fixable"], serde_json::json!(["armFriction"]));
}

#[test]
fn a_result_that_does_not_fit_the_campaign_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = viscous_arm_campaign(dir.path());
    let result = write(
        dir.path(),
        "other.json",
        r#"{"campaign": "other", "best": {"parameters": {"armFriction": 0.01}}}"#,
    );
    let run = calib(&[
        "sensitivity",
        campaign.to_str().unwrap(),
        "--method",
        "sobol",
        "--samples",
        "8",
        "--db",
        dir.path().join("db").to_str().unwrap(),
        "--out",
        dir.path().join("out").to_str().unwrap(),
        "--at",
        result.to_str().unwrap(),
    ]);
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(
        stderr.contains("other.json: best.parameters has no `pendulumFriction`"),
        "{stderr}"
    );
    let missing = dir.path().join("absent.json");
    let run = calib(&[
        "sensitivity",
        campaign.to_str().unwrap(),
        "--samples",
        "8",
        "--db",
        dir.path().join("db").to_str().unwrap(),
        "--at",
        missing.to_str().unwrap(),
    ]);
    assert!(!run.status.success());
    let stderr = String::from_utf8_lossy(&run.stderr);
    assert!(stderr.contains("absent.json: cannot be read"), "{stderr}");
}
