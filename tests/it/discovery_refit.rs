//! The loop of discovery on a campaign: calibrate the frictions, discover what the model
//! misses on the campaign's own record, refit the proposal as a user-defined effect, and
//! compare the objective with the noise floor. Records of the independent simulator
//! `tests/python/furuta_extra_torque.py` (scipy, no code shared with the worker).
//! Skipped (with the reason printed) where python3 or scipy is missing, except under
//! continuous integration (`CI` set), where that fails the test.

use crate::common::*;
use calib_analysis::diagnosis::discovery::{
    discover, joint_model, record_of, refit_discovered, Discovery, DiscoveryOptions, ProposalRefit,
};
use calib_analysis::diagnosis::noise_floor;
use calib_engine::calibration::{calibrate, load_measurement};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::objective::Objective;
use calib_engine::optim::problem::Silent;
use std::path::Path;

/// The two bearing frictions free, from nominal values off the truth, on `csv`.
fn campaign(dir: &Path, csv: &Path) -> Campaign {
    let text = driven_friction_campaign(
        "discovery-refit",
        csv,
        "methods = [\"nelder-mead\", \"levenberg-marquardt\"]\nstarts = 3\nmax_evaluations = 600\nseed = 1",
    );
    Campaign::load(&write(dir, "campaign.toml", &text)).unwrap()
}

/// Calibrate the campaign on the record made with `args`, then discover on it with the
/// calibrated parameters: the campaign, its best point and objective, the noise floor, and
/// what discovery found.
struct Calibrated {
    campaign: Campaign,
    point: Vec<f64>,
    objective: f64,
    floor: f64,
    found: Discovery,
    truth: serde_json::Value,
}

fn calibrated(dir: &Path, args: &[&str]) -> Option<Calibrated> {
    let (csv, truth) = furuta_extra_torque_record(dir, "record.csv", args)?;
    let campaign = campaign(dir, &csv);
    let measurement = load_measurement(&campaign).unwrap();
    let (_, floor) = noise_floor(&Objective::new(&campaign, &measurement).unwrap());
    let floor = floor.value;
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    let model = joint_model(&campaign, campaign.full_parameters(&best.point)).unwrap();
    let record = record_of(&campaign, &measurement, model.as_ref()).unwrap();
    let found = discover(model.as_ref(), &record, &DiscoveryOptions::default()).unwrap();
    eprintln!(
        "calibrated: {:?}, objective {:.4e}, noise floor {:.4e}",
        best.point, best.objective, floor
    );
    for p in found.proposals() {
        eprintln!("{}", p.to_toml());
    }
    Some(Calibrated {
        point: best.point.clone(),
        objective: best.objective,
        campaign,
        floor,
        found,
        truth,
    })
}

/// Print what the refit did: each window, the objective against the floor, the residual
/// and the profile intervals.
fn print_refit(refit: &ProposalRefit) {
    eprintln!("{}", refit.toml);
    for s in &refit.stages {
        eprintln!(
            "stage [{:.2}, {:.2}] s: objective {:.5e} (by {}, {} evaluations)",
            s.window.0, s.window.1, s.objective, s.method, s.evaluations
        );
    }
    eprintln!(
        "objective {:.4e} -> {:.4e}, noise floor {:.4e} (ratio {:.3} -> {:.3}), {} evaluations",
        refit.objective_before,
        refit.objective_after,
        refit.noise_floor,
        refit.ratio_before(),
        refit.ratio_after(),
        refit.evaluations
    );
    for p in &refit.parameters {
        eprintln!("  {:<32} {:.7e}", p.name, p.value);
    }
    for r in &refit.residual {
        eprintln!(
            "  residual {}: rms {:.4e}, lag-1 autocorrelation {:.3}, Ljung-Box {:.1} ({:.1})",
            r.output, r.rms, r.lag1, r.ljung_box, r.ljung_box_critical
        );
    }
    eprintln!("  threshold {:?}", refit.threshold);
    for i in &refit.intervals {
        eprintln!(
            "  {}: {:.7e} profile [{:?}, {:?}] linearised [{:.7e}, {:.7e}], {} evaluations",
            i.name,
            i.value,
            i.ci_low,
            i.ci_high,
            i.linearised_low,
            i.linearised_high,
            i.evaluations
        );
    }
}

