//! Model inputs: the Furuta rig driven by a measured arm motor torque.
//!
//! The record comes from an independent simulator (`tests/python/furuta_driven.py`, scipy's
//! `solve_ivp` with stick-slip modes switched at located events; its free swing matches
//! `furuta_clean.csv` to that record's noise). Its motor torque column drives the model's
//! `armTorque` input, linear between samples. Skipped (with the reason printed) where python3
//! or scipy is missing, except under continuous integration (`CI` set), where that fails the
//! test.

use crate::common::*;
use calib_engine::calibration::calibrate;
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use std::path::{Path, PathBuf};

/// Length of the driven record [s].
const STOP: f64 = 20.0;

/// The driven record (20 s at the rig's true frictions, seed 5) written into `dir`, and the
/// truth the simulator printed; `None` (with the reason) where python3 or scipy is missing.
fn driven_record(dir: &Path) -> Option<(PathBuf, serde_json::Value)> {
    furuta_driven_record(dir, "driven.csv", STOP, &["--seed", "5"])
}

/// A campaign fitting both frictions on the driven record; `inputs` is its `[[inputs]]`
/// section (or nothing).
fn driven_campaign(csv: &Path, theta0: f64, inputs: &str) -> String {
    format!(
        r#"
name = "driven"
[model]
name = "furuta"
[model.parameters]
theta0 = {theta0:?}
[measurement]
file = "{}"
time_column = "time_s"
{FURUTA_OUTPUTS}{inputs}
{FURUTA_FRICTIONS}[window]
start = 0.0
stop = {STOP:?}
[search]
methods = ["nelder-mead"]
starts = 3
max_evaluations = 400
seed = 1
"#,
        csv.display()
    )
}

const TORQUE_INPUT: &str = r#"[[inputs]]
model = "armTorque"
measured = "motor_torque_Nm"
"#;

/// Both frictions within 1% of the truth and the objective at the noise floor with the
/// measured torque as the model's input; the same campaign without it fits at least ten
/// times worse.
#[test]
fn a_measured_arm_torque_drives_the_model_to_the_true_frictions() {
    let dir = tempfile::tempdir().unwrap();
    let Some((csv, truth)) = driven_record(dir.path()) else {
        return;
    };
    let theta0 = truth["start_state"]["theta0"].as_f64().unwrap();
    let arm = truth["true_friction"]["armFriction"].as_f64().unwrap();
    let pendulum = truth["true_friction"]["pendulumFriction"].as_f64().unwrap();
    println!(
        "driven record: {} samples, arm over [{:.2}, {:.2}] rad, stuck {} times ({} s)",
        truth["samples"],
        truth["arm_range_rad"][0].as_f64().unwrap(),
        truth["arm_range_rad"][1].as_f64().unwrap(),
        truth["arm_sticks"],
        truth["arm_stuck_s"]
    );

    let path = write(
        dir.path(),
        "driven.toml",
        &driven_campaign(&csv, theta0, TORQUE_INPUT),
    );
    let c = calibrate(&Campaign::load(&path).unwrap(), LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    // Each output's residual is the encoder's noise (σ = 0.002 rad) plus its quantisation
    // (steps q = 2π/4096, uniform error: q²/12), over every sample of the window.
    let samples = c.objective.grid.len();
    let floor = synthetic_noise_floor(2, samples);
    println!(
        "with the torque input: armFriction {:.6e} ({:+.3}%), pendulumFriction {:.6e} ({:+.3}%), \
         objective {:.5} (noise floor {floor:.5} = {samples} samples x 2 outputs x \
         (0.002² + q²/12)), nominal {:.4}, {} evaluations",
        best.point[0],
        100.0 * (best.point[0] / arm - 1.0),
        best.point[1],
        100.0 * (best.point[1] / pendulum - 1.0),
        best.objective,
        c.nominal.objective,
        c.evaluations()
    );
    assert_eq!(samples, truth["samples"].as_u64().unwrap() as usize);
    assert!(
        (best.point[0] / arm - 1.0).abs() < 0.01,
        "armFriction {} vs {arm}",
        best.point[0]
    );
    assert!(
        (best.point[1] / pendulum - 1.0).abs() < 0.01,
        "pendulumFriction {} vs {pendulum}",
        best.point[1]
    );
    assert!(
        best.objective <= 1.5 * floor,
        "objective {} vs noise floor {floor}",
        best.objective
    );

    let path = write(
        dir.path(),
        "undriven.toml",
        &driven_campaign(&csv, theta0, ""),
    );
    let without = calibrate(&Campaign::load(&path).unwrap(), LocalEvaluator, &Silent).unwrap();
    let worst = without.best_run();
    println!(
        "without the input: armFriction {:.6e}, pendulumFriction {:.6e}, objective {:.4} \
         ({:.0} times the driven fit's), {} evaluations",
        worst.point[0],
        worst.point[1],
        worst.objective,
        worst.objective / best.objective,
        without.evaluations()
    );
    assert!(
        worst.objective >= 10.0 * best.objective,
        "without the torque input the fit reaches {} (with it {})",
        worst.objective,
        best.objective
    );
}
