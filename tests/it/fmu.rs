//! Users' own models as FMUs: `calib models`, `calib simulate` and `calib calibrate` on the
//! Modelica Association's Reference FMUs (built from their sources at test time), and an FMU
//! that crashes or hangs on purpose, which costs a failed simulation and nothing more.

use crate::common::*;
use crate::reference_fmus::{read_reference, reference_fmus};
use std::path::{Path, PathBuf};

fn fmu(version: u32, model: &str) -> Option<PathBuf> {
    Some(reference_fmus()?.join(format!("fmi{version}/{model}.fmu")))
}

fn ok(out: &std::process::Output) -> String {
    assert!(
        out.status.success(),
        "calib failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn calib_models_lists_an_fmus_parameters_outputs_and_other_variables() {
    let Some(path) = fmu(2, "BouncingBall") else {
        return;
    };
    let json: serde_json::Value =
        serde_json::from_str(&ok(&calib(&["models", path.to_str().unwrap(), "--json"]))).unwrap();
    let model = &json[0];
    assert!(model["name"]
        .as_str()
        .unwrap()
        .starts_with("BouncingBall.me@"));
    let e = model["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["name"] == "e")
        .expect("parameter e");
    assert_eq!(
        (e["default"].as_f64(), e["min"].as_f64(), e["max"].as_f64()),
        (Some(0.7), Some(0.5), Some(1.0))
    );
    let outputs: Vec<&str> = model["outputs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["name"].as_str().unwrap())
        .collect();
    assert_eq!(
        outputs,
        ["h", "v", "der(h)", "der(v)"],
        "outputs first, then the other variables"
    );
    assert_eq!(model["outputs"][0]["unit"], "m");
    let text = ok(&calib(&["models", path.to_str().unwrap()]));
    assert!(text.contains("Coefficient of restitution"), "{text}");
    assert!(text.contains("offset(h)"), "{text}");

    let out = calib(&["models", "/nowhere/Model.fmu"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("/nowhere/Model.fmu"));
}

#[test]
fn calib_simulate_co_simulation_writes_the_reference_result() {
    for version in [2, 3] {
        let Some(path) = fmu(version, "VanDerPol") else {
            return;
        };
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("sim.csv");
        ok(&calib(&[
            "simulate",
            path.to_str().unwrap(),
            "--interface",
            "co-simulation",
            "--stop",
            "20",
            "--step",
            "0.01",
            "--outputs",
            "x0,x1",
            "--out",
            csv.to_str().unwrap(),
        ]));
        let (_, ours) = read_reference(&csv);
        let (_, reference) = read_reference(&path.with_file_name("VanDerPol_ref.csv"));
        assert_eq!(ours.len(), reference.len());
        let worst = ours
            .iter()
            .zip(&reference)
            .flat_map(|(a, b)| [(a[1] - b[1]).abs(), (a[2] - b[2]).abs()])
            .fold(0.0, f64::max);
        assert!(worst < 1e-12, "FMI {version}: {worst:e}");
    }
}

/// A noisy record of `model` made by FMPy, the independent simulator.
fn record(
    fmu: &Path,
    dir: &Path,
    set: &str,
    stop: &str,
    step: &str,
    noise: &[&str],
    outputs: &str,
) -> PathBuf {
    fmu_record(
        fmu,
        &dir.join("record.csv"),
        &[set],
        stop,
        step,
        noise,
        outputs,
    )
}

#[test]
fn a_campaign_on_the_van_der_pol_fmu_recovers_mu_from_a_noisy_record() {
    let Some(path) = fmu(2, "VanDerPol") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let campaign = van_der_pol_example(&path, dir.path());
    let result = calibrate_json(
        &campaign,
        &dir.path().join("db"),
        &dir.path().join("out"),
        &[],
    );
    let mu = result["best"]["parameters"]["mu"].as_f64().unwrap();
    assert!((mu / 1.7 - 1.0).abs() < 0.005, "mu = {mu}");
    assert_eq!(result["failed"], 0);
    assert!(result["model"]
        .as_str()
        .unwrap()
        .starts_with("VanDerPol.me@"));
}

#[test]
fn a_campaign_on_the_bouncing_ball_recovers_the_restitution_from_bounce_heights() {
    let Some(path) = fmu(2, "BouncingBall") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let data = record(&path, dir.path(), "e=0.8", "3", "0.01", &["h=0.005"], "h");
    let text = format!(
        r#"
[model]
fmu = "{}"
[measurement]
file = "{}"
[[outputs]]
model = "h"
measured = "h"
[[parameters]]
name = "e"
nominal = 0.7
min = 0.5
max = 1.0
[window]
start = 0.0
stop = 3.0
[search]
methods = ["nelder-mead"]
starts = 3
max_evaluations = 200
"#,
        path.display(),
        data.display()
    );
    let campaign = write(dir.path(), "ball.toml", &text);
    let result = calibrate_json(
        &campaign,
        &dir.path().join("db"),
        &dir.path().join("out"),
        &[],
    );
    let e = result["best"]["parameters"]["e"].as_f64().unwrap();
    assert!((e / 0.8 - 1.0).abs() < 0.005, "e = {e}");
}

/// The misbehaving FMU of `tests/crash_fmu/`, built with the C compiler.
fn crash_fmu(dir: &Path) -> Option<PathBuf> {
    c_test_fmu("crash_fmu", "crash", "Crash", &[], dir)
}

#[test]
fn an_fmu_that_crashes_costs_a_failed_simulation_and_the_campaign_finishes() {
    let dir = tempfile::tempdir().unwrap();
    let Some(path) = crash_fmu(dir.path()) else {
        return;
    };
    // The record: y = t (p = 1), every 0.5 s.
    let rows: String = (0..=20)
        .map(|i| format!("{},{}\n", i as f64 * 0.5, i as f64 * 0.5))
        .collect();
    let data = write(dir.path(), "record.csv", &format!("time,y\n{rows}"));
    let text = format!(
        r#"
[model]
fmu = "{}"
[measurement]
file = "{}"
[[outputs]]
model = "y"
measured = "y"
[[parameters]]
name = "p"
nominal = 1.3
min = 0.5
max = 2.0
[window]
start = 0.0
stop = 10.0
[search]
methods = ["nelder-mead"]
starts = 4
max_evaluations = 60
"#,
        path.display(),
        data.display()
    );
    let campaign = write(dir.path(), "crash.toml", &text);
    let result = calibrate_json(
        &campaign,
        &dir.path().join("db"),
        &dir.path().join("out"),
        &[],
    );
    let p = result["best"]["parameters"]["p"].as_f64().unwrap();
    assert!((p - 1.0).abs() < 1e-3, "p = {p}");
    let failed = result["failed"].as_u64().unwrap();
    assert!(
        failed > 0,
        "the screening covers p > 1.5, where every simulation crashes"
    );

    // The crash itself, as `calib simulate` reports it: the signal and the FMU's message.
    // Repeated: the host's end races the worker noticing the closed channel, and the crash
    // must be reported every time, never the worker's own request to stop.
    for _ in 0..20 {
        let out = calib(&[
            "simulate",
            path.to_str().unwrap(),
            "--set",
            "p=1.8",
            "--stop",
            "1",
        ]);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(stderr.contains("SIGSEGV"), "{stderr}");
        assert!(stderr.contains("crashing on purpose"), "{stderr}");
    }
}

#[test]
fn an_fmu_that_hangs_is_stopped_at_its_deadline() {
    let dir = tempfile::tempdir().unwrap();
    let Some(path) = crash_fmu(dir.path()) else {
        return;
    };
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .args([
            "simulate",
            path.to_str().unwrap(),
            "--set",
            "p=0.05",
            "--stop",
            "1",
        ])
        .env("CALIB_FMU_DEADLINE", "1")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("did not finish within 1 s"), "{stderr}");
}

/// `calib worker` in a child process on a free port of 127.0.0.1.
struct WorkerProcess {
    child: std::process::Child,
    url: String,
}

impl WorkerProcess {
    fn start(extra: &[&str]) -> Self {
        use std::io::BufRead;
        let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
            .args(["worker", "--listen", "127.0.0.1:0", "--slots", "2"])
            .args(extra)
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
            .unwrap_or_else(|| panic!("unexpected first line: {line}"));
        Self {
            child,
            url: format!("http://{address}"),
        }
    }
}

impl Drop for WorkerProcess {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn fmus_in(dir: &Path) -> usize {
    std::fs::read_dir(dir)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "fmu")
        })
        .count()
}

#[test]
fn a_campaign_on_a_worker_allowed_fmus_gives_the_local_runs() {
    let Some(path) = fmu(2, "VanDerPol") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("fmu-cache");
    let worker = WorkerProcess::start(&["--allow-fmu", "--fmu-cache", cache.to_str().unwrap()]);
    let campaign = van_der_pol_example(&path, dir.path());
    let local = calibrate_json(
        &campaign,
        &dir.path().join("db-local"),
        &dir.path().join("out"),
        &[],
    );
    let remote = calibrate_json(
        &campaign,
        &dir.path().join("db-remote"),
        &dir.path().join("out"),
        &["--workers", &worker.url],
    );
    assert_eq!(remote["simulated"], local["simulated"]);
    assert_eq!(
        remote["best"], local["best"],
        "the same best point, bit for bit"
    );
    assert_eq!(remote["runs"], local["runs"], "the same runs");
    assert_eq!(fmus_in(&cache), 1, "the FMU is kept once, by its hash");
}

#[test]
fn a_worker_without_allow_fmu_refuses_fmus() {
    let Some(path) = fmu(2, "VanDerPol") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let worker = WorkerProcess::start(&[]);
    let campaign = van_der_pol_example(&path, dir.path());
    let out = calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--out",
        dir.path().join("out").to_str().unwrap(),
        "--workers",
        &worker.url,
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("start it with --allow-fmu"), "{stderr}");
}

