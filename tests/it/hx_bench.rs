//! Calibrating `hx_highfi` on a bench record whose five boundary conditions are measured
//! signals: `examples/hx_bench.toml`, on its record made afresh by the `calib simulate`
//! command its header gives (step tests on each input at different times, sensor noise on
//! every column), with the five columns mapped to the model's inputs by `[[inputs]]`.

use crate::common::*;
use calib_engine::calibration::{calibrate, Calibration};
use calib_engine::campaign::{Campaign, Method};
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use std::path::Path;

/// The bench's factors, as the example's header sets them.
const TRUTH: [(&str, f64); 3] = [("CF_RefHT", 0.7), ("CF_AirHT", 1.25), ("CF_Refdp", 1.15)];

/// Output sensors' noise in the example's record: pressure drop (Pa), heat flow (W).
const SIGMA: [f64; 2] = [150.0, 20.0];

/// The `calib simulate` arguments of the example's header, writing to `out`.
fn record_command(campaign: &str, out: &Path) -> Vec<String> {
    let mut lines = campaign
        .lines()
        .skip_while(|l| !l.starts_with("#   calib simulate"));
    let mut args = Vec::new();
    for line in lines.by_ref() {
        args.extend(
            line.trim_start_matches('#')
                .split_whitespace()
                .map(String::from),
        );
        if line.contains("--out ") {
            break;
        }
    }
    assert_eq!(args.first().map(String::as_str), Some("calib"), "{args:?}");
    let at = args.iter().position(|a| a == "--out").expect("--out");
    args[at + 1] = out.display().to_string();
    args.remove(0);
    args
}

/// The campaign without its `[[inputs]]`: the built-in ramps in place of the record's
/// boundary conditions.
fn without_inputs(campaign: &str) -> String {
    let mut skipping = false;
    let mut kept = String::new();
    for line in campaign.lines() {
        if line.starts_with('[') {
            skipping = line == "[[inputs]]";
        }
        if !skipping {
            kept += line;
            kept += "\n";
        }
    }
    kept
}

/// One Nelder–Mead run of 120 evaluations from the nominal point.
fn run(file: &Path, what: &str) -> Calibration {
    let mut campaign = Campaign::load(file).unwrap();
    campaign.search.methods = vec![Method::NelderMead];
    campaign.search.starts = 1;
    campaign.search.max_evaluations = 120;
    let started = std::time::Instant::now();
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    println!(
        "{what}: objective {:.4e} at the nominal point -> {:.4e} at {:?}, {} evaluations, \
         {:.1} s",
        c.nominal.objective,
        best.objective,
        best.point,
        c.evaluations(),
        started.elapsed().as_secs_f64()
    );
    c
}

/// RMS of each output's residual at the best point.
fn rms(c: &Calibration) -> Vec<f64> {
    let n = c.objective.grid.len() as f64;
    c.best_evaluation
        .sse
        .iter()
        .map(|s| (s / n).sqrt())
        .collect()
}

/// Measured: driven by the recorded columns, one Nelder–Mead run ends at CF_RefHT 0.723,
/// CF_AirHT 1.223, CF_Refdp 1.1505 (+3.3 %, −2.1 %, +0.04 %) with an objective of 422,
/// below the 435 of the truth itself and 1.7 times the 242 that the output sensors' noise
/// alone gives: the rest is the noise of the input sensors, which drives the model as
/// recorded (the outlet pressure's enters the pressure drop at once, the inlet pressure
/// lagging by a second).
///
/// The two heat-transfer factors share the heat flow, and the input noise the model is
/// driven by moves where it splits it between them (errors in the variables): over eight
/// noise draws (`--seed` 1–8) the fit landed within 12.0 % of CF_RefHT, 8.4 % of CF_AirHT
/// and 0.07 % of CF_Refdp, with objectives 1.6–2.3 times the floor, and the profile
/// likelihood's 95 % interval of the worst draw (seed 6: −12 %, +8.4 %) leaves the truth
/// out. With the output sensors' noise alone (seeds 1 and 3) it landed within 1.5 % and
/// 0.6 %. The tolerances below hold every draw.
///
/// The same campaign on the built-in ramps ends 600 times worse (2.53e5, at CF_RefHT 0.955,
/// CF_AirHT 1.036, CF_Refdp 1.204).
#[test]
fn factors_are_recovered_from_a_record_driven_by_measured_boundary_conditions() {
    let example = repo().join("examples/hx_bench.toml");
    let text = std::fs::read_to_string(&example).unwrap();
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("data")).unwrap();
    let args = record_command(&text, &dir.path().join("data/hx_bench.csv"));
    let made = calib(&args.iter().map(String::as_str).collect::<Vec<_>>());
    assert!(
        made.status.success(),
        "{}",
        String::from_utf8_lossy(&made.stderr)
    );
    let driven = run(
        &write(dir.path(), "hx_bench.toml", &text),
        "measured inputs",
    );
    assert_eq!(driven.objective.inputs.signals.len(), 5);

    let samples = driven.objective.grid.len() as f64;
    // What the output sensors' noise alone gives at the truth (weights 1/σ²): about one per
    // sample and output.
    let floor = 2.0 * samples;
    // The objective at the truth, driven by the noisy recorded inputs.
    let at_truth = driven.objective.evaluate(&TRUTH.map(|(_, v)| v)).objective;
    let best = driven.best_run();
    println!(
        "noise floor {floor:.1}, objective at the truth {at_truth:.1}, fitted {:.1} ({:.2}x \
         the floor); rms dp_ref, Qdot_refTotal {:?} (sensor noise {SIGMA:?})",
        best.objective,
        best.objective / floor,
        rms(&driven)
    );
    for (k, ((name, v), tolerance)) in TRUTH.iter().zip([0.15, 0.10, 0.005]).enumerate() {
        assert_eq!(driven.campaign.free[k].name, *name);
        let found = best.point[k];
        println!(
            "{name}: {found:.4} (truth {v}, {:+.2} %)",
            100.0 * (found / v - 1.0)
        );
        assert!(
            (found / v - 1.0).abs() < tolerance,
            "{name} {found}, truth {v}"
        );
    }
    assert!(
        best.objective <= 1.01 * at_truth,
        "{} against {at_truth} at the truth",
        best.objective
    );
    assert!(
        best.objective < 3.0 * floor,
        "{} against {floor}",
        best.objective
    );

    let ramps = run(
        &write(dir.path(), "ramps.toml", &without_inputs(&text)),
        "built-in ramps",
    );
    assert!(ramps.objective.inputs.signals.is_empty());
    let worse = ramps.best_run().objective / best.objective;
    println!(
        "built-in ramps end {worse:.1}x worse than the measured inputs; rms {:?}",
        rms(&ramps)
    );
    assert!(worse > 50.0, "{worse}");
}
