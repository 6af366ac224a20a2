//! FMUs driven by measured signals through the `calib` binary, where each FMU runs in a child
//! process: `calib simulate FMU --input FILE` gives FMPy's outputs on the same signals, and a
//! campaign whose `[[inputs]]` drive an FMU recovers the parameter FMPy's record was made
//! with.

use crate::common::*;
use crate::real_tool_fmus::real_tool_fmus;
use crate::reference_fmus::{read_reference, reference_fmus};
use std::path::Path;

/// FMPy's run (`tests/python/fmpy_simulate.py`) of `fmu` through `interface` (`me`, `cs`)
/// driven by `input` (`--hold`: held), with `set` (`NAME=VALUE`): header and rows, or `None`
/// where FMPy is not installed (a failure under CI).
#[allow(clippy::too_many_arguments)]
fn fmpy(
    fmu: &Path,
    interface: &str,
    stop: &str,
    step: &str,
    names: &[&str],
    input: &Path,
    hold: bool,
    set: &[&str],
) -> Option<(Vec<String>, Vec<Vec<f64>>)> {
    let out = input.with_extension(format!("{interface}.fmpy.csv"));
    let mut command = std::process::Command::new("python3");
    command
        .arg(repo().join("tests/python/fmpy_simulate.py"))
        .arg(fmu)
        .args([interface, stop, step, "1e-8"])
        .arg(&out)
        .args(names)
        .arg("--input")
        .arg(input);
    if hold {
        command.arg("--hold");
    }
    for s in set {
        command.args(["--set", s]);
    }
    let run = command.output().expect("python3 runs");
    if !run.status.success() {
        let why = String::from_utf8_lossy(&run.stderr);
        if why.contains("No module named 'fmpy'") {
            skip("FMPy, the second opinion (`pip install fmpy==0.3.32`), is not installed");
            return None;
        }
        panic!("FMPy failed on {}: {why}", fmu.display());
    }
    Some(read_reference(&out))
}

/// The Reference FMU `Feedthrough` through `calib simulate --input` (the FMU in a child
/// process, the signals sent to it once): its four outputs are FMPy's, through Model
/// Exchange and Co-Simulation, FMI 2.0 and 3.0.
#[test]
fn calib_simulate_drives_an_fmus_inputs_from_a_file_as_fmpy_does() {
    let Some(dir) = reference_fmus() else {
        return;
    };
    let work = tempfile::tempdir().unwrap();
    let mut csv = String::from(
        "time,Float64_continuous_input,Float64_discrete_input,Int32_input,Boolean_input\n",
    );
    for k in 0..=20 {
        let t = f64::from(k) * 0.1;
        csv += &format!(
            "{t},{},{},{},{}\n",
            (3.0 * t).sin(),
            (2.0 * t).cos(),
            (3.0 * (2.0 * t).sin()).round(),
            u8::from((5.0 * t).sin() > 0.0)
        );
    }
    let input = write(work.path(), "in.csv", &csv);
    let outputs = [
        "Float64_continuous_output",
        "Float64_discrete_output",
        "Int32_output",
        "Boolean_output",
    ];
    for version in [2, 3] {
        let fmu = dir.join(format!("fmi{version}/Feedthrough.fmu"));
        for (interface, short) in [("model-exchange", "me"), ("co-simulation", "cs")] {
            let sim = work.path().join(format!("sim-{version}-{short}.csv"));
            let out = calib(&[
                "simulate",
                fmu.to_str().unwrap(),
                "--interface",
                interface,
                "--stop",
                "2",
                "--step",
                "0.05",
                "--input",
                input.to_str().unwrap(),
                "--outputs",
                &outputs.join(","),
                "--out",
                sim.to_str().unwrap(),
            ]);
            assert!(
                out.status.success(),
                "FMI {version} {interface}: {}",
                String::from_utf8_lossy(&out.stderr)
            );
            let (_, ours) = read_reference(&sim);
            let Some((header, theirs)) =
                fmpy(&fmu, short, "2", "0.05", &outputs, &input, false, &[])
            else {
                return;
            };
            assert_eq!(ours.len(), theirs.len(), "FMI {version} {interface}");
            for (k, name) in outputs.iter().enumerate() {
                let col = header.iter().position(|h| h == name).unwrap();
                for (a, b) in ours.iter().zip(&theirs) {
                    assert!(
                        (a[k + 1] - b[col]).abs() <= 1e-12,
                        "FMI {version} {interface} {name} at {}: {} vs FMPy {}",
                        a[0],
                        a[k + 1],
                        b[col]
                    );
                }
            }
            // The inputs reached the FMU: the real output follows sin(3t).
            let last = ours.last().unwrap();
            assert!(last[1].abs() > 0.1, "{last:?}");
        }
    }
    // A column named after no input of the FMU.
    let typo = write(work.path(), "typo.csv", "time,Int32_inpt\n0,1\n2,1\n");
    let fmu = dir.join("fmi2/Feedthrough.fmu");
    let out = calib(&[
        "simulate",
        fmu.to_str().unwrap(),
        "--stop",
        "2",
        "--input",
        typo.to_str().unwrap(),
    ]);
    let e = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{e}");
    assert!(e.contains("did you mean `Int32_input`?"), "{e}");
}

/// gemseo-fmu's Mass_Damper (OpenModelica 1.19, Model Exchange) driven by a measured force
/// held between its 0.01 s samples (`100 sin(20 t)` N and a 50 N step at 0.5 s): FMPy's
/// record at a damping of 6 N.s/m (the FMU's default is 10) is fitted back by a campaign
/// whose `[[inputs]]` give the force column to the FMU's input `f`, within 1%.
#[test]
fn a_campaign_with_inputs_recovers_an_fmus_parameter_from_fmpys_record() {
    let Some(dir) = real_tool_fmus() else {
        return;
    };
    let fmu = dir.join("gemseo-fmu/Mass_Damper.fmu");
    let work = tempfile::tempdir().unwrap();
    let times: Vec<f64> = (0..=100).map(|k| f64::from(k) * 0.01).collect();
    let force: Vec<f64> = times
        .iter()
        .map(|&t| 100.0 * (20.0 * t).sin() + if t >= 0.5 { 50.0 } else { 0.0 })
        .collect();
    let mut csv = String::from("time,f\n");
    for (t, f) in times.iter().zip(&force) {
        csv += &format!("{t},{f}\n");
    }
    let input = write(work.path(), "force.csv", &csv);
    let Some((header, truth)) = fmpy(
        &fmu,
        "me",
        "1",
        "0.01",
        &["y"],
        &input,
        true,
        &["damper.d=6"],
    ) else {
        return;
    };
    let y = header.iter().position(|h| h == "y").unwrap();
    assert_eq!(truth.len(), times.len());
    let mut record = String::from("time,position,force\n");
    for (row, f) in truth.iter().zip(&force) {
        record += &format!("{},{},{f}\n", row[0], row[y]);
    }
    let record = write(work.path(), "record.csv", &record);
    let campaign = write(
        work.path(),
        "damper.toml",
        &format!(
            r#"
[model]
fmu = "{}"
[measurement]
file = "{}"
[[outputs]]
model = "y"
measured = "position"
[[inputs]]
model = "f"
measured = "force"
interpolation = "hold"
[[parameters]]
name = "damper.d"
nominal = 10.0
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
    println!(
        "Mass_Damper driven by its force: damper.d {d:.6} (6), {} evaluations",
        result["evaluations"]
    );
    assert!((d - 6.0).abs() < 0.06, "damper.d = {d}");
}
