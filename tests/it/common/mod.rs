//! Shared test harness: paths, campaign files in temporary folders, the `calib` binary.

pub mod cluster;
pub mod coordinator;
pub mod pki;

use calib_model::Run;
use std::path::{Path, PathBuf};
use std::process::Output;

/// The repository root.
pub fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// The shared data folder beside the repository (real record and synthetic records), or
/// the folder `CALIB_SHARED_DATA` names (a checkout elsewhere).
pub fn shared_data() -> PathBuf {
    std::env::var_os("CALIB_SHARED_DATA")
        .map_or_else(|| repo().join("../shared/data"), PathBuf::from)
}

/// Skip a test that cannot run here, saying why; under continuous integration (`CI` set, see
/// [`calib_model::testing`]) nothing required may skip, so there the same call fails the
/// test.
#[track_caller]
pub fn skip(reason: &str) {
    calib_model::testing::skip(reason);
}

/// A record of the Furuta rig from the independent simulator `tests/python/furuta_driven.py`
/// (scipy): `stop` seconds, its other `args`, written as `name` into `dir`, and the truth it
/// printed; `None` (with the reason) where python3 or scipy is missing.
pub fn furuta_driven_record(
    dir: &Path,
    name: &str,
    stop: f64,
    args: &[&str],
) -> Option<(PathBuf, serde_json::Value)> {
    let stop = stop.to_string();
    let mut all = vec!["--stop", stop.as_str()];
    all.extend(args);
    simulator_record("furuta_driven.py", &dir.join(name), &all)
}

/// A record of `tests/python/furuta_extra_torque.py` (the driven rig with a torque on the
/// arm that the effect library does not hold; 20 s unless `args` say otherwise), written as
/// `name` into `dir`, and the truth it printed; `None` (with the reason) where python3 or
/// scipy is missing.
pub fn furuta_extra_torque_record(
    dir: &Path,
    name: &str,
    args: &[&str],
) -> Option<(PathBuf, serde_json::Value)> {
    simulator_record("furuta_extra_torque.py", &dir.join(name), args)
}

/// Run the independent simulator `tests/python/<script>` writing `csv`, and the truth it
/// printed; `None` (with the reason) where python3 or scipy is missing.
pub fn simulator_record(
    script: &str,
    csv: &Path,
    args: &[&str],
) -> Option<(PathBuf, serde_json::Value)> {
    let out = std::process::Command::new("python3")
        .arg(repo().join("tests/python").join(script))
        .arg("--out")
        .arg(csv)
        .args(args)
        .output();
    match out {
        Err(e) => {
            skip(&format!("python3 cannot run: {e}"));
            None
        }
        Ok(out) if !out.status.success() => {
            let why = String::from_utf8_lossy(&out.stderr);
            assert!(
                why.contains("No module named 'scipy'") || why.contains("No module named 'numpy'"),
                "{script} failed: {why}"
            );
            skip("scipy is not installed (pip install scipy)");
            None
        }
        Ok(out) => Some((
            csv.to_path_buf(),
            serde_json::from_slice(&out.stdout).unwrap(),
        )),
    }
}

/// A loopback address that refuses connections for as long as the returned socket lives: the
/// socket is bound but never listens, so a connection gets a reset and no other process can
/// take the port meanwhile (where port 1 or 9 may well be served).
pub fn refusing_address() -> (tokio::net::TcpSocket, std::net::SocketAddr) {
    let socket = tokio::net::TcpSocket::new_v4().expect("a socket");
    socket
        .bind("127.0.0.1:0".parse().unwrap())
        .expect("bind a loopback port");
    let address = socket.local_addr().expect("its address");
    (socket, address)
}

/// The real Furuta record, or `None` (with the reason printed) where the shared folder is
/// absent; under continuous integration its absence fails the test.
pub fn real_record() -> Option<PathBuf> {
    let path = shared_data().join("real/FurutaData.mat");
    if path.exists() {
        Some(path)
    } else {
        skip(&format!(
            "{} is absent (it lives beside the repository, never in it)",
            path.display()
        ));
        None
    }
}

