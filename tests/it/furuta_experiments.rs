//! Several experiments in one calibration: a free swing and a record driven by a measured
//! arm torque, fitted with one pair of frictions.
//!
//! Both records come from the independent simulator `tests/python/furuta_driven.py` (scipy,
//! no code shared with the worker) at the rig's true frictions: a free swing from 30° off
//! upright, and a 20 s record driven by the motor torque from a start near hanging. Each alone
//! and both together recover the frictions; together they pin them down at least as tightly
//! as the better record alone (profile likelihood intervals); a start angle free in the
//! driven experiment alone is found; workers give the very numbers of this process; disjoint
//! windows fit only their samples. Skipped (with the reason printed) where python3 or scipy
//! is missing, except under continuous integration (`CI` set), where that fails the test.

use crate::common::cluster::*;
use crate::common::*;
use calib_analysis::profile::{profile, report, BestFrom, Profiles, Settings};
use calib_engine::calibration::{calibrate, calibrate_with_store, Calibration};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use calib_engine::store::MemoryStore;
use std::path::{Path, PathBuf};

/// Length of both records [s].
const STOP: f64 = 20.0;
/// Start angle of the free swing [rad] (30° off upright, the rig's).
const SWING_THETA0: f64 = std::f64::consts::FRAC_PI_6;
/// Start angle of the driven record [rad] (0.34 rad off hanging).
const DRIVEN_THETA0: f64 = 2.8;

/// A record of the independent simulator: `args` after `--out` and `--stop`, written as
/// `name` into `dir`, and the truth it printed; `None` (with the reason) where python3 or
/// scipy is missing.
fn record(dir: &Path, name: &str, args: &[&str]) -> Option<(PathBuf, serde_json::Value)> {
    furuta_driven_record(dir, name, STOP, args)
}

/// The two records: the free swing (seed 3) and the driven one (seed 5).
struct Records {
    _dir: tempfile::TempDir,
    swing: PathBuf,
    driven: PathBuf,
    arm: f64,
    pendulum: f64,
}

fn records() -> Option<Records> {
    let dir = tempfile::tempdir().unwrap();
    let theta0 = SWING_THETA0.to_string();
    let (swing, swing_truth) = record(
        dir.path(),
        "swing.csv",
        &["--no-torque", "--theta0", &theta0, "--seed", "3"],
    )?;
    let theta0 = DRIVEN_THETA0.to_string();
    let (driven, driven_truth) = record(
        dir.path(),
        "driven.csv",
        &["--theta0", &theta0, "--seed", "5"],
    )?;
    let friction =
        |truth: &serde_json::Value, name: &str| truth["true_friction"][name].as_f64().unwrap();
    for truth in [&swing_truth, &driven_truth] {
        println!(
            "record: theta0 {}, torque amplitude {} N m, arm over [{:.2}, {:.2}] rad, arm \
             stuck {} times ({} s), pendulum stuck {} s",
            truth["start_state"]["theta0"],
            truth["motor_torque"]["amplitude_Nm"],
            truth["arm_range_rad"][0].as_f64().unwrap(),
            truth["arm_range_rad"][1].as_f64().unwrap(),
            truth["arm_sticks"],
            truth["arm_stuck_s"],
            truth["pendulum_stuck_s"]
        );
    }
    let arm = friction(&swing_truth, "armFriction");
    let pendulum = friction(&swing_truth, "pendulumFriction");
    assert_eq!(arm, friction(&driven_truth, "armFriction"));
    assert_eq!(pendulum, friction(&driven_truth, "pendulumFriction"));
    Some(Records {
        _dir: dir,
        swing,
        driven,
        arm,
        pendulum,
    })
}

/// The head of the campaigns here: the model, its outputs and its two frictions.
fn head() -> String {
    format!("[model]\nname = \"furuta\"\n{FURUTA_OUTPUTS}{FURUTA_FRICTIONS}")
}