#[test]
fn cogging_is_proposed_and_its_refit_reaches_the_noise_floor() {
    let dir = tempfile::tempdir().unwrap();
    let Some(c) = calibrated(dir.path(), &["--cogging", "0.006", "--seed", "1"]) else {
        return;
    };
    let proposals = c.found.proposals();
    assert_eq!(proposals.len(), 1, "{proposals:?}");
    let proposal = proposals[0];
    assert_eq!(proposal.place, "armJoint");
    assert!(
        proposal.formula.contains("sin(8 * armJoint.phi)")
            && proposal.formula.contains("cos(8 * armJoint.phi)"),
        "{}",
        proposal.formula
    );
    let truth_friction = c.truth["true_friction"]["armFriction"].as_f64().unwrap();
    // The model without the cogging cannot follow the record.
    assert!(
        c.objective > 10.0 * c.floor,
        "{} vs {}",
        c.objective,
        c.floor
    );

    let refit = refit_discovered(
        &c.campaign,
        &c.point,
        c.objective,
        c.floor,
        proposal,
        LocalEvaluator,
        &Silent,
    )
    .unwrap();
    print_refit(&refit);
    // Refitted as an amplitude and a phase of the multiple discovery found.
    assert!(
        refit.toml.contains("amp1 * sin(8 * armJoint.phi + phase1)"),
        "{}",
        refit.toml
    );
    // The objective falls from over 10⁴ times the noise floor to within 1.5 times it (the
    // simulator's truth with the effect leaves 0.98 times).
    assert!(refit.ratio_before() > 1e4, "ratio {}", refit.ratio_before());
    assert!(refit.ratio_after() <= 1.5, "ratio {}", refit.ratio_after());
    // The arm's friction error, proposed as `sign(armJoint.w)`, went into the friction.
    assert_eq!(refit.folded, ["sign(armJoint.w)"]);
    let arm_friction = refit.parameters[0].value;
    assert!(
        (arm_friction - truth_friction).abs() < 0.01 * truth_friction,
        "armFriction {arm_friction} vs {truth_friction}"
    );
    // The amplitude's 95% profile interval is closed and holds the truth; so does the
    // phase's (the record's cogging has phase 0).
    let amplitude = refit.interval("amp1").unwrap();
    assert!(amplitude.identifiable(), "{amplitude:?}");
    assert!(amplitude.holds(0.006), "{amplitude:?}");
    let phase = refit.interval("phase1").unwrap();
    assert!(phase.identifiable() && phase.holds(0.0), "{phase:?}");
}

#[test]
fn a_cubic_drag_is_proposed_and_its_refit_reaches_the_noise_floor() {
    let dir = tempfile::tempdir().unwrap();
    let Some(c) = calibrated(dir.path(), &["--arm-cubic-drag", "3e-4", "--seed", "2"]) else {
        return;
    };
    let proposals = c.found.proposals();
    assert_eq!(proposals.len(), 1, "{proposals:?}");
    let proposal = proposals[0];
    assert_eq!(proposal.place, "armJoint");
    let cubic = "armJoint.w * armJoint.w * armJoint.w";
    let term = proposal
        .terms
        .iter()
        .find(|t| t.function == cubic)
        .unwrap_or_else(|| panic!("{}", proposal.formula));
    assert!(
        c.objective > 10.0 * c.floor,
        "{} vs {}",
        c.objective,
        c.floor
    );
    let refit = refit_discovered(
        &c.campaign,
        &c.point,
        c.objective,
        c.floor,
        proposal,
        LocalEvaluator,
        &Silent,
    )
    .unwrap();
    print_refit(&refit);
    assert!(refit.ratio_after() <= 1.5, "ratio {}", refit.ratio_after());
    let interval = refit.interval(&term.parameter).unwrap();
    assert!(interval.identifiable(), "{interval:?}");
    assert!(interval.holds(-3e-4), "{interval:?}");
}

