//! An FMU's time grid and tolerance as the user and the FMU mean them: `calib simulate`'s
//! `--start`, `--stop` (always the last row) and `--cs-step` (the Co-Simulation
//! communication step, apart from the output interval), compared with FMPy, an independent
//! simulator; and the FMU's own `DefaultExperiment` tolerance, with which a campaign that
//! sets none recovers the true parameters of a record FMPy made at that tolerance.

use crate::common::*;
use crate::real_tool_fmus::real_tool_fmus;
use crate::reference_fmus::{read_reference, reference_fmus};
use std::path::{Path, PathBuf};

fn reference(version: u32, model: &str) -> Option<PathBuf> {
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

/// `calib simulate FMU ARGS` as rows (time first).
fn simulate(fmu: &Path, args: &[&str]) -> Vec<Vec<f64>> {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("sim.csv");
    let mut all = vec!["simulate", fmu.to_str().unwrap()];
    all.extend_from_slice(args);
    all.extend(["--out", csv.to_str().unwrap()]);
    ok(&calib(&all));
    read_reference(&csv).1
}

/// `fmpy.simulate_fmu(FMU, output=OUTPUTS, KEYWORDS)` as rows (time, then the outputs in the
/// order asked), or `None` (with the reason) where FMPy is not installed.
fn fmpy(fmu: &Path, outputs: &[&str], keywords: &str) -> Option<Vec<Vec<f64>>> {
    let script = format!(
        "import sys, fmpy\n\
         names = {outputs:?}\n\
         r = fmpy.simulate_fmu(sys.argv[1], output=names, {keywords})\n\
         for row in r:\n    print(','.join(repr(float(row[n])) for n in ['time'] + names))\n"
    );
    let out = std::process::Command::new("python3")
        .args(["-c", &script])
        .arg(fmu)
        .output();
    match out {
        Ok(out) if out.status.success() => Some(
            String::from_utf8_lossy(&out.stdout)
                .lines()
                .map(|l| l.split(',').map(|v| v.parse().unwrap()).collect())
                .collect(),
        ),
        Ok(out) => {
            let why = String::from_utf8_lossy(&out.stderr);
            assert!(
                why.contains("No module named 'fmpy'"),
                "FMPy failed on {}: {why}",
                fmu.display()
            );
            skip("FMPy is not installed (pip install fmpy)");
            None
        }
        Err(e) => {
            skip(&format!("python3: {e}"));
            None
        }
    }
}

/// Largest difference between two tables of the same shape.
fn worst(ours: &[Vec<f64>], theirs: &[Vec<f64>]) -> f64 {
    assert_eq!(ours.len(), theirs.len(), "rows: {ours:?}\nvs {theirs:?}");
    ours.iter()
        .zip(theirs)
        .flat_map(|(a, b)| {
            assert_eq!(a.len(), b.len());
            a.iter().zip(b).map(|(x, y)| (x - y).abs())
        })
        .fold(0.0, f64::max)
}

#[test]
fn a_stop_time_that_is_not_a_whole_number_of_steps_is_the_last_row() {
    for version in [2, 3] {
        let Some(path) = reference(version, "VanDerPol") else {
            return;
        };
        let ours = simulate(
            &path,
            &[
                "--interface",
                "co-simulation",
                "--stop",
                "1.05",
                "--step",
                "0.1",
                "--outputs",
                "x0,x1",
            ],
        );
        assert_eq!(ours.last().unwrap()[0], 1.05, "FMI {version}");
        let Some(theirs) = fmpy(
            &path,
            &["x0", "x1"],
            "fmi_type='CoSimulation', stop_time=1.05, output_interval=0.1",
        ) else {
            return;
        };
        let w = worst(&ours, &theirs);
        assert!(w < 1e-12, "FMI {version}: {w:e}");
    }
}

#[test]
fn a_communication_step_below_the_output_interval_gives_fmpys_result_at_that_step() {
    let Some(path) = reference(2, "VanDerPol") else {
        return;
    };
    let ours = simulate(
        &path,
        &[
            "--interface",
            "co-simulation",
            "--stop",
            "2",
            "--step",
            "0.25",
            "--cs-step",
            "0.05",
            "--outputs",
            "x0,x1",
        ],
    );
    assert_eq!(ours.len(), 9);
    // FMPy steps a Co-Simulation FMU by its output interval: every fifth of its rows.
    let Some(theirs) = fmpy(
        &path,
        &["x0", "x1"],
        "fmi_type='CoSimulation', stop_time=2, output_interval=0.05",
    ) else {
        return;
    };
    let theirs: Vec<Vec<f64>> = theirs.into_iter().step_by(5).collect();
    let w = worst(&ours, &theirs);
    assert!(w < 1e-12, "{w:e}");
}

/// OpenModelica's Co-Simulation FMUs step with explicit Euler at the communication step: the
/// Mass_Damper of gemseo-fmu blows up (to -4e9) when stepped by a 0.1 s output interval and
/// needs a step of 1e-4 s, which a 0.1 s grid of 11 rows now gets.
#[test]
fn a_co_simulation_fmu_that_needs_small_steps_runs_on_a_coarse_output_grid() {
    let Some(dir) = real_tool_fmus() else {
        return;
    };
    let path = dir.join("gemseo-fmu/Mass_Damper.fmu");
    let ours = simulate(
        &path,
        &[
            "--interface",
            "co-simulation",
            "--stop",
            "1",
            "--step",
            "0.1",
            "--cs-step",
            "1e-4",
            "--outputs",
            "y",
        ],
    );
    assert_eq!(ours.len(), 11);
    let Some(theirs) = fmpy(
        &path,
        &["y"],
        "fmi_type='CoSimulation', stop_time=1, output_interval=1e-4",
    ) else {
        return;
    };
    let theirs: Vec<Vec<f64>> = theirs.into_iter().step_by(1000).collect();
    let w = worst(&ours, &theirs);
    assert!(w < 1e-9, "{w:e}: {ours:?}\nvs {theirs:?}");
    assert!(ours.iter().all(|r| r[1].abs() < 1.0), "{ours:?}");
}

/// Dahlquist's `x' = -k x` with `x = 1` at the start: initialised at 2 s, it is
/// `exp(-(t - 2))` (Model Exchange) and FMPy's result from 2 s (Co-Simulation), not the
/// run from 0 s read from 2 s on.
#[test]
fn the_start_time_is_where_the_fmu_is_initialised() {
    for version in [2, 3] {
        let Some(path) = reference(version, "Dahlquist") else {
            return;
        };
        let args = |interface| {
            simulate(
                &path,
                &[
                    "--interface",
                    interface,
                    "--start",
                    "2",
                    "--stop",
                    "4",
                    "--step",
                    "0.5",
                    "--outputs",
                    "x",
                ],
            )
        };
        let me = args("model-exchange");
        assert_eq!(me.len(), 5);
        for row in &me {
            let exact = (-(row[0] - 2.0)).exp();
            assert!((row[1] - exact).abs() < 1e-7, "FMI {version}: {row:?}");
        }
        assert_eq!(me[0], [2.0, 1.0]);
        let cs = args("co-simulation");
        let Some(theirs) = fmpy(
            &path,
            &["x"],
            "fmi_type='CoSimulation', start_time=2, stop_time=4, output_interval=0.5",
        ) else {
            return;
        };
        let w = worst(&cs, &theirs);
        assert!(w < 1e-12, "FMI {version}: {w:e}");
        assert_eq!(cs[0], [2.0, 1.0]);
    }
}

/// Describe's counterpart on the command line: which tolerance a model gets, and why.
#[test]
fn calib_models_says_which_tolerance_an_fmu_gets_and_why() {
    let Some(dir) = real_tool_fmus() else {
        return;
    };
    let describe = |path: &Path| -> serde_json::Value {
        let json: serde_json::Value =
            serde_json::from_str(&ok(&calib(&["models", path.to_str().unwrap(), "--json"])))
                .unwrap();
        json[0]["default_solver"].clone()
    };
    let own = describe(&dir.join("aixcalibuha/PumpAndValve_linux.fmu"));
    assert_eq!(own["rtol"], 1e-4);
    assert_eq!(own["tolerance_origin"], "the FMU's default experiment");
    if let Some(path) = reference(2, "VanDerPol") {
        let calibs = describe(&path);
        assert_eq!(calibs["rtol"], 1e-8);
        assert_eq!(calibs["tolerance_origin"], "calib's default");
    }
    let text = ok(&calib(&[
        "models",
        dir.join("aixcalibuha/PumpAndValve_linux.fmu")
            .to_str()
            .unwrap(),
    ]));
    assert!(
        text.contains("rtol 1e-4") && text.contains("the FMU's default experiment"),
        "{text}"
    );
}

/// AixCaliBuHA's PumpAndValve example (Dymola 2020, Co-Simulation, DefaultExperiment
/// tolerance 1e-4), whose true ramp durations are 0.432 s and 2.5423 s: a record FMPy makes
/// at the FMU's own tolerance is fitted back within 1e-4 by a campaign that sets no
/// tolerance. At calib's rtol 1e-8 the FMU follows another trajectory (by up to 0.06 K) and
/// the fit lands at 0.43256 and 2.54141.
#[test]
fn a_campaign_on_a_dymola_fmu_fits_at_the_fmus_own_tolerance() {
    let Some(dir) = real_tool_fmus() else {
        return;
    };
    let fmu = dir.join("aixcalibuha/PumpAndValve_linux.fmu");
    let Some(truth) = fmpy(
        &fmu,
        &["heatCapacitor.T", "pipe.T"],
        "stop_time=10, output_interval=0.1, \
         start_values={'speedRamp.duration': 0.432, 'valveRamp.duration': 2.5423}",
    ) else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    let mut csv = String::from("time,TCap,TPipe\n");
    for row in &truth {
        csv += &format!("{},{},{}\n", row[0], row[1], row[2]);
    }
    let record = write(work.path(), "record.csv", &csv);
    let campaign = write(
        work.path(),
        "pump.toml",
        &format!(
            r#"
[model]
fmu = "{}"
[measurement]
file = "{}"
[[outputs]]
model = "heatCapacitor.T"
measured = "TCap"
scale = "variance"
[[outputs]]
model = "pipe.T"
measured = "TPipe"
scale = "variance"
[[parameters]]
name = "speedRamp.duration"
nominal = 1.0
min = 0.1
max = 10.0
[[parameters]]
name = "valveRamp.duration"
nominal = 1.0
min = 0.1
max = 10.0
[window]
start = 0.0
stop = 10.0
"#,
            fmu.display(),
            record.display()
        ),
    );
    let result = calibrate_json(
        &campaign,
        &work.path().join("db"),
        &work.path().join("out"),
        &[],
    );
    let fit = &result["best"]["parameters"];
    let speed = fit["speedRamp.duration"].as_f64().unwrap();
    let valve = fit["valveRamp.duration"].as_f64().unwrap();
    println!(
        "PumpAndValve at its own tolerance: speedRamp.duration {speed:.7} (0.432), \
         valveRamp.duration {valve:.7} (2.5423), {} evaluations",
        result["evaluations"]
    );
    assert!(
        (speed - 0.432).abs() < 1e-4 && (valve - 2.5423).abs() < 1e-4,
        "speedRamp.duration = {speed}, valveRamp.duration = {valve}"
    );
}

/// A campaign's `[model] start_time`: Dahlquist's `x = exp(-k (t - 2))` from 2 s on is
/// fitted back to `k = 0.7`; from 0 s the same record would need another `k`.
#[test]
fn a_campaign_starts_an_fmu_at_its_start_time() {
    let Some(path) = reference(2, "Dahlquist") else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    let mut csv = String::from("time,x\n");
    for i in 0..=40 {
        let t = 2.0 + 0.1 * f64::from(i);
        csv += &format!("{t},{}\n", (-0.7 * (t - 2.0)).exp());
    }
    let record = write(work.path(), "record.csv", &csv);
    let campaign = write(
        work.path(),
        "dahlquist.toml",
        &format!(
            r#"
[model]
fmu = "{}"
start_time = 2.0
[measurement]
file = "{}"
[[outputs]]
model = "x"
measured = "x"
[[parameters]]
name = "k"
nominal = 1.0
min = 0.1
max = 3.0
[window]
start = 2.0
stop = 6.0
"#,
            path.display(),
            record.display()
        ),
    );
    let result = calibrate_json(
        &campaign,
        &work.path().join("db"),
        &work.path().join("out"),
        &[],
    );
    let k = result["best"]["parameters"]["k"].as_f64().unwrap();
    assert!((k - 0.7).abs() < 1e-4, "k = {k}");
}

/// A campaign's `[model] step`: gemseo-fmu's Mass_Damper (OpenModelica, Co-Simulation),
/// recorded by FMPy at a 1e-4 s communication step and sampled every 0.01 s, gives back its
/// damping of 10 N.s/m when stepped at 1e-4 s (at the record's 0.01 s it blows up).
#[test]
fn a_campaign_steps_a_co_simulation_fmu_at_its_communication_step() {
    let Some(dir) = real_tool_fmus() else {
        return;
    };
    let fmu = dir.join("gemseo-fmu/Mass_Damper.fmu");
    let Some(truth) = fmpy(
        &fmu,
        &["y"],
        "fmi_type='CoSimulation', stop_time=1, output_interval=1e-4",
    ) else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    let mut csv = String::from("time,y\n");
    for row in truth.iter().step_by(100) {
        csv += &format!("{},{}\n", row[0], row[1]);
    }
    let record = write(work.path(), "record.csv", &csv);
    let campaign = write(
        work.path(),
        "damper.toml",
        &format!(
            r#"
[model]
fmu = "{}"
interface = "co-simulation"
step = 1e-4
[measurement]
file = "{}"
[[outputs]]
model = "y"
measured = "y"
[[parameters]]
name = "damper.d"
nominal = 5.0
min = 1.0
max = 20.0
[window]
start = 0.0
stop = 1.0
"#,
            fmu.display(),
            record.display()
        ),
    );
    let result = calibrate_json(
        &campaign,
        &work.path().join("db"),
        &work.path().join("out"),
        &[],
    );
    let d = result["best"]["parameters"]["damper.d"].as_f64().unwrap();
    assert!((d - 10.0).abs() < 1e-3, "damper.d = {d}");
}

/// Describe (the worker's RPC) says the same: the tolerance a request that sets none gets,
/// and where it comes from.
#[test]
fn describe_says_which_tolerance_a_model_gets_and_why() {
    use calib_worker::service::simulator::describe;
    let Some(dir) = real_tool_fmus() else {
        return;
    };
    let pump =
        calib_model::fmu::open(&dir.join("aixcalibuha/PumpAndValve_linux.fmu"), None).unwrap();
    let d = describe(pump);
    assert_eq!(d.tolerance_origin, "the FMU's default experiment");
    let solver = d.default_solver.unwrap();
    assert_eq!((solver.rtol, solver.start_time), (Some(1e-4), Some(0.0)));
    let furuta = calib_model::validate::model("furuta").unwrap();
    let d = describe(furuta);
    assert_eq!(d.tolerance_origin, "the model's calibration tolerance");
    assert_eq!(d.default_solver.unwrap().rtol, Some(1e-8));
    if let Some(path) = reference(2, "VanDerPol") {
        let vdp = calib_model::fmu::open(&path, None).unwrap();
        assert_eq!(describe(vdp).tolerance_origin, "calib's default");
        let cs =
            calib_model::fmu::open(&path, Some(calib_model::fmu::Interface::CoSimulation)).unwrap();
        assert_eq!(
            describe(cs).default_solver.unwrap().communication_step,
            Some(0.01),
            "the FMU's DefaultExperiment stepSize"
        );
    }
}