const SEARCH: &str = r#"[search]
methods = ["nelder-mead"]
starts = 3
max_evaluations = 400
seed = 1
"#;

const TORQUE_INPUT: &str = r#"[[inputs]]
model = "armTorque"
measured = "motor_torque_Nm"
"#;

/// A campaign of one record: `csv` from `theta0`, with `inputs` (an `[[inputs]]` section or
/// nothing) and `window` (a `[window]` section or a top-level `windows = ...` line).
fn one_record(name: &str, csv: &Path, theta0: f64, inputs: &str, window: &str) -> String {
    format!(
        "name = \"{name}\"\n{window}\n{head}[model.parameters]\ntheta0 = {theta0:?}\n\
         [measurement]\nfile = \"{}\"\ntime_column = \"time_s\"\n{inputs}{SEARCH}",
        csv.display(),
        head = head(),
    )
}

fn window() -> String {
    format!("[window]\nstart = 0.0\nstop = {STOP:?}")
}

/// Both records as two experiments, the torque driving the second; `driven_parameters` is
/// appended to the driven experiment (its `[[experiments.parameters]]`).
fn both(r: &Records, driven_parameters: &str) -> String {
    format!(
        r#"name = "both"
{head}
[[experiments]]
name = "swing"
file = "{}"
time_column = "time_s"
window = {{ start = 0.0, stop = {STOP:?} }}
fixed = {{ theta0 = {SWING_THETA0:?} }}

[[experiments]]
name = "driven"
file = "{}"
time_column = "time_s"
window = {{ start = 0.0, stop = {STOP:?} }}
fixed = {{ theta0 = {DRIVEN_THETA0:?} }}
[[experiments.inputs]]
model = "armTorque"
measured = "motor_torque_Nm"
{driven_parameters}
{SEARCH}"#,
        r.swing.display(),
        r.driven.display(),
        head = head(),
    )
}

fn load(dir: &Path, name: &str, text: &str) -> Campaign {
    Campaign::load(&write(dir, &format!("{name}.toml"), text)).unwrap()
}

/// `point[i]` within 1% of `truth`.
#[track_caller]
fn within_1_percent(what: &str, value: f64, truth: f64) {
    assert!(
        (value / truth - 1.0).abs() < 0.01,
        "{what}: {value:.6e} vs the truth {truth:.6e}"
    );
}

/// The noise floor of a calibration: 2 outputs × every sample of each experiment.
fn floor(c: &Calibration) -> f64 {
    c.objective
        .experiments()
        .map(|e| synthetic_noise_floor(e.outputs.len(), e.grid.len()))
        .sum()
}

fn summary(label: &str, c: &Calibration, r: &Records) -> String {
    let best = c.best_run();
    format!(
        "{label}: armFriction {:.6e} ({:+.3}%), pendulumFriction {:.6e} ({:+.3}%), objective \
         {:.5} (noise floor {:.5}), {} evaluations",
        best.point[0],
        100.0 * (best.point[0] / r.arm - 1.0),
        best.point[1],
        100.0 * (best.point[1] / r.pendulum - 1.0),
        best.objective,
        floor(c),
        c.evaluations()
    )
}

/// The 95% profile interval's width of `name`, which must be closed on both sides.
fn width(s: &Profiles, name: &str) -> f64 {
    let p = s.profiles.iter().find(|p| p.name == name).unwrap();
    let (Some(low), Some(high)) = (p.ci_low(), p.ci_high()) else {
        panic!(
            "{name} of {} is not identifiable: {:?}",
            s.campaign,
            p.conclusion()
        );
    };
    assert!(low < p.value && p.value < high, "{name}: [{low}, {high}]");
    high - low
}

