//! FMUs driven by input signals, run by calib in this process and by FMPy
//! (`tests/python/fmpy_simulate.py --input`) on the same signals, through the same interface:
//! the Reference FMU `Feedthrough` (a real, a discrete real, an integer and a boolean input
//! passed to its outputs) and OpenModelica's `Mass_Damper` of gemseo-fmu (a force on a
//! damped mass on a spring), each read linearly and held.

use crate::real_tool_fmus::real_tool_fmus;
use crate::reference_fmus::{read_reference, reference_fmus};
use calib_model::fmu::{self, Interface};
use calib_model::inputs::{InputSignal, Inputs, Interpolation};
use calib_model::testing::skip;
use calib_model::Run;
use calib_model::{Model, SolverOptions};
use std::path::{Path, PathBuf};

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the workspace")
        .to_path_buf()
}

/// Samples of named signals: times, then one column per input.
struct Table {
    names: Vec<&'static str>,
    times: Vec<f64>,
    columns: Vec<Vec<f64>>,
}

impl Table {
    fn write(&self, path: &Path) {
        let mut text = format!("time,{}\n", self.names.join(","));
        for (i, t) in self.times.iter().enumerate() {
            let row: Vec<String> = self.columns.iter().map(|c| format!("{:?}", c[i])).collect();
            text += &format!("{t:?},{}\n", row.join(","));
        }
        std::fs::write(path, text).unwrap();
    }

    fn inputs(&self, model: &dyn Model, interpolation: Interpolation) -> Inputs {
        let info = model.info();
        Inputs {
            signals: self
                .names
                .iter()
                .zip(&self.columns)
                .map(|(name, values)| InputSignal {
                    input: info
                        .input_index(name)
                        .unwrap_or_else(|| panic!("input {name}")),
                    times: self.times.clone().into(),
                    values: values.clone().into(),
                    interpolation,
                })
                .collect(),
        }
    }
}

/// FMPy's run of `fmu` driven by the table in `input` (held with `hold`): rows with time
/// first, then `names`, or `None` where FMPy is not installed (a failure under CI).
#[allow(clippy::too_many_arguments)]
fn fmpy(
    fmu: &Path,
    interface: Interface,
    stop: f64,
    step: f64,
    rtol: f64,
    names: &[&str],
    input: &Path,
    hold: bool,
) -> Option<Vec<Vec<f64>>> {
    let out = input.with_extension("fmpy.csv");
    let mut command = std::process::Command::new("python3");
    command
        .arg(repo().join("tests/python/fmpy_simulate.py"))
        .arg(fmu)
        .arg(match interface {
            Interface::ModelExchange => "me",
            Interface::CoSimulation => "cs",
        })
        .arg(stop.to_string())
        .arg(step.to_string())
        .arg(rtol.to_string())
        .arg(&out)
        .args(names)
        .arg("--input")
        .arg(input);
    if hold {
        command.arg("--hold");
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
    let (header, rows) = read_reference(&out);
    let order: Vec<usize> = std::iter::once("time")
        .chain(names.iter().copied())
        .map(|n| header.iter().position(|h| h == n).expect("a column"))
        .collect();
    Some(
        rows.iter()
            .map(|r| order.iter().map(|&k| r[k]).collect())
            .collect(),
    )
}

/// calib's run, in this process, onto `grid` (rows with time first, then `names`).
fn calib(
    model: &dyn Model,
    names: &[&str],
    grid: &[f64],
    options: &SolverOptions,
    inputs: &Inputs,
) -> Vec<Vec<f64>> {
    let info = model.info();
    let outputs: Vec<usize> = names
        .iter()
        .map(|n| info.output_index(n).unwrap())
        .collect();
    let t = model
        .simulate(&Run::new(&info.default_vector(), grid, &outputs, options).driven(inputs))
        .unwrap_or_else(|e| panic!("{}: {e}", info.name));
    grid.iter()
        .enumerate()
        .map(|(i, &time)| {
            std::iter::once(time)
                .chain(t.values.iter().map(|v| v[i]))
                .collect()
        })
        .collect()
}

/// Per output, the largest |calib − FMPy| over the rows of `ours` (FMPy's rows at the same
/// times, found in `theirs`), relative to FMPy's range of that output (at least `floor`).
fn worst_relative(ours: &[Vec<f64>], theirs: &[Vec<f64>], floor: f64) -> Vec<f64> {
    let matched: Vec<&Vec<f64>> = ours
        .iter()
        .map(|r| {
            theirs
                .iter()
                .find(|s| (s[0] - r[0]).abs() <= 1e-9 * r[0].abs().max(1.0))
                .unwrap_or_else(|| panic!("FMPy has no row at {}", r[0]))
        })
        .collect();
    (1..ours[0].len())
        .map(|k| {
            let (lo, hi) = matched
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, r| {
                    (a.0.min(r[k]), a.1.max(r[k]))
                });
            let diff = ours
                .iter()
                .zip(&matched)
                .map(|(a, b)| (a[k] - b[k]).abs())
                .fold(0.0, f64::max);
            diff / (hi - lo).max(floor)
        })
        .collect()
}

