//! Closing the loop: the diagnosis finds the effect a record carries, says "noise" when there
//! is nothing to find, and admits it when the missing piece is outside its library.

use crate::common::*;
use calib_analysis::diagnosis::outside::found_outside_the_library;
use calib_analysis::diagnosis::{diagnose, Diagnosis, Verdict};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use calib_model::Run;
use calib_model::{models, SolverOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::path::Path;

fn run(campaign: &Path) -> Diagnosis {
    let campaign = Campaign::load(campaign).unwrap();
    let d = diagnose(&campaign, &LocalEvaluator, &Silent).unwrap();
    println!(
        "{}: verdict {:?}, selected {:?}, objective {:.4e} -> {:.4e} (floor {:.4e}), top {:?}, {:.1} s",
        campaign.name,
        d.verdict,
        d.selected,
        d.baseline.objective,
        d.final_fit.objective,
        d.noise_floor,
        d.candidates.iter().take(3).map(|c| (&c.effect, c.score)).collect::<Vec<_>>(),
        d.elapsed.as_secs_f64()
    );
    d
}

fn value(d: &Diagnosis, name: &str) -> f64 {
    d.final_fit
        .parameters
        .iter()
        .find(|p| p.name == name)
        .unwrap_or_else(|| panic!("{name} not among the final parameters"))
        .value
}

#[test]
fn viscous_arm_friction_is_found_and_measured() {
    let d = run(&repo().join("examples/furuta_viscous_arm.toml"));
    assert_eq!(d.candidates[0].effect, "viscous_friction.arm");
    assert_eq!(d.selected, vec!["viscous_friction.arm".to_string()]);
    assert_eq!(d.verdict, Verdict::Explained);
    // docs/diagnosis.md's row, to its printed digits (the diagnosis is deterministic):
    // 0.00199998 [0.001997, 0.002003], frictions 0.0101257 / 0.00116999, 7.957 → 0.02507,
    // 317× lower, noise floor 0.02529, 0.99× the floor, held out 0.985 → 0.00866.
    assert_reads_as(d.baseline.held_out_objective, "0.985", "held out before");
    assert_reads_as(d.final_fit.held_out_objective, "0.00866", "held out after");
    let viscous = |name: &str| value(&d, name);
    assert_reads_as(
        viscous("viscous_friction.arm"),
        "0.00199998",
        "viscous_friction.arm",
    );
    assert_reads_as(viscous("armFriction"), "0.0101257", "armFriction");
    assert_reads_as(
        viscous("pendulumFriction"),
        "0.00116999",
        "pendulumFriction",
    );
    assert_reads_as(d.baseline.objective, "7.957", "baseline");
    assert_reads_as(d.final_fit.objective, "0.02507", "final objective");
    assert_reads_as(d.noise_floor, "0.02529", "noise floor");
    assert_reads_as(
        d.baseline.objective / d.final_fit.objective,
        "317",
        "times lower",
    );
    assert_reads_as(
        d.final_fit.objective / d.noise_floor,
        "0.99",
        "times the floor",
    );
    // The truth the record was made with, at the looser tolerances the claim states.
    assert!((value(&d, "viscous_friction.arm") / 0.002 - 1.0).abs() < 0.10);
    let (arm, pendulum) = true_frictions();
    assert!((value(&d, "armFriction") / arm - 1.0).abs() < 0.05);
    assert!((value(&d, "pendulumFriction") / pendulum - 1.0).abs() < 0.05);
    assert!(d.final_fit.objective * 20.0 <= d.baseline.objective);
    // Within 1.5x the noise floor of the record (2 outputs, 0.002 rad noise, 4096 counts).
    let floor = synthetic_noise_floor(2, d.final_fit.residual[0].samples);
    assert!(
        d.final_fit.objective < 1.5 * floor,
        "{} vs {floor}",
        d.final_fit.objective
    );
    assert!(d.final_fit.held_out_objective < d.baseline.held_out_objective);
    let ci = d
        .final_fit
        .parameters
        .iter()
        .find(|p| p.name == "viscous_friction.arm")
        .unwrap();
    assert!(ci.ci_low < 0.002 && 0.002 < ci.ci_high || (ci.value / 0.002 - 1.0).abs() < 0.01);
    assert_reads_as(ci.ci_low, "0.001997", "interval's lower end");
    assert_reads_as(ci.ci_high, "0.002003", "interval's upper end");
}

#[test]
fn clean_data_needs_nothing() {
    let d = run(&repo().join("examples/furuta.toml"));
    assert!(d.selected.is_empty());
    assert_eq!(d.verdict, Verdict::Noise);
    assert!(d.explained());
}

#[test]
fn the_real_rig_with_the_seeds_model_leaves_only_noise() {
    if real_record().is_none() {
        return;
    }
    let d = run(&repo().join("examples/furuta_real.toml"));
    assert!(d.selected.is_empty());
    assert_eq!(d.verdict, Verdict::Noise);
    // Discovery reads the real record, whose clock is written in single precision (steps
    // 0.0499992 to 0.0500031 s): a uniform grid to it, not a reason to stop.
    let found = found_outside_the_library(&d, &LocalEvaluator, &Silent).unwrap();
    assert!(found.unavailable.is_none(), "{:?}", found.unavailable);
    assert!(found.discovery.is_some());
    println!("{}", found.text());
}

#[test]
fn the_real_rig_with_a_naive_model_leads_back_to_coulomb_friction() {
    if real_record().is_none() {
        return;
    }
    let d = run(&repo().join("examples/furuta_real_naive.toml"));
    assert!(
        d.selected
            .iter()
            .all(|e| e.starts_with("coulomb_friction."))
            && !d.selected.is_empty(),
        "{:?}",
        d.selected
    );
    assert!(d.candidates[0].effect.starts_with("coulomb_friction."));
    // Below the seed's own model in the seed's tool chain (2.729): docs give 0.944 from a
    // baseline of 64.63, 68x lower; held here to 1% and to over 60x.
    println!(
        "naive model on the real rig: {:.5} -> {:.5}, selected {:?}",
        d.baseline.objective, d.final_fit.objective, d.selected
    );
    // docs/diagnosis.md's row, to its printed digits: 64.63 → 0.944, 68× lower, at Coulomb
    // frictions 0.0100076 and 0.00099979. (Its held-out figures, 4.61 and 0.148, are not
    // what the diagnosis gives: printed here, not held.)
    println!(
        "held out: {:e} -> {:e}",
        d.baseline.held_out_objective, d.final_fit.held_out_objective
    );
    assert_reads_as(d.final_fit.objective, "0.944", "final objective");
    assert_reads_as(d.baseline.objective, "64.63", "baseline");
    assert_reads_as(
        d.baseline.objective / d.final_fit.objective,
        "68",
        "times lower",
    );
    assert_reads_as(
        value(&d, "coulomb_friction.arm"),
        "0.0100076",
        "coulomb arm",
    );
    assert_reads_as(
        value(&d, "coulomb_friction.pendulum"),
        "0.00099979",
        "coulomb pendulum",
    );
    assert!(d.final_fit.objective < 2.729);
}

/// A synthetic record of the furuta with `set` (name, value) applied and 2 mrad noise,
/// written as CSV; `disturb` adds something to the arm angle at time t.
fn record(dir: &Path, set: &[(&str, f64)], disturb: impl Fn(f64) -> f64) -> std::path::PathBuf {
    let model = models::find("furuta").unwrap();
    let info = model.info();
    let mut p = info.default_vector();
    let (arm, pendulum) = true_frictions();
    p[info.parameter_index("armFriction").unwrap()] = arm;
    p[info.parameter_index("pendulumFriction").unwrap()] = pendulum;
    for (name, v) in set {
        p[info.parameter_index(name).unwrap()] = *v;
    }
    let grid: Vec<f64> = (0..=4000).map(|i| i as f64 * 0.01).collect();
    let t = model
        .simulate(&Run::new(&p, &grid, &[0, 1], &SolverOptions::default()))
        .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let mut noise = || gaussian(&mut rng, 0.002);
    let mut text = String::from("time_s,arm_angle_rad,pendulum_angle_rad\n");
    for (i, time) in grid.iter().enumerate() {
        let a = t.values[0][i] + disturb(*time) + noise();
        let b = t.values[1][i] + noise();
        text.push_str(&format!("{time},{a},{b}\n"));
    }
    write(dir, "record.csv", &text)
}

/// A campaign over `data` freeing the two Coulomb frictions (one held at 0 with `hold`).
fn campaign_for(dir: &Path, data: &Path, hold: Option<&str>) -> std::path::PathBuf {
    let mut text = format!(
        r#"
name = "table"
[model]
name = "furuta"
stop_time = 40.0
[model.parameters]
{}
[measurement]
file = "{}"
time_column = "time_s"
{FURUTA_OUTPUTS}[window]
start = 0.0
stop = 30.0
[search]
methods = ["nelder-mead", "powell"]
starts = 4
max_evaluations = 600
seed = 1
[diagnosis]
holdout_start = 30.01
holdout_stop = 40.0
"#,
        hold.map_or(String::new(), |h| format!("{h} = 0.0")),
        data.display()
    );
    for (name, nominal) in [("armFriction", 0.012), ("pendulumFriction", 0.0015)] {
        if Some(name) != hold {
            text.push_str(&format!(
                "[[parameters]]\nname = \"{name}\"\nnominal = {nominal}\nmin = 0.0\nmax = 0.9\n"
            ));
        }
    }
    write(dir, "table.toml", &text)
}

/// A record carrying `effect` at `value` is diagnosed as that effect.
fn finds(effect: &str, value: f64) {
    let dir = tempfile::tempdir().unwrap();
    let (set, hold) = match effect {
        "coulomb_friction.arm" => (vec![], Some("armFriction")),
        "coulomb_friction.pendulum" => (vec![], Some("pendulumFriction")),
        _ => (vec![(effect, value)], None),
    };
    let data = record(dir.path(), &set, |_| 0.0);
    let d = run(&campaign_for(dir.path(), &data, hold));
    assert!(
        d.selected.first().map(String::as_str) == Some(effect),
        "{effect}: selected {:?}, ranked {:?}",
        d.selected,
        d.candidates
            .iter()
            .take(4)
            .map(|c| (&c.effect, c.score))
            .collect::<Vec<_>>()
    );
    assert!(d.explained(), "{effect}: verdict {:?}", d.verdict);
}

#[test]
fn finds_viscous_friction_arm() {
    finds("viscous_friction.arm", 0.002);
}
#[test]
fn finds_viscous_friction_pendulum() {
    finds("viscous_friction.pendulum", 0.0003);
}
#[test]
fn finds_quadratic_drag_arm() {
    finds("quadratic_drag.arm", 0.003);
}
#[test]
fn finds_quadratic_drag_pendulum() {
    finds("quadratic_drag.pendulum", 0.00005);
}
#[test]
fn finds_stiffness_arm() {
    finds("stiffness.arm", 0.01);
}
#[test]
fn finds_stiffness_pendulum() {
    finds("stiffness.pendulum", 0.002);
}
#[test]
fn finds_torque_bias_arm() {
    finds("torque_bias.arm", 0.004);
}
#[test]
fn finds_torque_bias_pendulum() {
    finds("torque_bias.pendulum", 0.002);
}
#[test]
fn finds_coulomb_friction_arm() {
    finds("coulomb_friction.arm", 0.0);
}
#[test]
fn finds_coulomb_friction_pendulum() {
    finds("coulomb_friction.pendulum", 0.0);
}
#[test]
fn finds_offset_arm() {
    finds("offset(armJoint.phi)", 0.05);
}
#[test]
fn finds_offset_pendulum() {
    finds("offset(pendulumJoint.phi)", 0.05);
}
#[test]
fn finds_gain_arm() {
    finds("gain(armJoint.phi)", 0.1);
}
#[test]
fn finds_gain_pendulum() {
    finds("gain(pendulumJoint.phi)", 0.05);
}
#[test]
fn finds_delay_arm() {
    finds("delay(armJoint.phi)", 0.08);
}
#[test]
fn finds_delay_pendulum() {
    finds("delay(pendulumJoint.phi)", 0.05);
}
#[test]
fn finds_lag_arm() {
    finds("lag(armJoint.phi)", 0.1);
}
#[test]
fn finds_lag_pendulum() {
    finds("lag(pendulumJoint.phi)", 0.05);
}

#[test]
fn a_disturbance_outside_the_library_is_not_claimed_as_explained() {
    let dir = tempfile::tempdir().unwrap();
    // A periodic disturbance of the arm at 0.7 Hz that no candidate can describe.
    let data = record(dir.path(), &[], |t| {
        0.03 * (2.0 * std::f64::consts::PI * 0.7 * t).sin()
    });
    let d = run(&campaign_for(dir.path(), &data, None));
    assert!(
        matches!(d.verdict, Verdict::Unexplained | Verdict::Partial),
        "verdict {:?}, selected {:?}",
        d.verdict,
        d.selected
    );
    assert!(!d.explained());
}

/// The naive model with the bounds a user types ([0, 0.9] on both viscous coefficients, not
/// [0, 0.02]): the screened multistart still finds the viscous-only optimum (≈ 64.6) instead
/// of stopping on the bound, and the diagnosis still leads to Coulomb friction.
#[test]
fn the_naive_model_on_wide_bounds_still_leads_back_to_coulomb_friction() {
    if real_record().is_none() {
        return;
    }
    let source = repo().join("examples/furuta_real_naive.toml");
    let text = std::fs::read_to_string(&source).unwrap();
    let wide = text.replace("max = 0.02", "max = 0.9");
    assert_eq!(wide.matches("max = 0.9").count(), 2);
    let dir = tempfile::tempdir().unwrap();
    let data = shared_data().join("real/FurutaData.mat");
    let wide = wide.replace(
        "../../shared/data/real/FurutaData.mat",
        data.to_str().unwrap(),
    );
    let d = run(&write(dir.path(), "naive_wide.toml", &wide));
    assert!(
        d.baseline.objective < 70.0,
        "baseline {} (viscous-only optimum ≈ 64.6)",
        d.baseline.objective
    );
    assert!(
        d.selected
            .iter()
            .all(|e| e.starts_with("coulomb_friction."))
            && d.selected.len() == 2,
        "{:?}",
        d.selected
    );
    assert!(d.final_fit.objective < 2.729, "{}", d.final_fit.objective);
    // docs/diagnosis.md: the screened baseline still reaches 64.6, the diagnosis 0.944.
    assert_reads_as(d.baseline.objective, "64.6", "baseline on wide bounds");
    assert_reads_as(
        d.final_fit.objective,
        "0.944",
        "final objective on wide bounds",
    );
}