/// Each record alone and both together recover the frictions within 1%; together at the
/// noise floor of both records; and the profile intervals of both together are no wider
/// than those of the better record alone.
#[test]
fn two_records_pin_the_frictions_at_least_as_tightly_as_the_better_one() {
    let Some(r) = records() else { return };
    let dir = tempfile::tempdir().unwrap();
    let campaigns = [
        (
            "swing",
            load(
                dir.path(),
                "swing",
                &one_record("swing", &r.swing, SWING_THETA0, "", &window()),
            ),
        ),
        (
            "driven",
            load(
                dir.path(),
                "driven",
                &one_record("driven", &r.driven, DRIVEN_THETA0, TORQUE_INPUT, &window()),
            ),
        ),
        ("both", load(dir.path(), "both", &both(&r, ""))),
    ];
    let settings = Settings::default();
    let mut profiles = Vec::new();
    for (label, campaign) in &campaigns {
        let store = MemoryStore::new();
        let c = calibrate_with_store(campaign, LocalEvaluator, &store, &Silent).unwrap();
        println!("{}", summary(label, &c, &r));
        let best = c.best_run();
        within_1_percent(&format!("{label}: armFriction"), best.point[0], r.arm);
        within_1_percent(
            &format!("{label}: pendulumFriction"),
            best.point[1],
            r.pendulum,
        );
        let floor = floor(&c);
        if *label == "both" {
            assert_eq!(c.objective.more.len(), 1);
            assert_eq!(
                c.objective.grid.len() + c.objective.more[0].grid.len(),
                4002
            );
            assert!(
                best.objective <= 1.5 * floor,
                "both: objective {} vs the summed noise floor {floor}",
                best.objective
            );
        }
        // The profile starts from the calibration just stored.
        let s = profile(campaign, &LocalEvaluator, &store, &settings).unwrap();
        assert_eq!(s.best_from, BestFrom::Store);
        assert_eq!(s.best, best.point);
        println!("{}", report::table(&s));
        profiles.push(s);
    }
    // The threshold and the linearised intervals count every sample of every experiment:
    // the linearised interval of both records agrees with their profile.
    let both = &profiles[2];
    assert_eq!(both.threshold.samples, 2 * 2 * 2001);
    for p in &both.profiles {
        let ratio = (p.linearised.ci_high - p.linearised.ci_low) / width(both, &p.name);
        assert!(
            (0.8..=1.25).contains(&ratio),
            "{}: linearised width {ratio:.3} times the profile's",
            p.name
        );
    }
    println!(
        "95% profile interval widths\n{:<18} {:>12} {:>12} {:>12} {:>8}",
        "parameter", "swing", "driven", "both", "both/min"
    );
    let mut ratios = Vec::new();
    for name in ["armFriction", "pendulumFriction"] {
        let w: Vec<f64> = profiles.iter().map(|s| width(s, name)).collect();
        let ratio = w[2] / w[0].min(w[1]);
        println!(
            "{name:<18} {:>12.4e} {:>12.4e} {:>12.4e} {ratio:>8.3}",
            w[0], w[1], w[2]
        );
        ratios.push((name, ratio));
    }
    // Two independent records add their information: the combined interval is narrower
    // than either alone (1/w² ≈ 1/w_a² + 1/w_b² on a linear model). The slack covers what the
    // threshold estimates from each fit's own residual: its variance s² and its correlation
    // N/N_eff (the largest lag-1 autocorrelation of any series), which may differ by a few
    // per cent between the records and the pair.
    for (name, ratio) in ratios {
        assert!(
            ratio <= 1.05,
            "{name}: both records give an interval {ratio:.3} times the narrower alone"
        );
    }
}