fn grid(stop: f64, step: f64) -> Vec<f64> {
    let n = (stop / step).round() as usize;
    (0..=n).map(|i| i as f64 * step).collect()
}

const FEEDTHROUGH: [&str; 4] = [
    "Float64_continuous_input",
    "Float64_discrete_input",
    "Int32_input",
    "Boolean_input",
];
const PASSED: [&str; 4] = [
    "Float64_continuous_output",
    "Float64_discrete_output",
    "Int32_output",
    "Boolean_output",
];

/// Signals for the Feedthrough every 0.1 s over 2 s, with a step (two samples at 1 s) in
/// the real one; the integer takes fractional values (rounded: -3 … 3), the boolean 0 and
/// 0.8 (true when it rounds to non-zero).
fn feedthrough_table() -> Table {
    let mut times: Vec<f64> = (0..=20).map(|k| f64::from(k) * 0.1).collect();
    times.insert(11, 1.0);
    let columns = vec![
        times
            .iter()
            .enumerate()
            .map(|(k, &t)| (3.0 * t).sin() + if k > 10 { 2.0 } else { 0.0 })
            .collect(),
        times.iter().map(|&t| (2.0 * t).cos()).collect(),
        times.iter().map(|&t| 3.2 * (2.0 * t).sin()).collect(),
        times
            .iter()
            .map(|&t| if (5.0 * t).sin() > 0.0 { 0.8 } else { 0.0 })
            .collect(),
    ];
    Table {
        names: FEEDTHROUGH.to_vec(),
        times,
        columns,
    }
}

/// The Reference FMU `Feedthrough` (FMI 2.0 and 3.0, Model Exchange and Co-Simulation)
/// passes its inputs to its outputs: calib's outputs on a 0.05 s grid are FMPy's, read
/// linearly (the real input; the discrete ones held, as FMPy holds them) and held, and the
/// grid times between samples show the interpolation (0.05 s is half-way).
#[test]
fn the_feedthrough_fmu_passes_real_integer_and_boolean_inputs_as_fmpy_does() {
    let Some(dir) = reference_fmus() else {
        return;
    };
    let scratch = tempfile::tempdir().unwrap();
    let table = feedthrough_table();
    let grid = grid(2.0, 0.05);
    let mut compared = 0;
    for version in [2, 3] {
        let path = dir.join(format!("fmi{version}/Feedthrough.fmu"));
        if version == 3 && !path.exists() {
            continue;
        }
        for interface in [Interface::ModelExchange, Interface::CoSimulation] {
            let model = fmu::open_local(&path, Some(interface)).unwrap();
            let names: Vec<String> = model.info().inputs.iter().map(|i| i.name.clone()).collect();
            for name in FEEDTHROUGH {
                assert!(names.iter().any(|n| n == name), "FMI {version}: {names:?}");
            }
            for hold in [false, true] {
                let interpolation = if hold {
                    Interpolation::Hold
                } else {
                    Interpolation::Linear
                };
                let input = scratch.path().join(format!("in-{version}-{hold}.csv"));
                table.write(&input);
                let options = SolverOptions {
                    communication_step: Some(0.05),
                    ..SolverOptions::default()
                };
                let ours = calib(
                    &model,
                    &PASSED,
                    &grid,
                    &options,
                    &table.inputs(&model, interpolation),
                );
                let Some(theirs) = fmpy(&path, interface, 2.0, 0.05, 1e-8, &PASSED, &input, hold)
                else {
                    return;
                };
                let worst = worst_relative(&ours, &theirs, 1.0);
                assert!(
                    worst.iter().all(|w| *w <= 1e-12),
                    "FMI {version} {} hold={hold}: {worst:?}\n{ours:?}\nvs {theirs:?}",
                    interface.name()
                );
                // Between samples: the real input linear or held, the integer rounded.
                let at = |t: f64| ours.iter().find(|r| (r[0] - t).abs() < 1e-12).unwrap();
                let half = (0.3f64.sin() + 0.6f64.sin()) / 2.0;
                let expected = if hold { 0.3f64.sin() } else { half };
                // Co-Simulation holds each input over a communication step (the grid's): its
                // outputs at t are what it was given at the step's start.
                if interface == Interface::ModelExchange || hold {
                    assert!((at(0.15)[1] - expected).abs() < 1e-12, "{:?}", at(0.15));
                }
                assert_eq!(at(0.25)[3], (3.2 * 0.4f64.sin()).round());
                if interface == Interface::ModelExchange {
                    assert_eq!(at(1.0)[1], 3.0f64.sin() + 2.0, "the step at 1 s");
                }
                compared += 1;
            }
        }
    }
    assert!(compared >= 4);
}

