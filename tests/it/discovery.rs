//! Discovery of a torque outside the effect library, on records of the independent simulator
//! `tests/python/furuta_extra_torque.py` (scipy, no code shared with the worker: the driven
//! rig of `furuta_driven.py` with a cogging torque or a drag cubic in the arm's speed, 2 mrad noise
//! and 4096-count quantisation). The model's parameters are the simulator's truth (the rig's
//! geometry and frictions): discovery looks at what the model lacks, not at a fit.
//! Skipped (with the reason printed) where python3 or scipy is missing, except under
//! continuous integration (`CI` set), where that fails the test.

use crate::common::*;
use calib_analysis::diagnosis::discovery::{
    discover, Discovery, DiscoveryOptions, FurutaJoints, Record,
};
use std::path::Path;

/// A record of the simulator with `args`, read back, and the truth it printed.
fn record(dir: &Path, name: &str, args: &[&str]) -> Option<(Record, serde_json::Value)> {
    let csv = dir.join(name);
    let out = std::process::Command::new("python3")
        .arg(repo().join("tests/python/furuta_extra_torque.py"))
        .arg("--out")
        .arg(&csv)
        .args(args)
        .output();
    let out = match out {
        Err(e) => {
            skip(&format!("python3 cannot run: {e}"));
            return None;
        }
        Ok(out) => out,
    };
    if !out.status.success() {
        let why = String::from_utf8_lossy(&out.stderr);
        assert!(
            why.contains("No module named 'scipy'") || why.contains("No module named 'numpy'"),
            "furuta_extra_torque.py failed: {why}"
        );
        skip("scipy is not installed (pip install scipy)");
        return None;
    }
    let truth: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let text = std::fs::read_to_string(&csv).unwrap();
    let mut columns = vec![Vec::new(); 4];
    for line in text.lines().skip(1) {
        for (c, v) in columns.iter_mut().zip(line.split(',')) {
            c.push(v.parse::<f64>().unwrap());
        }
    }
    let record = Record {
        time: columns[0].clone(),
        angles: vec![columns[1].clone(), columns[2].clone()],
        inputs: vec![columns[3].clone()],
    };
    Some((record, truth))
}

/// The furuta model at the simulator's truth.
fn model(truth: &serde_json::Value) -> FurutaJoints {
    let info = calib_model::models::find("furuta").unwrap().info().clone();
    let mut params = info.default_vector();
    for (name, value) in truth["true_friction"].as_object().unwrap() {
        params[info.parameter_index(name).unwrap()] = value.as_f64().unwrap();
    }
    FurutaJoints { params }
}

fn run(args: &[&str]) -> Option<(Discovery, serde_json::Value)> {
    let dir = tempfile::tempdir().unwrap();
    let (record, truth) = record(dir.path(), "record.csv", args)?;
    let found = discover(&model(&truth), &record, &DiscoveryOptions::default()).unwrap();
    for joint in &found.joints {
        eprintln!(
            "{}: {} samples ({:.0} effective), {} of {} candidates, threshold {:.3e}, RMS {:.3e} -> {:.3e}",
            joint.joint,
            joint.samples,
            joint.effective_samples,
            joint.candidates,
            joint.library,
            joint.threshold,
            joint.residual_rms,
            joint.remaining_rms
        );
        for t in &joint.terms {
            eprintln!(
                "  {} * {} = {:.6e} [{:.6e}, {:.6e}]",
                t.parameter, t.function, t.estimate, t.ci_low, t.ci_high
            );
        }
        for h in &joint.harmonics {
            eprintln!(
                "  harmonic {} of {}: amplitude {:.6e} [{:.6e}, {:.6e}], phase {:.3}",
                h.multiple, h.angle, h.amplitude, h.ci_low, h.ci_high, h.phase
            );
        }
    }
    for p in found.proposals() {
        eprintln!("{}", p.to_toml());
    }
    Some((found, truth))
}

#[test]
fn cogging_on_the_arm_is_found_with_its_multiple_and_amplitude() {
    let Some((found, truth)) = run(&["--cogging", "0.006", "--seed", "1"]) else {
        return;
    };
    let range = truth["arm_range_rad"].as_array().unwrap();
    assert!(
        range[1].as_f64().unwrap() - range[0].as_f64().unwrap() > 5.0,
        "{range:?}"
    );
    let arm = &found.joints[0];
    assert_eq!(arm.joint, "armJoint");
    // The multiple is found among m = 1..40, and nothing else is.
    assert_eq!(arm.harmonics.len(), 1, "{:?}", arm.terms);
    let h = &arm.harmonics[0];
    assert_eq!((h.angle.as_str(), h.multiple), ("armJoint.phi", 8));
    assert_eq!(arm.terms.len(), 2, "{:?}", arm.terms);
    assert!(
        h.ci_low <= 0.006 && 0.006 <= h.ci_high,
        "amplitude {} [{}, {}]",
        h.amplitude,
        h.ci_low,
        h.ci_high
    );
    // The phase is 0: a·sin(8φ).
    assert!(h.phase.abs() < 0.2, "phase {}", h.phase);
    // The proposal is an effect on the arm joint with bounds around the truth.
    let proposal = arm.proposal.as_ref().unwrap();
    assert_eq!(proposal.place, "armJoint");
    assert_eq!(
        proposal.formula,
        "a1 * sin(8 * armJoint.phi) + b1 * cos(8 * armJoint.phi)"
    );
    let a1 = &proposal.parameters[0];
    assert!(a1.min < 0.006 && 0.006 < a1.max, "{a1:?}");
    assert!(proposal.to_toml().contains("torque = \"armJoint\""));
    // The pendulum misses nothing.
    assert!(
        found.joints[1].terms.is_empty(),
        "{:?}",
        found.joints[1].terms
    );
}