/// The driven record's start angle, free in that experiment alone and started 0.05 rad off,
/// is found within 1e-3 rad while the shared frictions still land within 1%.
#[test]
fn a_start_angle_free_in_one_experiment_is_found() {
    let Some(r) = records() else { return };
    let dir = tempfile::tempdir().unwrap();
    // theta0 is fixed for the driven experiment by `fixed` in `both`: free it instead.
    let text = both(
        &r,
        &format!(
            "[[experiments.parameters]]\nname = \"theta0\"\nnominal = {:?}\nmin = 2.5\nmax = 3.1\n",
            DRIVEN_THETA0 - 0.05
        ),
    )
    .replace(
        &format!("fixed = {{ theta0 = {DRIVEN_THETA0:?} }}\n[[experiments.inputs]]"),
        "[[experiments.inputs]]",
    );
    let campaign = load(dir.path(), "both", &text);
    let names: Vec<&str> = campaign.free.iter().map(|p| p.name.as_str()).collect();
    assert_eq!(names, ["armFriction", "pendulumFriction", "theta0@driven"]);
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    println!(
        "{}, theta0@driven {:.6} ({:+.2e} rad off the truth, started {:+.2e})",
        summary("both, theta0@driven free", &c, &r),
        best.point[2],
        best.point[2] - DRIVEN_THETA0,
        -0.05
    );
    within_1_percent("armFriction", best.point[0], r.arm);
    within_1_percent("pendulumFriction", best.point[1], r.pendulum);
    assert!(
        (best.point[2] - DRIVEN_THETA0).abs() < 1e-3,
        "theta0@driven {} vs {DRIVEN_THETA0}",
        best.point[2]
    );
    assert!(best.objective <= 1.5 * floor(&c));
}

/// Workers give the very numbers of this process for two experiments: best point and
/// objective bit for bit.
#[test]
fn two_experiments_on_workers_equal_the_local_run() {
    let Some(r) = records() else { return };
    let dir = tempfile::tempdir().unwrap();
    let campaign = load(dir.path(), "both", &both(&r, ""));
    let local = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let cluster = TestCluster::start(2, 2);
    let remote = cluster.connect();
    let on_workers = calibrate(&campaign, remote.evaluator(), &Silent).unwrap();
    let (a, b) = (local.best_run(), on_workers.best_run());
    println!(
        "local {:?} {:.17e}; workers {:?} {:.17e}; {} simulations on the workers",
        a.point,
        a.objective,
        b.point,
        b.objective,
        cluster.simulations()
    );
    assert_eq!(
        a.point.iter().map(|v| v.to_bits()).collect::<Vec<_>>(),
        b.point.iter().map(|v| v.to_bits()).collect::<Vec<_>>()
    );
    assert_eq!(a.objective.to_bits(), b.objective.to_bits());
    assert_eq!(local.runs.len(), on_workers.runs.len());
    for (x, y) in local.runs.iter().zip(&on_workers.runs) {
        assert_eq!(x.point, y.point);
        assert_eq!(x.objective.to_bits(), y.objective.to_bits());
    }
    assert_eq!(
        local.best_evaluation.sse, on_workers.best_evaluation.sse,
        "each experiment's errors"
    );
    assert!(cluster.simulations() > 0);
    within_1_percent("armFriction", b.point[0], r.arm);
    within_1_percent("pendulumFriction", b.point[1], r.pendulum);
}

/// `windows = [[0, 5], [10, 20]]`: the grid holds the samples of those intervals alone, and
/// the fit still finds the frictions at the noise floor of those samples.
#[test]
fn disjoint_windows_fit_only_their_samples() {
    let Some(r) = records() else { return };
    let dir = tempfile::tempdir().unwrap();
    let campaign = load(
        dir.path(),
        "gaps",
        &one_record(
            "gaps",
            &r.driven,
            DRIVEN_THETA0,
            TORQUE_INPUT,
            "windows = [[0.0, 5.0], [10.0, 20.0]]",
        ),
    );
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    println!("{}", summary("driven, windows [0, 5] and [10, 20]", &c, &r));
    let grid = &c.objective.grid;
    // 100 Hz: 501 samples in [0, 5] and 1001 in [10, 20], none in between.
    assert_eq!(grid.len(), 501 + 1001);
    assert!(grid
        .iter()
        .all(|&t| (0.0..=5.0 + 1e-9).contains(&t) || (10.0 - 1e-9..=20.0 + 1e-9).contains(&t)));
    assert!(grid.iter().any(|&t| t > 19.99) && grid.iter().any(|&t| (t - 5.0).abs() < 1e-9));
    let best = c.best_run();
    within_1_percent("armFriction", best.point[0], r.arm);
    within_1_percent("pendulumFriction", best.point[1], r.pendulum);
    assert!(best.objective <= 1.5 * floor(&c));
    let json = calib_analysis::report::result_json(&c);
    assert_eq!(
        json["window"]["windows"],
        serde_json::json!([[0.0, 5.0], [10.0, 20.0]])
    );
}