/// A force on gemseo-fmu's Mass_Damper (OpenModelica 1.19, FMI 2.0: 1 kg on a 10 kN/m
/// spring with a 10 N.s/m damper): `100 sin(20 t)` N sampled every 0.01 s, plus a 50 N step
/// at 0.5 s, for 1 s. calib and FMPy on the same samples:
/// - Co-Simulation (the FMU's explicit Euler at a 1e-4 s communication step, the inputs set
///   before each step): equal to 1e-12 of the range, linear and held;
/// - Model Exchange held (each jump a time event for both): within 1e-5 of the range
///   (measured 6e-7) at rtol 1e-8;
/// - Model Exchange linear: FMPy 0.3.32 sets the inputs after each of CVode's steps and
///   before each event-indicator evaluation, not before each derivative evaluation, so its
///   inputs lag by up to a step: at a 0.01 s output interval it is 2.5e-3 of the range off
///   calib, at 1e-4 s 2.9e-5, at 1e-5 s 4e-6 (calib's own run moves by 4e-8 from rtol 1e-8 to
///   1e-11). Compared at FMPy's 1e-4 s, within 1e-4 of the range.
#[test]
fn an_openmodelica_fmu_driven_by_a_force_agrees_with_fmpy() {
    let Some(dir) = real_tool_fmus() else {
        return;
    };
    let _alone = crate::one_real_tool_fmu_at_a_time();
    let path = dir.join("gemseo-fmu/Mass_Damper.fmu");
    let scratch = tempfile::tempdir().unwrap();
    let times: Vec<f64> = (0..=100).map(|k| f64::from(k) * 0.01).collect();
    let force: Vec<f64> = times
        .iter()
        .map(|&t| 100.0 * (20.0 * t).sin() + if t >= 0.5 { 50.0 } else { 0.0 })
        .collect();
    let table = Table {
        names: vec!["f"],
        times,
        columns: vec![force],
    };
    let input = scratch.path().join("force.csv");
    table.write(&input);
    let grid = grid(1.0, 0.01);
    let names = ["y", "mass.v"];
    let mut report = Vec::new();
    for interface in [Interface::ModelExchange, Interface::CoSimulation] {
        let model = fmu::open_local(&path, Some(interface)).unwrap();
        for hold in [false, true] {
            let interpolation = if hold {
                Interpolation::Hold
            } else {
                Interpolation::Linear
            };
            let (options, fmpy_step, bound) = match interface {
                Interface::CoSimulation => (
                    SolverOptions {
                        rtol: 1e-6,
                        communication_step: Some(1e-4),
                        ..SolverOptions::default()
                    },
                    1e-4,
                    1e-12,
                ),
                Interface::ModelExchange => (
                    SolverOptions {
                        rtol: 1e-8,
                        atol: 1e-10,
                        ..SolverOptions::default()
                    },
                    if hold { 0.01 } else { 1e-4 },
                    if hold { 1e-5 } else { 1e-4 },
                ),
            };
            let ours = calib(
                &model,
                &names,
                &grid,
                &options,
                &table.inputs(&model, interpolation),
            );
            let Some(theirs) = fmpy(
                &path,
                interface,
                1.0,
                fmpy_step,
                options.rtol,
                &names,
                &input,
                hold,
            ) else {
                return;
            };
            let worst = worst_relative(&ours, &theirs, 1e-6);
            report.push(format!(
                "{} {}: {:.1e} (allowed {bound:e})",
                interface.name(),
                if hold { "held" } else { "linear" },
                worst.iter().fold(0.0f64, |a, b| a.max(*b))
            ));
            assert!(
                worst.iter().all(|w| *w <= bound),
                "{}",
                report.last().unwrap()
            );
            // The force moves the mass: by far more than the agreement.
            let swing = ours
                .iter()
                .map(|r| r[1])
                .fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(swing > 0.01, "{swing}");
        }
    }
    eprintln!(
        "Mass_Damper, max |calib − FMPy| / range per output:\n{}",
        report.join("\n")
    );
}

/// A signal that names no input, or does not cover the simulated span, is refused before
/// the FMU runs; an FMU's inputs are described with their start values.
#[test]
fn an_fmus_inputs_are_described_and_bad_signals_refused() {
    let Some(dir) = reference_fmus() else {
        return;
    };
    let model = fmu::open_local(
        &dir.join("fmi2/Feedthrough.fmu"),
        Some(Interface::ModelExchange),
    )
    .unwrap();
    let info = model.info();
    let int = &info.inputs[info.input_index("Int32_input").unwrap()];
    assert!(
        int.description.contains("rounded") && int.description.contains("undriven: 0"),
        "{}",
        int.description
    );
    let short = Inputs {
        signals: vec![InputSignal {
            input: 0,
            times: vec![0.0, 0.5].into(),
            values: vec![1.0, 2.0].into(),
            interpolation: Interpolation::Linear,
        }],
    };
    let e = model
        .simulate(
            &Run::new(
                &info.default_vector(),
                &[0.0, 1.0],
                &[0],
                &SolverOptions::default(),
            )
            .driven(&short),
        )
        .unwrap_err();
    assert!(e.to_string().contains("do not cover"), "{e}");
}