#[test]
fn a_clean_record_gets_no_proposal_after_calibration() {
    let dir = tempfile::tempdir().unwrap();
    let Some(c) = calibrated(dir.path(), &["--seed", "3"]) else {
        return;
    };
    assert!(c.found.proposals().is_empty(), "{:?}", c.found.proposals());
    assert!(
        c.objective <= 1.5 * c.floor,
        "{} vs {}",
        c.objective,
        c.floor
    );
}

/// `calib diagnose --discover`: the diagnosis finds nothing in the library, discovery proposes
/// the cogging on the arm, its refit reaches the noise floor with the amplitude's profile
/// interval holding the truth, and the outputs carry it (formula, intervals, residual).
#[test]
fn diagnose_discover_reports_what_it_found_outside_the_library() {
    let dir = tempfile::tempdir().unwrap();
    let Some((csv, _)) = furuta_extra_torque_record(
        dir.path(),
        "record.csv",
        &["--cogging", "0.006", "--seed", "1"],
    ) else {
        return;
    };
    let c = campaign(dir.path(), &csv);
    let source = c.source.clone().unwrap();
    let out = dir.path().join("out");
    let run = calib(&[
        "diagnose",
        source.to_str().unwrap(),
        "--discover",
        "--json",
        "--out",
        out.to_str().unwrap(),
        "--db",
        dir.path().join("db").to_str().unwrap(),
    ]);
    let json = json_of(&run);
    assert_ne!(json["verdict"], "explained", "{}", json["verdict"]);
    let found = &json["found_outside_the_library"];
    assert_eq!(found["available"], true, "{found}");
    let block = found["proposals"][0].as_str().unwrap();
    assert!(block.contains("torque = \"armJoint\""), "{block}");
    assert!(block.contains("sin(8 * armJoint.phi)"), "{block}");
    let refit = &found["refits"][0];
    let number = |v: &serde_json::Value| v.as_f64().unwrap_or_else(|| panic!("{v}"));
    let (before, after, floor) = (
        number(&refit["objective_before"]),
        number(&refit["objective_after"]),
        number(&refit["noise_floor"]),
    );
    eprintln!(
        "objective {before:.4e} -> {after:.4e}, floor {floor:.4e} ({:.1} -> {:.3} times); {}",
        before / floor,
        after / floor,
        refit["intervals"]
    );
    // The diagnosis fits 0–16 s (16–20 s held out): the refit on that window reaches the
    // noise floor too, and the amplitude's profile interval holds the truth.
    assert!(after <= 1.5 * floor, "{after} vs {floor}");
    let amplitude = refit["intervals"]
        .as_array()
        .unwrap()
        .iter()
        .find(|i| i["name"] == "discovered.armJoint.amp1")
        .unwrap_or_else(|| panic!("{refit}"));
    assert!(
        number(&amplitude["ci_low"]) <= 0.006 && 0.006 <= number(&amplitude["ci_high"]),
        "{amplitude}"
    );
    for output in refit["residual"].as_array().unwrap() {
        assert!(output["lag1"].as_f64().unwrap().abs() < 0.1, "{output}");
    }
    let written = out.join("discovery-refit/diagnosis");
    let md = std::fs::read_to_string(written.join("diagnosis.md")).unwrap();
    assert!(md.contains("## Found outside the library"), "{md}");
    for words in [
        "amp1 * sin(8 * armJoint.phi + phase1)",
        "the sine of 8 periods per turn of armJoint.phi, shifted by the phase phase1",
        "discovered.armJoint.amp1",
        "profile 95% [",
        "lag-1 autocorrelation",
    ] {
        assert!(md.contains(words), "{words} not in {md}");
    }
    let stored: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(written.join("diagnosis.json")).unwrap())
            .unwrap();
    assert_eq!(stored["found_outside_the_library"]["proposals"][0], block);
}
