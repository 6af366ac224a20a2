//! The `calib` command line: what users see, including every kind of bad input.

use crate::common::*;
use std::path::Path;

/// Run `calib calibrate` on a campaign and expect a clean failure with exit code 2 whose
/// message contains every fragment.
fn expect_bad_input(campaign: &Path, fragments: &[&str]) {
    let out = calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--out",
        "/dev/null/never",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {stderr}");
    assert!(!stderr.contains("panicked"), "{stderr}");
    for f in fragments {
        assert!(stderr.contains(f), "`{f}` missing from: {stderr}");
    }
}

/// A clean campaign with one text replacement, written to a temporary folder.
fn campaign_with(dir: &Path, from: &str, to: &str) -> std::path::PathBuf {
    let text = clean_campaign("methods = [\"nelder-mead\"]\nmax_evaluations = 50");
    let changed = text.replacen(from, to, 1);
    assert_ne!(changed, text, "`{from}` not in the campaign");
    write(dir, "c.toml", &changed)
}

/// A campaign over a CSV file with the given content.
fn campaign_on_csv(dir: &Path, csv: &str) -> std::path::PathBuf {
    let data = write(dir, "data.csv", csv);
    let clean = repo().join("examples/data/furuta_clean.csv");
    campaign_with(dir, clean.to_str().unwrap(), data.to_str().unwrap())
}

#[test]
fn missing_campaign_file() {
    let dir = tempfile::tempdir().unwrap();
    expect_bad_input(&dir.path().join("nope.toml"), &["nope.toml"]);
}

#[test]
fn unknown_key_is_rejected_with_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_with(dir.path(), "stop = 40.0", "stop = 40.0\ncolour = \"red\"");
    expect_bad_input(&c, &["c.toml:", "colour"]);
}

#[test]
fn unknown_model() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_with(dir.path(), "name = \"furuta\"", "name = \"furuta9\"");
    expect_bad_input(&c, &["c.toml:4", "unknown model `furuta9`"]);
}

#[test]
fn unknown_parameter() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_with(dir.path(), "name = \"armFriction\"", "name = \"armFrict\"");
    expect_bad_input(
        &c,
        &[
            "c.toml:",
            "no parameter `armFrict`; did you mean `armFriction`?",
        ],
    );
    // The nearest name, not every name the model has.
    let out = calib(&["calibrate", c.to_str().unwrap(), "--out", "/dev/null/never"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("pendulumFriction"), "{stderr}");
}

#[test]
fn simulate_suggests_the_nearest_name_and_keeps_the_workers_limits() {
    let stderr_of = |args: &[&str]| {
        let out = calib(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = stderr_of(&["simulate", "furuta", "--set", "armFrict=0.01"]);
    assert!(
        e.contains("--set armFrict=0.01: model `furuta` has no parameter `armFrict`; did you mean `armFriction`?"),
        "{e}"
    );
    assert!(!e.contains("pendulumFriction"), "{e}");
    let e = stderr_of(&["simulate", "furtua"]);
    assert!(
        e.contains("unknown model `furtua`; did you mean `furuta`?"),
        "{e}"
    );
    let e = stderr_of(&["simulate", "furuta", "--outputs", "armJoint.ph"]);
    assert!(e.contains("did you mean `armJoint.phi`?"), "{e}");
    // The same limits as a worker's request: rtol, grid length, stop time.
    let e = stderr_of(&["simulate", "furuta", "--rtol", "0.5"]);
    assert!(e.contains("--rtol 0.5: 0.5 is not in [1e-14, 0.1]"), "{e}");
    let e = stderr_of(&["simulate", "furuta", "--stop", "10", "--step", "1e-5"]);
    assert!(e.contains("at most 500000 rows"), "{e}");
    let e = stderr_of(&["simulate", "furuta", "--stop", "2e6", "--step", "10"]);
    assert!(e.contains("beyond what calib simulates"), "{e}");
}

#[test]
fn unknown_output() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_with(
        dir.path(),
        "model = \"armJoint.phi\"",
        "model = \"armJoint.angle\"",
    );
    expect_bad_input(&c, &["c.toml:", "armJoint.angle", "no output"]);
}

#[test]
fn nominal_outside_bounds() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_with(dir.path(), "nominal = 0.012", "nominal = 1.2");
    expect_bad_input(&c, &["c.toml:", "armFriction", "outside its bounds"]);
}