#[test]
fn a_crashing_fmu_leaves_the_worker_serving_and_the_campaign_finishing() {
    let dir = tempfile::tempdir().unwrap();
    let Some(path) = crash_fmu(dir.path()) else {
        return;
    };
    let cache = dir.path().join("fmu-cache");
    let worker = WorkerProcess::start(&["--allow-fmu", "--fmu-cache", cache.to_str().unwrap()]);
    let rows: String = (0..=20)
        .map(|i| format!("{},{}\n", i as f64 * 0.5, i as f64 * 0.5))
        .collect();
    let data = write(dir.path(), "record.csv", &format!("time,y\n{rows}"));
    let text = format!(
        "[model]\nfmu = \"{}\"\n[measurement]\nfile = \"{}\"\n[[outputs]]\nmodel = \"y\"\nmeasured = \"y\"\n\
         [[parameters]]\nname = \"p\"\nnominal = 1.3\nmin = 0.5\nmax = 2.0\n[window]\nstart = 0.0\nstop = 10.0\n\
         [search]\nmethods = [\"nelder-mead\"]\nstarts = 4\nmax_evaluations = 60\n",
        path.display(),
        data.display()
    );
    let campaign = write(dir.path(), "crash.toml", &text);
    let local = calibrate_json(
        &campaign,
        &dir.path().join("db-local"),
        &dir.path().join("out"),
        &[],
    );
    let remote = calibrate_json(
        &campaign,
        &dir.path().join("db-remote"),
        &dir.path().join("out"),
        &["--workers", &worker.url],
    );
    assert!(remote["failed"].as_u64().unwrap() > 0);
    assert_eq!(
        remote["failed"], local["failed"],
        "the same points crash on the worker"
    );
    assert_eq!(remote["best"], local["best"]);
    // The worker is still serving: a second campaign on it finishes.
    let again = calibrate_json(
        &campaign,
        &dir.path().join("db-again"),
        &dir.path().join("out"),
        &["--workers", &worker.url],
    );
    assert_eq!(again["best"], local["best"]);
}