/// `examples/data/furuta_driven.csv` is exactly what the command in
/// `examples/furuta_driven.toml` writes.
#[test]
fn the_driven_examples_record_is_what_its_command_makes() {
    let example = std::fs::read_to_string(repo().join("examples/furuta_driven.toml")).unwrap();
    assert!(
        example.contains(
            "python3 tests/python/furuta_driven.py --out examples/data/furuta_driven.csv \\\n\
             #       --stop 20 --theta0 2.8 --seed 5"
        ),
        "the example names the command this test runs"
    );
    let dir = tempfile::tempdir().unwrap();
    let Some((csv, _)) = record(
        dir.path(),
        "driven.csv",
        &["--theta0", "2.8", "--seed", "5"],
    ) else {
        return;
    };
    assert!(
        std::fs::read(&csv).unwrap()
            == std::fs::read(repo().join("examples/data/furuta_driven.csv")).unwrap(),
        "furuta_driven.py no longer writes examples/data/furuta_driven.csv"
    );
}

/// `examples/furuta_driven.toml` recovers the frictions of `examples/data/furuta_rig.json`.
#[test]
fn the_driven_example_fits_the_true_frictions() {
    let campaign = Campaign::load(&repo().join("examples/furuta_driven.toml")).unwrap();
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let (arm, pendulum) = true_frictions();
    let best = c.best_run();
    println!(
        "examples/furuta_driven.toml: armFriction {:.6e}, pendulumFriction {:.6e}, objective \
         {:.5} (noise floor {:.5}), {} evaluations",
        best.point[0],
        best.point[1],
        best.objective,
        floor(&c),
        c.evaluations()
    );
    within_1_percent("armFriction", best.point[0], arm);
    within_1_percent("pendulumFriction", best.point[1], pendulum);
    assert!(best.objective <= 1.5 * floor(&c));
}