#[test]
fn min_not_below_max() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_with(dir.path(), "min = 0.0\nmax = 0.9", "min = 0.9\nmax = 0.9");
    expect_bad_input(&c, &["c.toml:", "armFriction", "must be below max"]);
}

#[test]
fn window_outside_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_with(dir.path(), "stop = 40.0", "stop = 50.0");
    expect_bad_input(&c, &["c.toml", "window", "outside the data"]);
}

#[test]
fn missing_measurement_file() {
    let dir = tempfile::tempdir().unwrap();
    let clean = repo().join("examples/data/furuta_clean.csv");
    let c = campaign_with(dir.path(), clean.to_str().unwrap(), "/nonexistent/rig.csv");
    expect_bad_input(&c, &["/nonexistent/rig.csv"]);
}

#[test]
fn missing_column() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_on_csv(dir.path(), "time_s,arm_angle_rad\n0,0\n1,0\n");
    expect_bad_input(&c, &["data.csv", "pendulum_angle_rad"]);
}

#[test]
fn non_numeric_cell() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_on_csv(
        dir.path(),
        "time_s,arm_angle_rad,pendulum_angle_rad\n0,0,0.5\n1,zero,0.5\n2,0,0.5\n",
    );
    expect_bad_input(&c, &["data.csv", "3", "zero"]);
}

#[test]
fn time_not_increasing() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_on_csv(
        dir.path(),
        "time_s,arm_angle_rad,pendulum_angle_rad\n0,0,0.5\n2,0,0.5\n1,0,0.5\n",
    );
    expect_bad_input(&c, &["data.csv", "4"]);
}

#[test]
fn nan_in_the_data() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_on_csv(
        dir.path(),
        "time_s,arm_angle_rad,pendulum_angle_rad\n0,0,0.5\n1,NaN,0.5\n2,0,0.5\n",
    );
    expect_bad_input(&c, &["data.csv", "3", "arm_angle_rad"]);
}

#[test]
fn empty_data() {
    let dir = tempfile::tempdir().unwrap();
    let c = campaign_on_csv(dir.path(), "time_s,arm_angle_rad,pendulum_angle_rad\n");
    expect_bad_input(&c, &["data.csv"]);
}