#[test]
fn a_cubic_drag_on_the_arm_is_found() {
    let Some((found, _)) = run(&["--arm-cubic-drag", "3e-4", "--seed", "2"]) else {
        return;
    };
    let arm = &found.joints[0];
    assert_eq!(arm.terms.len(), 1, "{:?}", arm.terms);
    let t = &arm.terms[0];
    assert_eq!(t.function, "armJoint.w * armJoint.w * armJoint.w");
    // The drag opposes the motion: −3e-4 ω³.
    assert!(t.ci_low <= -3e-4 && -3e-4 <= t.ci_high, "{t:?}");
    assert!((t.estimate + 3e-4).abs() < 0.1 * 3e-4, "{t:?}");
    let proposal = arm.proposal.as_ref().unwrap();
    assert_eq!(
        proposal.formula,
        "c1 * armJoint.w * armJoint.w * armJoint.w"
    );
    assert!(
        found.joints[1].terms.is_empty(),
        "{:?}",
        found.joints[1].terms
    );
}

#[test]
fn a_clean_record_gets_no_proposal() {
    let Some((found, _)) = run(&["--seed", "3"]) else {
        return;
    };
    assert!(found.proposals().is_empty(), "{:?}", found.proposals());
    for joint in &found.joints {
        assert!(
            joint.samples > 500,
            "{}: {} samples",
            joint.joint,
            joint.samples
        );
    }
}

/// With the frictions from a calibration (Nelder–Mead, 3 starts) on the cogging record
/// instead of the truth.
#[test]
fn cogging_is_found_after_calibrating_the_frictions() {
    use calib_engine::calibration::calibrate;
    use calib_engine::campaign::Campaign;
    use calib_engine::evaluator::LocalEvaluator;
    use calib_engine::optim::problem::Silent;
    let dir = tempfile::tempdir().unwrap();
    let Some((record, truth)) = record(
        dir.path(),
        "cogging.csv",
        &["--cogging", "0.006", "--seed", "1"],
    ) else {
        return;
    };
    let text = driven_friction_campaign(
        "cogging",
        &dir.path().join("cogging.csv"),
        "methods = [\"nelder-mead\"]\nstarts = 3\nmax_evaluations = 600\nseed = 1",
    );
    let campaign = Campaign::load(&write(dir.path(), "cogging.toml", &text)).unwrap();
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    eprintln!(
        "calibrated: armFriction {:.6e} (truth {}), pendulumFriction {:.6e} (truth {}), objective {:.4}",
        best.point[0],
        truth["true_friction"]["armFriction"],
        best.point[1],
        truth["true_friction"]["pendulumFriction"],
        best.objective
    );
    let params = campaign.full_parameters(&best.point);
    let found = discover(
        &FurutaJoints { params },
        &record,
        &DiscoveryOptions::default(),
    )
    .unwrap();
    let arm = &found.joints[0];
    for t in &arm.terms {
        eprintln!(
            "  {} = {:.4e} [{:.4e}, {:.4e}]",
            t.function, t.estimate, t.ci_low, t.ci_high
        );
    }
    for h in &arm.harmonics {
        eprintln!(
            "  harmonic {}: {:.4e} [{:.4e}, {:.4e}]",
            h.multiple, h.amplitude, h.ci_low, h.ci_high
        );
    }
    // The cogging, and the friction the calibration got wrong while the model could not
    // follow the record: the missing `−(F_true − F_fit)·sign(ω)`.
    assert_eq!(arm.harmonics.len(), 1, "{:?}", arm.terms);
    let h = &arm.harmonics[0];
    assert_eq!((h.angle.as_str(), h.multiple), ("armJoint.phi", 8));
    assert!(h.ci_low <= 0.006 && 0.006 <= h.ci_high, "{h:?}");
    let others: Vec<_> = arm
        .terms
        .iter()
        .filter(|t| !t.function.contains("8 *"))
        .collect();
    assert_eq!(others.len(), 1, "{:?}", arm.terms);
    assert_eq!(others[0].function, "sign(armJoint.w)");
    let missing = -(truth["true_friction"]["armFriction"].as_f64().unwrap() - best.point[0]);
    assert!(
        others[0].ci_low <= missing && missing <= others[0].ci_high,
        "{:?} vs {missing}",
        others[0]
    );
}

/// A record too short for the library (1.5 s: fewer usable samples than three per candidate
/// function) gets no proposal, and the report says why each joint was not looked at.
#[test]
fn a_joint_with_too_few_samples_is_said_to_be_unseen() {
    let dir = tempfile::tempdir().unwrap();
    let Some((mut record, truth)) = record(dir.path(), "record.csv", &["--cogging", "0.006"])
    else {
        return;
    };
    record.time.truncate(150);
    for series in record.angles.iter_mut().chain(record.inputs.iter_mut()) {
        series.truncate(150);
    }
    let found = discover(&model(&truth), &record, &DiscoveryOptions::default()).unwrap();
    assert!(found.proposals().is_empty());
    for joint in &found.joints {
        let why = joint.unseen.as_deref().unwrap_or_default();
        assert!(
            why.starts_with("too few usable samples"),
            "{}: {why:?}",
            joint.joint
        );
    }
}