#[test]
fn a_diagnosis_of_the_van_der_pol_fmu_finds_an_offset_on_its_output() {
    let Some(path) = fmu(2, "VanDerPol") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let campaign = van_der_pol_example(&path, dir.path());
    // The record again, its x0 read through a sensor 0.3 off.
    van_der_pol_record(
        &path,
        &dir.path().join("data/vanderpol.csv"),
        &["offset(x0)=0.3"],
    );
    let mut text = std::fs::read_to_string(&campaign).unwrap();
    text.push_str(
        "\n[diagnosis]\nrefit = 1\ncandidates = [\"offset(x0)\", \"gain(x0)\", \"lag(x0)\"]\n",
    );
    std::fs::write(&campaign, text).unwrap();
    let diagnosis = json_of(&calib(&[
        "diagnose",
        campaign.to_str().unwrap(),
        "--db",
        dir.path().join("db").to_str().unwrap(),
        "--out",
        dir.path().join("out").to_str().unwrap(),
        "--json",
    ]));
    assert_eq!(
        diagnosis["selected"],
        serde_json::json!(["offset(x0)"]),
        "{diagnosis}"
    );
    let offset = diagnosis["final"]["parameters"]["offset(x0)"]["value"]
        .as_f64()
        .unwrap();
    assert!((offset - 0.3).abs() < 0.01, "offset {offset}");
}