#[test]
fn models_lists_the_furuta_contract() {
    let out = calib(&["models"]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for name in [
        "furuta",
        "armFriction",
        "pendulumFriction",
        "pend_Ixx",
        "armJoint.phi",
        "pendulumJoint.w",
        "viscous_friction.arm",
        "armTorque",
        "T_air_in",
    ] {
        assert!(text.contains(name), "`{name}` missing from: {text}");
    }
    let out = calib(&["models", "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json[0]["name"], "furuta");
}

#[test]
fn simulate_writes_a_trajectory_csv() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("sim.csv");
    let out = calib(&[
        "simulate",
        "furuta",
        "--set",
        "armFriction=0.01",
        "--stop",
        "40",
        "--step",
        "0.01",
        "--out",
        path.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&path).unwrap();
    let mut lines = text.lines();
    assert_eq!(
        lines.next().unwrap(),
        "time,armJoint.phi,pendulumJoint.phi,armJoint.w,pendulumJoint.w"
    );
    assert_eq!(lines.count(), 4001);
    let bad = calib(&["simulate", "furuta", "--set", "armFriction=x"]);
    assert_eq!(bad.status.code(), Some(2));
    let bad = calib(&["simulate", "furuta", "--set", "nope=1"]);
    assert_eq!(bad.status.code(), Some(2));
}

/// `--input` drives a model input by a profile and writes it as a column; `--noise` on it
/// perturbs the column only (the model follows the profile, as a bench's sensor records it).
#[test]
fn simulate_drives_inputs_by_profiles() {
    let run = |extra: &[&str]| {
        let mut args = vec![
            "simulate",
            "furuta",
            "--stop",
            "2",
            "--step",
            "0.5",
            "--input",
            "armTorque=0:0,1:0.05",
        ];
        args.extend_from_slice(extra);
        let out = calib(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let text = String::from_utf8(out.stdout).unwrap();
        let rows: Vec<Vec<String>> = text
            .lines()
            .map(|l| l.split(',').map(String::from).collect())
            .collect();
        rows
    };
    let clean = run(&[]);
    assert_eq!(
        clean[0].join(","),
        "time,armTorque,armJoint.phi,pendulumJoint.phi,armJoint.w,pendulumJoint.w"
    );
    let torque: Vec<f64> = clean[1..].iter().map(|r| r[1].parse().unwrap()).collect();
    assert_eq!(torque, [0.0, 0.025, 0.05, 0.05, 0.05]);
    let noisy = run(&["--noise", "armTorque=0.01"]);
    for (c, n) in clean[1..].iter().zip(&noisy[1..]) {
        assert_ne!(c[1], n[1]);
        assert_eq!(
            c[2..],
            n[2..],
            "the model follows the profile, not the noise"
        );
    }
    // Driven, the arm turns; free, it would not.
    let free = calib(&["simulate", "furuta", "--stop", "2", "--step", "0.5"]);
    let free = String::from_utf8(free.stdout).unwrap();
    let free_phi: f64 = free
        .lines()
        .last()
        .unwrap()
        .split(',')
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    let driven_phi: f64 = clean.last().unwrap()[2].parse().unwrap();
    assert!(
        (driven_phi - free_phi).abs() > 0.1,
        "{driven_phi} vs {free_phi}"
    );

    let stderr_of = |args: &[&str]| {
        let out = calib(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let e = stderr_of(&["simulate", "furuta", "--input", "armTorqe=0:1"]);
    assert!(e.contains("did you mean `armTorque`"), "{e}");
    let e = stderr_of(&["simulate", "furuta", "--input", "armTorque=0:1,x"]);
    assert!(e.contains("`x` is not TIME:VALUE"), "{e}");
    let e = stderr_of(&["simulate", "furuta", "--input", "armTorque=2:1,1:0"]);
    assert!(e.contains("non-decreasing"), "{e}");
    let e = stderr_of(&["simulate", "furuta", "--noise", "armTorque=0.1"]);
    assert!(
        e.contains("neither a written output nor a driven input"),
        "{e}"
    );
}

/// `calib simulate --input`: a constant motor torque from a file drives the Furuta's arm as
/// the opposite torque bias does, to the bit (the same sum in the equations of motion), held
/// or read linearly; a column that names no input gets the nearest name; a file that stops
/// before the simulation is refused.
#[test]
fn simulate_drives_a_model_from_an_input_file() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| -> String {
        let out = calib(args);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let torque = write(
        dir.path(),
        "torque.csv",
        "time,armTorque\n0,0.02\n2.5,0.02\n5,0.02\n",
    );
    let torque = torque.to_str().unwrap();
    let common = ["simulate", "furuta", "--stop", "5", "--step", "0.01"];
    let driven = run(&[&common[..], &["--input", torque]].concat());
    let held = run(&[
        &common[..],
        &["--input", torque, "--input-interpolation", "hold"],
    ]
    .concat());
    let biased = run(&[&common[..], &["--set", "torque_bias.arm=-0.02"]].concat());
    let free = run(&common);
    assert_eq!(driven, biased);
    assert_eq!(held, biased);
    assert_ne!(driven, free, "the torque moves the arm");
    assert_eq!(driven.lines().count(), 502);

    let stderr_of = |args: &[&str]| {
        let out = calib(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let typo = write(dir.path(), "typo.csv", "time,armTorq\n0,0.02\n5,0.02\n");
    let e = stderr_of(&[
        "simulate",
        "furuta",
        "--stop",
        "5",
        "--input",
        typo.to_str().unwrap(),
    ]);
    assert!(
        e.contains(
            "column `armTorq`: model `furuta` has no input `armTorq`; did you mean `armTorque`?"
        ),
        "{e}"
    );
    let short = write(dir.path(), "short.csv", "time,armTorque\n0,0.02\n2,0.02\n");
    let e = stderr_of(&[
        "simulate",
        "furuta",
        "--stop",
        "5",
        "--input",
        short.to_str().unwrap(),
    ]);
    assert!(
        e.contains("do not cover the simulation from 0 to 5 s"),
        "{e}"
    );
    let e = stderr_of(&["simulate", "furuta", "--input-interpolation", "hold"]);
    assert!(e.contains("--input"), "{e}");
}

/// `calib models` lists every model's inputs, or says it has none.
#[test]
fn models_lists_inputs() {
    let out = calib(&["models"]);
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("armTorque"), "{text}");
    let out = calib(&["models", "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(json[0]["inputs"][0]["name"], "armTorque");
    assert_eq!(json[0]["inputs"][0]["unit"], "N.m");
}

#[test]
fn calibrate_writes_the_result_and_plots() {
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\"]\nstarts = 1\nmax_evaluations = 200";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let out = calib(&["calibrate", campaign.to_str().unwrap(), "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let results = dir.path().join("results/clean");
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(results.join("result.json")).unwrap())
            .unwrap();
    assert_eq!(json, written);
    assert!(
        json["best"]["objective"].as_f64().unwrap() < json["nominal_objective"].as_f64().unwrap()
    );
    assert!(json["best"]["parameters"]["armFriction"].is_f64());
    let run = &json["runs"][0];
    for key in [
        "method",
        "start",
        "parameters",
        "objective",
        "evaluations",
        "iterations",
    ] {
        assert!(!run[key].is_null(), "runs[0].{key} missing");
    }
    assert!(json["evaluations"].as_u64().unwrap() > 10);
    for plot in ["armJoint.phi.svg", "pendulumJoint.phi.svg"] {
        let svg = std::fs::read_to_string(results.join(plot)).unwrap();
        assert!(svg.contains("<svg") && svg.contains("calibrated"), "{plot}");
    }
}

/// A `calib worker` process, killed when dropped.
struct WorkerProcess {
    child: std::process::Child,
    address: String,
}

impl WorkerProcess {
    fn start() -> Self {
        use std::io::BufRead;
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
            .args(["worker", "--listen", "127.0.0.1:0", "--slots", "1"])
            .stdout(std::process::Stdio::piped())
            .spawn()
            .expect("start calib worker");
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        let address = line
            .strip_prefix("worker listening on ")
            .and_then(|rest| rest.split_whitespace().next())
            .unwrap_or_else(|| panic!("unexpected first line: {line}"))
            .to_string();
        Self { child, address }
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A campaign over a worker process gives what the same campaign gives in this process, bit
/// for bit, and the worker simulated every point of it. Each run has its own store, so
/// neither replays the other.
#[test]
fn calibrate_over_a_worker_process() {
    let worker = WorkerProcess::start();
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\"]\nmax_evaluations = 40\nseed = 2";
    let campaign = write(dir.path(), "c.toml", &clean_campaign(search));
    let workers = format!("http://{}", worker.address);
    let run = |name: &str, extra: &[&str]| {
        let out_dir = dir.path().join(name).join("out");
        let db = dir.path().join(name).join("db");
        let mut args = vec![
            "calibrate",
            campaign.to_str().unwrap(),
            "--out",
            out_dir.to_str().unwrap(),
            "--db",
            db.to_str().unwrap(),
            "--json",
        ];
        args.extend_from_slice(extra);
        let out = calib(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let mut json: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        json.as_object_mut().unwrap().remove("elapsed_seconds");
        let stats = calib(&["store", "stats", "--db", db.to_str().unwrap(), "--json"]);
        assert!(stats.status.success());
        let stats: serde_json::Value = serde_json::from_slice(&stats.stdout).unwrap();
        (json, stats["evaluations"].as_u64().unwrap())
    };
    let (remote, remote_stored) = run("remote", &["--workers", &workers]);
    let (local, local_stored) = run("local", &[]);
    let simulated = remote["simulated"].as_u64().unwrap();
    // Each run simulated its points itself, into its own store.
    assert!(simulated > 0, "{remote}");
    assert_eq!(local["simulated"], simulated, "{local}");
    assert_eq!((remote_stored, local_stored), (simulated, simulated));
    // The worker process, not this one, simulated the remote run's points.
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    let status = runtime.block_on(async {
        calib_proto::v1::simulator_client::SimulatorClient::connect(workers.clone())
            .await
            .unwrap()
            .status(calib_proto::v1::StatusRequest {
                protocol_version: calib_proto::PROTOCOL_VERSION,
            })
            .await
            .unwrap()
            .into_inner()
    });
    assert_eq!(status.simulations, simulated, "{status:?}");
    // Every run, every best figure, every count: the same numbers, written the same way
    // (shortest round-trip form, so equal text is equal bits).
    assert_eq!(remote.to_string(), local.to_string());
}

/// An address another process holds is the machine's state, not the user's mistake: every
/// serving command exits 1 (not 2), naming the option and the address.
#[test]
fn an_address_in_use_is_the_environments_failure() {
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let address = held.local_addr().unwrap().to_string();
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("db");
    let db = db.to_str().unwrap();
    let commands: [(&[&str], &str); 4] = [
        (
            &["ui", "--listen", &address, "--db", db, "--no-open"],
            "--listen",
        ),
        (
            &[
                "coordinator",
                "--listen",
                "127.0.0.1:0",
                "--http",
                &address,
                "--db",
                db,
            ],
            "--http",
        ),
        (
            &["coordinator", "--listen", &address, "--db", db],
            "--listen",
        ),
        (&["worker", "--listen", &address], "--listen"),
    ];
    for (args, option) in commands {
        let out = calib(args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {stderr}");
        assert!(
            stderr.contains(&format!("{option} {address}")) && stderr.contains("cannot listen"),
            "{args:?}: {stderr}"
        );
    }
}

#[test]
fn bad_worker_addresses_are_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = write(
        dir.path(),
        "c.toml",
        &clean_campaign("methods = [\"nelder-mead\"]\nmax_evaluations = 50"),
    );
    let out = calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--workers",
        "localhost:50051",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("--workers") && stderr.contains("http://HOST:PORT"),
        "{stderr}"
    );
}

/// `calib bench` and `calib bench store` default to a campaign that ships with calib, so both
/// run on a fresh clone (from its root) without the real record beside it.
#[test]
fn benchmarks_default_to_a_campaign_that_ships() {
    for args in [&["bench", "--help"][..], &["bench", "store", "--help"][..]] {
        let out = calib(args);
        assert!(out.status.success(), "{args:?}");
        let help = String::from_utf8_lossy(&out.stdout);
        let default = help
            .split("[default: ")
            .map(|rest| rest.split(']').next().unwrap_or_default())
            .find(|value| value.ends_with(".toml"))
            .unwrap_or_else(|| panic!("no default campaign in `calib {args:?}`:\n{help}"));
        let campaign = repo().join(default);
        let loaded = calib_engine::campaign::Campaign::load(&campaign);
        assert!(
            loaded.is_ok(),
            "`calib {args:?}` defaults to {default}: {:?}",
            loaded.err()
        );
        assert!(!default.contains("real"), "{default} needs the real record");
    }
}

#[test]
fn calibrate_shows_the_runs_at_the_best_and_the_bounds_that_bind() {
    // The true arm friction (0.0101) lies above this range: the fit must end on its bound.
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\"]\nstarts = 3\nmax_evaluations = 200\nseed = 3";
    let text = clean_campaign(search).replacen(
        "nominal = 0.012\nmin = 0.0\nmax = 0.9",
        "nominal = 0.006\nmin = 0.0\nmax = 0.008",
        1,
    );
    let campaign = write(dir.path(), "bound.toml", &text);
    let out_dir = dir.path().join("out");
    let out = calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--out",
        out_dir.to_str().unwrap(),
        "--db",
        dir.path().join("db").to_str().unwrap(),
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let result: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(out_dir.join("clean").join("result.json")).unwrap(),
    )
    .unwrap();

    let best = &result["best"];
    let arm = best["parameters"]["armFriction"].as_f64().unwrap();
    assert!(arm >= 0.008 * 0.99, "{arm}");
    assert_eq!(best["at_bound"]["armFriction"], "max");
    assert!(best["at_bound"]["pendulumFriction"].is_null());
    assert!(stdout.contains("at upper bound"), "{stdout}");
    assert!(stdout.contains("sits on its upper bound 0.008"), "{stdout}");

    // The count agrees with the runs listed, and every run shows why it stopped.
    let runs = result["runs"].as_array().unwrap();
    assert_eq!(runs.len(), 3);
    let objectives: Vec<f64> = runs
        .iter()
        .map(|r| r["objective"].as_f64().unwrap())
        .collect();
    let lowest = objectives.iter().copied().fold(f64::INFINITY, f64::min);
    let within = objectives.iter().filter(|&&f| f <= lowest * 1.01).count();
    let at_best = &result["runs_at_best"];
    assert_eq!(at_best["of"], 3);
    assert_eq!(at_best["count"].as_u64().unwrap() as usize, within);
    assert_eq!(at_best["tolerance"], 0.01);
    assert!(
        stdout.contains(&format!(
            "{within} of 3 runs reached the best objective within 1%"
        )),
        "{stdout}"
    );
    assert!(stdout.contains("termination"), "{stdout}");
    for r in runs {
        let why = r["termination"].as_str().unwrap();
        assert!(!why.is_empty() && stdout.contains(why), "{why}: {stdout}");
    }

    let waterfall = std::fs::read_to_string(out_dir.join("clean").join("waterfall.svg")).unwrap();
    assert!(
        waterfall.contains(&format!("within 1% of the best ({within} of 3)")),
        "{waterfall}"
    );
}

#[test]
fn a_repeated_diagnosis_is_served_from_the_store() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = std::fs::read_to_string(repo().join("examples/furuta_viscous_arm.toml"))
        .unwrap()
        .replace(
            "data/furuta_viscous_arm.csv",
            repo()
                .join("examples/data/furuta_viscous_arm.csv")
                .to_str()
                .unwrap(),
        )
        .replace(
            "methods = [\"nelder-mead\", \"powell\"]\nstarts = 4",
            "methods = [\"nelder-mead\"]\nstarts = 2",
        )
        + "refit = 2\ncandidates = [\"viscous_friction.arm\", \"offset(armJoint.phi)\"]\n";
    let campaign = write(dir.path(), "viscous.toml", &campaign);
    let db = dir.path().join("db");
    let diagnose = |out: &str| {
        json_of(&calib(&[
            "diagnose",
            campaign.to_str().unwrap(),
            "--db",
            db.to_str().unwrap(),
            "--out",
            dir.path().join(out).to_str().unwrap(),
            "--json",
        ]))
    };
    let misses = || {
        json_of(&calib(&[
            "store",
            "stats",
            "--db",
            db.to_str().unwrap(),
            "--json",
        ]))["misses"]
            .as_u64()
            .unwrap()
    };
    let first = diagnose("out1");
    assert_eq!(
        first["selected"],
        serde_json::json!(["viscous_friction.arm"])
    );
    let at_best = &first["baseline"]["runs_at_best"];
    assert_eq!(at_best["of"], 2);
    assert!(
        (1..=2).contains(&at_best["count"].as_u64().unwrap()),
        "{at_best}"
    );
    assert!(first["final"]["parameters"]["viscous_friction.arm"]["at_bound"].is_null());
    let simulated = first["simulated"].as_u64().unwrap();
    assert!(simulated > 100, "{simulated}");
    assert_eq!(misses(), simulated);

    let second = diagnose("out2");
    assert_eq!(second["simulated"], 0);
    assert_eq!(second["cached"], second["evaluations"]);
    assert_eq!(misses(), simulated, "the second diagnosis missed the store");
    for key in ["selected", "verdict", "candidates", "final", "baseline"] {
        assert_eq!(first[key], second[key], "{key}");
    }
}

/// `calib bench --json` and `calib bench --cluster --json` print one JSON object whose named
/// figures are all there and finite (their values are the benchmark's business, not the
/// tests').
/// The number that follows `before` in `line` (up to the next space, `x` or `)`).
fn number_after(line: &str, before: &str) -> f64 {
    let rest = line
        .split_once(before)
        .unwrap_or_else(|| panic!("no {before:?} in {line:?}"))
        .1
        .trim_start();
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
        .unwrap_or(rest.len());
    rest[..end]
        .parse()
        .unwrap_or_else(|_| panic!("no number after {before:?} in {line:?}"))
}

/// `calib bench` as a fresh clone runs it: from the repository, on its default campaign (no
/// `--campaign`, nothing beside the repository), here once per measurement. It prints its
/// table (the Furuta simulation against the seed, both heat exchangers against their
/// targets, a Nelder–Mead calibration and the full multistart), every ratio the one its
/// medians give, and names the same figures in JSON. Timings are printed, never asserted.
#[test]
fn bench_runs_on_a_fresh_clone_and_prints_its_table() {
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .args(["bench", "--repeat", "1", "--json"])
        .current_dir(repo())
        .output()
        .expect("run calib");
    let figures = json_of(&out);
    let table = String::from_utf8_lossy(&out.stderr).into_owned();
    println!("{table}");
    let line = |starts: &str| -> &str {
        table
            .lines()
            .find(|l| l.trim_start().starts_with(starts))
            .unwrap_or_else(|| panic!("no line starting {starts:?} in:\n{table}"))
    };
    let lines: Vec<&str> = table.lines().collect();
    let after = |heading: &str| -> &str {
        let i = lines
            .iter()
            .position(|l| l.starts_with(heading))
            .unwrap_or_else(|| panic!("no {heading:?} in:\n{table}"));
        lines.get(i + 1).copied().unwrap_or_default()
    };
    // The Furuta simulation: its median, and how many times faster than the seed's 300 ms.
    let furuta = after("furuta, one 40 s simulation");
    let median = number_after(furuta, "median");
    assert!(median > 0.0, "{furuta}");
    assert!(furuta.contains("seed: 300 ms"), "{furuta}");
    let faster = number_after(furuta, "->");
    assert!((faster - (300.0 / median).round()).abs() <= 1.0, "{furuta}");
    assert_eq!(
        figures["furuta_ms"].as_f64().map(|v| (v * 1e3).round()),
        Some((median * 1e3).round())
    );
    // Each heat exchanger: its median against its target, the ratio and the verdict.
    assert!(line("heat exchanger, one 300 s simulation").contains("301 output points"));
    for (name, target) in [("hx_lowfi", 2.0), ("hx_highfi", 15.0)] {
        let row = line(name);
        let median = number_after(row, "median");
        assert_eq!(number_after(row, "target:"), target, "{row}");
        let ratio = number_after(row, "->");
        assert!((ratio - median / target).abs() <= 0.006, "{row}");
        // The verdict is the unrounded median's: read it only where rounding cannot flip it.
        if (median - target).abs() > 0.005 {
            let met = median <= target;
            assert!(row.ends_with(if met { "met" } else { "missed" }), "{row}");
        }
        assert!(row.ends_with("met") || row.ends_with("missed"), "{row}");
        assert_eq!(figures[format!("{name}_target_ms")].as_f64(), Some(target));
        let figure = figures[format!("{name}_ratio_to_target")].as_f64().unwrap();
        assert!((figure - ratio).abs() <= 0.006, "{figure} vs {row}");
    }
    // One Nelder–Mead calibration of the default campaign, and the full multistart.
    let nm = after("furuta: one Nelder-Mead calibration from the nominal point, one core");
    assert!(nm.contains("seed: 25 s"), "{nm}");
    let nominal = number_after(nm, "objective");
    let fitted = number_after(nm, "->");
    assert!(fitted < nominal / 100.0, "{nm}");
    let faster = number_after(nm, "seed: 25 s  ->");
    assert!(
        (faster - (25e3 / number_after(nm, "median")).round()).abs() <= 1.0,
        "{nm}"
    );
    let multi = after("furuta: full multistart (3 methods x 4 starts)");
    let evaluations = number_after(multi, "(");
    let simulated = number_after(multi, "evaluations,");
    assert!(simulated > 0.0 && simulated <= evaluations, "{multi}");
    assert!(number_after(multi, "best objective") <= fitted, "{multi}");
    for key in [
        "furuta_speedup_vs_seed",
        "hx_lowfi_ms",
        "hx_highfi_ms",
        "nelder_mead_calibration_ms",
        "multistart_calibration_ms",
    ] {
        let value = figures[key].as_f64();
        assert!(
            value.is_some_and(f64::is_finite),
            "{key} is {value:?} in {figures}"
        );
    }
}

#[test]
fn bench_json_names_every_figure() {
    // The default benchmarks' figures: `bench_runs_on_a_fresh_clone_and_prints_its_table`.
    let campaign = repo().join("examples/furuta.toml");
    let campaign = campaign.to_str().unwrap();
    let args = [
        "bench",
        "--cluster",
        "--repeat",
        "1",
        "--json",
        "--campaign",
        campaign,
    ];
    let figures = json_of(&calib(&args));
    for key in [
        "coordinator_cpu_us_per_eval",
        "coordinator_cpu_ratio_to_evaluation",
        "grpc_overhead_ratio",
        "furuta_in_process_us",
        "dispatch_efficiency_100",
        "dispatch_rate_100",
    ] {
        let value = figures[key].as_f64();
        assert!(
            value.is_some_and(f64::is_finite),
            "`calib {args:?}`: {key} is {:?} in {figures}",
            figures.get(key)
        );
    }
}

/// `calib calibrate --cpu` reports the process's CPU time per simulated point.
#[test]
fn calibrate_reports_its_cpu_per_simulated_point() {
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\"]\nstarts = 1\nmax_evaluations = 40\nseed = 3";
    let campaign = write(dir.path(), "c.toml", &clean_campaign(search));
    let db = dir.path().join("db");
    let out = calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
        "--out",
        dir.path().to_str().unwrap(),
        "--cpu",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let line = stderr
        .lines()
        .find(|l| l.starts_with("coordinator CPU: "))
        .unwrap_or_else(|| panic!("no CPU line in:\n{stderr}"));
    let per_point: f64 = line
        .split(": ")
        .nth(2)
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("no figure in {line:?}"));
    assert!(per_point.is_finite() && per_point > 0.0, "{line}");
    assert!(line.contains("simulated points"), "{line}");
}