/// Whether `value` reads `printed` when rounded to as many digits as `printed` shows
/// ("0.944": within 0.0005 of 0.944; "2.091e8": within 5e5 of 2.091e8): the test of a
/// figure the documentation prints, at the tolerance its digits state.
pub fn reads_as(value: f64, printed: &str) -> bool {
    let expected: f64 = printed
        .parse()
        .unwrap_or_else(|_| panic!("{printed:?} is not a number"));
    let (mantissa, exponent) = match printed.split_once(['e', 'E']) {
        Some((m, e)) => (m, e.parse::<i32>().expect("an exponent")),
        None => (printed, 0),
    };
    let decimals = mantissa.split_once('.').map_or(0, |(_, d)| d.len()) as i32;
    let unit = 10f64.powi(exponent - decimals);
    // Half a unit of the last digit, and a hair for the decimal form of the bounds.
    (value - expected).abs() <= 0.5 * unit * (1.0 + 1e-9)
}

/// Assert that `value` reads `printed` at its digits (see [`reads_as`]).
#[track_caller]
pub fn assert_reads_as(value: f64, printed: &str, what: &str) {
    assert!(
        reads_as(value, printed),
        "{what}: {value} does not read as the documented {printed}"
    );
}

/// Noise floor of the synthetic records: outputs × samples × (σ² + q²/12), q = 2π/4096.
pub fn synthetic_noise_floor(outputs: usize, samples: usize) -> f64 {
    let q = 2.0 * std::f64::consts::PI / 4096.0;
    outputs as f64 * samples as f64 * (0.002f64.powi(2) + q * q / 12.0)
}

/// True frictions of the synthetic records.
pub fn true_frictions() -> (f64, f64) {
    let rig: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(repo().join("examples/data/furuta_rig.json")).unwrap(),
    )
    .unwrap();
    (
        rig["true_friction"]["armFriction"].as_f64().unwrap(),
        rig["true_friction"]["pendulumFriction"].as_f64().unwrap(),
    )
}

/// The outputs of a Furuta campaign on the seed's records: the arm's and the pendulum's
/// angle, by the names the records give their columns.
pub const FURUTA_OUTPUTS: &str = r#"[[outputs]]
model = "armJoint.phi"
measured = "arm_angle_rad"
[[outputs]]
model = "pendulumJoint.phi"
measured = "pendulum_angle_rad"
"#;

/// The two bearing frictions free on [0, 0.9] from the seed's nominal values.
pub const FURUTA_FRICTIONS: &str = r#"[[parameters]]
name = "armFriction"
nominal = 0.012
min = 0.0
max = 0.9
[[parameters]]
name = "pendulumFriction"
nominal = 0.002
min = 0.0
max = 0.9
"#;

/// A campaign for the clean synthetic record; `search` is the `[search]` body.
pub fn clean_campaign(search: &str) -> String {
    format!(
        r#"
name = "clean"
[model]
name = "furuta"
[measurement]
file = "{}"
time_column = "time_s"
{FURUTA_OUTPUTS}{FURUTA_FRICTIONS}[window]
start = 0.0
stop = 40.0
[search]
{search}
"#,
        repo().join("examples/data/furuta_clean.csv").display()
    )
}

/// A campaign for a record of the rig driven by its measured motor torque (the independent
/// simulator's `furuta_driven.py` columns), the two bearing frictions free on log10 bounds
/// from nominal values off the truth, fitted over 0–20 s; `search` is the `[search]` body.
pub fn driven_friction_campaign(name: &str, csv: &Path, search: &str) -> String {
    format!(
        r#"name = "{name}"
[model]
name = "furuta"
[measurement]
file = "{}"
time_column = "time_s"
{FURUTA_OUTPUTS}[[inputs]]
model = "armTorque"
measured = "motor_torque_Nm"
[[parameters]]
name = "armFriction"
nominal = 0.012
min = 1e-4
max = 0.9
scale = "log10"
[[parameters]]
name = "pendulumFriction"
nominal = 0.002
min = 1e-4
max = 0.9
scale = "log10"
[window]
start = 0.0
stop = 20.0
[search]
{search}
"#,
        csv.display()
    )
}