/// `calib calibrate examples/furuta_experiments.toml`: a plot per experiment and output and
/// per driven input, each experiment's share of the fit in result.json, the numbers of the
/// library's run; the analyses that take one record refuse it, saying why.
#[test]
fn calibrate_writes_each_experiments_plots_and_share_of_the_fit() {
    let example = repo().join("examples/furuta_experiments.toml");
    let dir = tempfile::tempdir().unwrap();
    let (db, out) = (dir.path().join("db"), dir.path().join("out"));
    let json = calibrate_json(&example, &db, &out, &[]);
    let folder = out.join("furuta_experiments");
    for file in [
        "result.json",
        "swing.armJoint.phi.svg",
        "swing.pendulumJoint.phi.svg",
        "driven.armJoint.phi.svg",
        "driven.pendulumJoint.phi.svg",
        "driven.input.armTorque.svg",
        "waterfall.svg",
    ] {
        assert!(folder.join(file).exists(), "{file} was not written");
    }
    // The free swing is not driven: no input plot, and no plot without an experiment's name.
    assert!(!folder.join("swing.input.armTorque.svg").exists());
    assert!(!folder.join("armJoint.phi.svg").exists());
    let input = std::fs::read_to_string(folder.join("driven.input.armTorque.svg")).unwrap();
    assert!(input.contains("armTorque") && input.contains("linear"));
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("result.json")).unwrap())
            .unwrap();
    assert_eq!(json, written);

    // The library's run of the same campaign: the same best point, objective and shares.
    let campaign = Campaign::load(&example).unwrap();
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    for (i, name) in ["armFriction", "pendulumFriction", "theta0@driven"]
        .iter()
        .enumerate()
    {
        assert_eq!(
            json["best"]["parameters"][name].as_f64(),
            Some(best.point[i]),
            "{name}"
        );
    }
    assert_eq!(json["best"]["objective"].as_f64(), Some(best.objective));
    assert_eq!(
        json["experiments"],
        calib_analysis::report::result_json(&c)["experiments"]
    );

    let experiments = json["experiments"].as_array().unwrap();
    assert_eq!(experiments.len(), 2);
    let (swing, driven) = (&experiments[0], &experiments[1]);
    assert_eq!(swing["name"], "swing");
    assert_eq!(driven["name"], "driven");
    assert_eq!(swing["samples"], 4001);
    assert_eq!(driven["samples"], 2001);
    assert_eq!(swing["windows"], serde_json::json!([[0.0, 40.0]]));
    assert_eq!(swing["inputs"], serde_json::json!([]));
    assert_eq!(
        driven["inputs"],
        serde_json::json!([{"model": "armTorque", "measured": "motor_torque_Nm",
                            "interpolation": "linear"}])
    );
    let shares: Vec<f64> = experiments
        .iter()
        .map(|e| e["objective"].as_f64().unwrap())
        .collect();
    println!(
        "calib calibrate {}: armFriction {:.6e}, pendulumFriction {:.6e}, theta0@driven {:.6}, \
         objective {:.5} = swing {:.5} + driven {:.5}",
        example.display(),
        best.point[0],
        best.point[1],
        best.point[2],
        best.objective,
        shares[0],
        shares[1]
    );
    assert!(((shares[0] + shares[1]) / best.objective - 1.0).abs() < 1e-12);
    for (e, share) in experiments.iter().zip(&shares) {
        let samples = e["samples"].as_u64().unwrap() as usize;
        let floor = synthetic_noise_floor(2, samples);
        assert!(*share <= 1.5 * floor, "{}: {share} vs {floor}", e["name"]);
        let sse: f64 = ["armJoint.phi", "pendulumJoint.phi"]
            .iter()
            .map(|o| e["sse"][o].as_f64().unwrap())
            .sum();
        assert!((sse / share - 1.0).abs() < 1e-12, "weights are 1");
    }
    let (arm, pendulum) = true_frictions();
    within_1_percent("armFriction", best.point[0], arm);
    within_1_percent("pendulumFriction", best.point[1], pendulum);
    assert!(
        (best.point[2] - 2.8).abs() < 1e-3,
        "theta0@driven {}",
        best.point[2]
    );

    // The diagnosis takes one record.
    let refused = calib(&[
        "diagnose",
        example.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&refused.stderr);
    assert_eq!(refused.status.code(), Some(2), "diagnose: {stderr}");
    assert!(
        stderr.contains("this campaign fits 2 experiments together"),
        "diagnose: {stderr}"
    );
    // The sensitivity analysis reports every experiment's outputs, each named after its
    // experiment.
    let analysed = calib(&[
        "sensitivity",
        example.to_str().unwrap(),
        "--samples",
        "8",
        "--db",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ]);
    let stderr = String::from_utf8_lossy(&analysed.stderr);
    assert!(analysed.status.success(), "sensitivity: {stderr}");
    let stdout = String::from_utf8_lossy(&analysed.stdout);
    for series in [
        "swing: armJoint.phi",
        "swing: pendulumJoint.phi",
        "driven: armJoint.phi",
        "driven: pendulumJoint.phi",
    ] {
        assert!(stdout.contains(series), "`{series}` missing from {stdout}");
    }
}