/// Write `text` as `name` in `dir` and return its path.
pub fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

/// Run the `calib` binary.
pub fn calib(args: &[&str]) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .args(args)
        .output()
        .expect("run calib")
}

/// Run the `calib` binary with `stdin` as its standard input.
pub fn calib_with_input(args: &[&str], stdin: &[u8]) -> Output {
    use std::io::Write;
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .args(args)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .expect("start calib");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(stdin)
        .expect("feed calib");
    child.wait_with_output().expect("run calib")
}

/// `calib calibrate CAMPAIGN --db DB --out OUT --json` plus `extra` arguments, to completion;
/// its result.json.
pub fn calibrate_json(campaign: &Path, db: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    let mut args = vec![
        "calibrate",
        campaign.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--json",
    ];
    args.extend_from_slice(extra);
    json_of(&calib(&args))
}

/// Standard output of a successful run, as JSON; panics with its standard error otherwise.
pub fn json_of(out: &Output) -> serde_json::Value {
    assert!(
        out.status.success(),
        "calib failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON on standard output")
}

/// Poll `condition` until it holds; panics naming `what` after `timeout`.
pub fn await_condition(
    what: &str,
    timeout: std::time::Duration,
    mut condition: impl FnMut() -> bool,
) {
    let deadline = std::time::Instant::now() + timeout;
    while !condition() {
        assert!(
            std::time::Instant::now() < deadline,
            "timed out after {timeout:?} waiting for {what}"
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// A draw of zero-mean Gaussian noise of standard deviation `sigma`, for synthetic records
/// made by the project's own models.
pub fn gaussian(rng: &mut rand_chacha::ChaCha8Rng, sigma: f64) -> f64 {
    use rand::Rng;
    rng.sample(rand_distr::Normal::new(0.0, sigma).expect("a finite standard deviation ≥ 0"))
}

/// Follow the `CALIB_PROGRESS=lines` progress of a `calib calibrate` child: the returned
/// counter holds the evaluations it last reported (all of them already stored), updated by
/// the returned reader thread until the child's standard error closes; the thread returns
/// the other lines of standard error.
pub fn watch_progress(
    child: &mut std::process::Child,
) -> (
    std::sync::Arc<std::sync::atomic::AtomicU64>,
    std::thread::JoinHandle<Vec<String>>,
) {
    use std::io::{BufRead, BufReader};
    let reported = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let counter = reported.clone();
    let stderr = child.stderr.take().expect("the child's stderr is piped");
    let reader = std::thread::spawn(move || {
        let mut others = Vec::new();
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            // "progress: N evaluations, best X"
            if let Some(n) = line
                .strip_prefix("progress: ")
                .and_then(|rest| rest.split_whitespace().next())
                .and_then(|n| n.parse().ok())
            {
                counter.store(n, std::sync::atomic::Ordering::SeqCst);
            } else {
                others.push(line);
            }
        }
        others
    });
    (reported, reader)
}

/// A record of the FMU `fmu` made by FMPy, the independent simulator (`tests/python/
/// fmpy_simulate.py`, Model Exchange at rtol 1e-8): the parameters `set` (`NAME=VALUE`; an
/// `offset(OUTPUT)=VALUE` is added to that output, as a sensor's offset), 0 to
/// `stop` every `step`, the `outputs` (comma-separated) with Gaussian noise of the standard
/// deviations `noise` (`NAME=SD`, seed 7) added, written to `csv`. Where FMPy is not
/// installed the test says so (under CI it fails) and the record is `calib simulate`'s.
pub fn fmu_record(
    fmu: &Path,
    csv: &Path,
    set: &[&str],
    stop: &str,
    step: &str,
    noise: &[&str],
    outputs: &str,
) -> PathBuf {
    let fmpy = std::process::Command::new("python3")
        .args(["-c", "import fmpy"])
        .output();
    if !fmpy.is_ok_and(|o| o.status.success()) {
        skip(
            "FMPy (`pip install fmpy==0.3.32`) makes the FMU records; calib simulate made this one",
        );
        return calib_simulate_record(fmu, csv, set, stop, step, noise, outputs);
    }
    let raw = csv.with_extension("fmpy.csv");
    let mut command = std::process::Command::new("python3");
    command
        .arg(repo().join("tests/python/fmpy_simulate.py"))
        .arg(fmu)
        .args(["me", stop, step, "1e-8"])
        .arg(&raw)
        .args(outputs.split(','));
    // A sensor offset on an output (`offset(NAME)=VALUE`) is added to the record; any other
    // assignment is a parameter of the FMU.
    let mut offsets: Vec<(&str, f64)> = Vec::new();
    for s in set {
        let (name, value) = s.split_once('=').unwrap();
        match name
            .strip_prefix("offset(")
            .and_then(|n| n.strip_suffix(')'))
        {
            Some(output) => offsets.push((output, value.parse().unwrap())),
            None => {
                assert!(
                    !name.contains('('),
                    "{s}: only offsets are applied to FMPy's record"
                );
                command.args(["--set", s]);
            }
        }
    }
    let out = command.output().expect("python3 runs");
    assert!(
        out.status.success(),
        "fmpy_simulate.py: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(&raw).unwrap();
    let mut lines = text.lines();
    let header: Vec<String> = lines.next().unwrap().split(',').map(String::from).collect();
    let offset: Vec<f64> = header
        .iter()
        .map(|name| {
            offsets
                .iter()
                .find(|(o, _)| o == name)
                .map_or(0.0, |(_, v)| *v)
        })
        .collect();
    let sd: Vec<f64> = header
        .iter()
        .map(|name| {
            noise
                .iter()
                .find_map(|n| n.strip_prefix(&format!("{name}=")))
                .map_or(0.0, |v| v.parse().unwrap())
        })
        .collect();
    use rand::SeedableRng;
    use rand_distr::Distribution;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let mut written = header.join(",") + "\n";
    for line in lines.filter(|l| !l.is_empty()) {
        let row: Vec<String> = line
            .split(',')
            .zip(sd.iter().zip(&offset))
            .map(|(v, (&sd, &offset))| {
                let v: f64 = v.parse::<f64>().unwrap() + offset;
                let e = if sd > 0.0 {
                    rand_distr::Normal::new(0.0, sd).unwrap().sample(&mut rng)
                } else {
                    0.0
                };
                format!("{:?}", v + e)
            })
            .collect();
        written.push_str(&(row.join(",") + "\n"));
    }
    std::fs::write(csv, written).unwrap();
    csv.to_path_buf()
}

/// The same record made by `calib simulate` (its own noise, seed 7).
fn calib_simulate_record(
    fmu: &Path,
    csv: &Path,
    set: &[&str],
    stop: &str,
    step: &str,
    noise: &[&str],
    outputs: &str,
) -> PathBuf {
    let mut args = vec!["simulate", fmu.to_str().unwrap()];
    for s in set {
        args.extend(["--set", s]);
    }
    args.extend([
        "--stop",
        stop,
        "--step",
        step,
        "--outputs",
        outputs,
        "--seed",
        "7",
    ]);
    for n in noise {
        args.extend(["--noise", n]);
    }
    args.extend(["--out", csv.to_str().unwrap()]);
    let out = calib(&args);
    assert!(
        out.status.success(),
        "calib {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
    csv.to_path_buf()
}

/// The Reference FMU VanDerPol's record of `examples/vanderpol.toml`: mu = 1.7 and `set`,
/// 20 s every 0.05 s, x0 and x1 with 0.02 of noise, written to `csv`.
pub fn van_der_pol_record(fmu: &Path, csv: &Path, set: &[&str]) -> PathBuf {
    let set: Vec<&str> = ["mu=1.7"].into_iter().chain(set.iter().copied()).collect();
    fmu_record(
        fmu,
        csv,
        &set,
        "20",
        "0.05",
        &["x0=0.02", "x1=0.02"],
        "x0,x1",
    )
}

/// `examples/vanderpol.toml` in `dir`, with the FMU `fmu` (VanDerPol) and the noisy record
/// (mu = 1.7) its comments make.
pub fn van_der_pol_example(fmu: &Path, dir: &Path) -> PathBuf {
    std::fs::create_dir_all(dir.join("fmus/fmi2")).unwrap();
    std::fs::create_dir_all(dir.join("data")).unwrap();
    let copy = dir.join("fmus/fmi2/VanDerPol.fmu");
    std::fs::copy(fmu, &copy).unwrap();
    van_der_pol_record(&copy, &dir.join("data/vanderpol.csv"), &[]);
    let campaign = dir.join("vanderpol.toml");
    std::fs::copy(repo().join("examples/vanderpol.toml"), &campaign).unwrap();
    campaign
}

/// The test FMU of `tests/<folder>/` (`<stem>.c` and `<stem>.xml`), compiled by the C
/// compiler (`$CC`, else `cc`) into `binaries/linux64/<identifier>.so` with `cc_args` after
/// the source, and zipped with python3 into `dir/<identifier>.fmu`. Without a compiler or
/// python3 the test skips (fails under continuous integration) and gets `None`.
pub fn c_test_fmu(
    folder: &str,
    stem: &str,
    identifier: &str,
    cc_args: &[String],
    dir: &Path,
) -> Option<PathBuf> {
    let src = repo().join("tests").join(folder);
    let root = dir.join(stem);
    std::fs::create_dir_all(root.join("binaries/linux64")).unwrap();
    std::fs::copy(
        src.join(format!("{stem}.xml")),
        root.join("modelDescription.xml"),
    )
    .unwrap();
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let built = std::process::Command::new(&cc)
        .args(["-shared", "-fPIC", "-O1", "-o"])
        .arg(root.join(format!("binaries/linux64/{identifier}.so")))
        .arg(src.join(format!("{stem}.c")))
        .args(cc_args)
        .status();
    if !built.is_ok_and(|s| s.success()) {
        skip(&format!("no C compiler (`{cc}`) to build tests/{folder}"));
        return None;
    }
    let fmu = dir.join(format!("{identifier}.fmu"));
    let zipped = std::process::Command::new("python3")
        .args(["-c", "import os,sys,zipfile\nz=zipfile.ZipFile(sys.argv[2],'w')\nfor d,_,fs in os.walk(sys.argv[1]):\n  for f in fs:\n    p=os.path.join(d,f); z.write(p, os.path.relpath(p, sys.argv[1]))\nz.close()"])
        .arg(&root)
        .arg(&fmu)
        .status();
    if !zipped.is_ok_and(|s| s.success()) {
        skip(&format!("no python3 to zip tests/{folder}"));
        return None;
    }
    Some(fmu)
}

/// A synthetic record of calib's own Furuta model at the rig's true frictions
/// ([`true_frictions`]), started at rest at pendulum angle `theta0` [rad], sampled at 100 Hz
/// for `stop` s, its angles with gaussian noise (2 mrad, seed `seed`). With `torque`, the
/// model's `armTorque` input is driven by `torque(t)` [N m] (linear between the samples) and
/// the record has a `motor_torque_Nm` column holding it; without, it is a free swing. Columns:
/// `time_s, arm_angle_rad, pendulum_angle_rad[, motor_torque_Nm]`.
pub fn furuta_record(
    csv: &Path,
    theta0: f64,
    stop: f64,
    seed: u64,
    torque: Option<&dyn Fn(f64) -> f64>,
) -> PathBuf {
    use calib_model::inputs::{InputSignal, Inputs, Interpolation};
    use rand::SeedableRng;
    let model = calib_model::models::find("furuta").expect("the furuta model");
    let info = model.info();
    let mut p = info.default_vector();
    let (arm, pendulum) = true_frictions();
    for (name, value) in [
        ("armFriction", arm),
        ("pendulumFriction", pendulum),
        ("theta0", theta0),
    ] {
        p[info.parameter_index(name).expect(name)] = value;
    }
    let samples = (stop * 100.0).round() as usize + 1;
    let times: Vec<f64> = (0..samples).map(|k| k as f64 / 100.0).collect();
    let applied: Option<Vec<f64>> = torque.map(|u| times.iter().map(|&t| u(t)).collect());
    let inputs = match &applied {
        Some(values) => Inputs {
            signals: vec![InputSignal {
                input: 0,
                times: times.clone().into(),
                values: values.clone().into(),
                interpolation: Interpolation::Linear,
            }],
        },
        None => Inputs::default(),
    };
    let outputs = [
        info.output_index("armJoint.phi").expect("arm"),
        info.output_index("pendulumJoint.phi").expect("pendulum"),
    ];
    let trajectory = model
        .simulate(&Run::new(&p, &times, &outputs, &model.default_options()).driven(&inputs))
        .expect("the synthetic record simulates");
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut text = String::from("time_s,arm_angle_rad,pendulum_angle_rad");
    if applied.is_some() {
        text.push_str(",motor_torque_Nm");
    }
    text.push('\n');
    for (k, t) in times.iter().enumerate() {
        let arm = trajectory.values[0][k] + gaussian(&mut rng, 0.002);
        let pendulum = trajectory.values[1][k] + gaussian(&mut rng, 0.002);
        text.push_str(&format!("{t},{arm},{pendulum}"));
        if let Some(u) = &applied {
            text.push_str(&format!(",{}", u[k]));
        }
        text.push('\n');
    }
    std::fs::write(csv, text).unwrap();
    csv.to_path_buf()
}

/// A motor torque [N m] that swings the rig's arm: a doublet of steps, then two sines.
pub fn arm_torque(t: f64) -> f64 {
    let a = 0.03;
    if (1.0..1.6).contains(&t) {
        a
    } else if (1.6..2.2).contains(&t) {
        -a
    } else if t >= 3.0 {
        let s = t - 3.0;
        a * (0.7 * (2.0 * std::f64::consts::PI * 0.45 * s).sin()
            + 0.5 * (2.0 * std::f64::consts::PI * 1.3 * s + 1.0).sin())
    } else {
        0.0
    }
}

/// A `calib` server process of `args` whose first line of standard output is
/// `<prefix><address>`; the process and that address.
pub fn spawn_server(args: &[&str], prefix: &str, stderr: &Path) -> (std::process::Child, String) {
    use std::io::{BufRead, BufReader};
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .args(args)
        .stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(stderr).unwrap())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let address = line
        .trim()
        .strip_prefix(prefix)
        .unwrap_or_else(|| panic!("unexpected first line: {line}"))
        .split_whitespace()
        .next()
        .unwrap()
        .to_string();
    (child, address)
}

/// Assert that a report's typed message holds the values of its JSON text (`report_json`)
/// field for field: the same names, the same values. What proto3 cannot tell apart counts
/// as one: null, an empty list and an empty map are each an unset field. `apart` names the
/// JSON's top-level keys the state holds in a message of their own.
pub fn assert_typed_twin<T: serde::Serialize>(typed: Option<&T>, json: &str, apart: &[&str]) {
    fn unset_removed(v: &mut serde_json::Value) -> bool {
        match v {
            serde_json::Value::Object(map) => {
                map.retain(|_, v| !unset_removed(v));
                map.is_empty()
            }
            serde_json::Value::Array(list) => {
                list.iter_mut().for_each(|v| {
                    unset_removed(v);
                });
                list.is_empty()
            }
            serde_json::Value::Null => true,
            _ => false,
        }
    }
    let typed = typed.expect("the typed report is set beside report_json");
    let mut typed = serde_json::to_value(typed).unwrap();
    let mut json: serde_json::Value = serde_json::from_str(json).unwrap();
    for key in apart {
        json.as_object_mut().unwrap().remove(*key);
    }
    unset_removed(&mut typed);
    unset_removed(&mut json);
    assert!(typed == json, "typed: {typed:#}\nreport_json: {json:#}");
}
