use super::*;
use crate::model::{SimulationError, SolverOptions};
use crate::models;
use crate::Run;

fn effect(name: &str, kind: PlaceKind, place: &str, formula: &str, params: &[&str]) -> UserEffect {
    UserEffect {
        name: name.into(),
        kind,
        place: place.into(),
        formula: formula.into(),
        parameters: params
            .iter()
            .map(|p| UserParameter {
                name: (*p).into(),
                nominal: 0.0,
                min: -10.0,
                max: 10.0,
            })
            .collect(),
    }
}

fn grid(stop: f64, step: f64) -> Vec<f64> {
    (0..=(stop / step).round() as usize)
        .map(|i| i as f64 * step)
        .collect()
}

/// The model with `effects`, the base's defaults with `set` applied by name.
fn vector(model: &dyn Model, set: &[(&str, f64)]) -> Vec<f64> {
    let info = model.info();
    let mut p = info.default_vector();
    for (name, v) in set {
        p[info.parameter_index(name).unwrap()] = *v;
    }
    p
}

#[test]
fn a_constant_formula_on_an_hx_output_is_its_offset() {
    let base = models::find("hx_lowfi").unwrap();
    let output = base.info().outputs[0].name.clone();
    let defined = [
        effect("shift", PlaceKind::Output, &output, "c", &["c"]),
        effect("scale", PlaceKind::Output, &output, "g * y", &["g"]),
    ];
    let with = attach(base, &defined).unwrap();
    let t = grid(60.0, 1.0);
    let options = base.default_options();
    let all: Vec<usize> = (0..base.info().outputs.len()).collect();
    let formula = with
        .simulate(&Run::new(
            &vector(with, &[("shift.c", 0.37)]),
            &t,
            &all,
            &options,
        ))
        .unwrap();
    let offset = format!("offset({output})");
    let built_in = base
        .simulate(&Run::new(
            &vector(base, &[(offset.as_str(), 0.37)]),
            &t,
            &all,
            &options,
        ))
        .unwrap();
    let worst = formula.values[0]
        .iter()
        .zip(&built_in.values[0])
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    assert!(worst <= 1e-12, "{worst:e}");
    // The other outputs are untouched.
    assert_eq!(formula.values[1..], built_in.values[1..]);
    // `y` is the output's own value: g * y is a gain error.
    let gained = with
        .simulate(&Run::new(
            &vector(with, &[("scale.g", 0.1)]),
            &t,
            &[0],
            &options,
        ))
        .unwrap();
    let gain = format!("gain({output})");
    let built_in = base
        .simulate(&Run::new(
            &vector(base, &[(gain.as_str(), 0.1)]),
            &t,
            &[0],
            &options,
        ))
        .unwrap();
    for (a, b) in gained.values[0].iter().zip(&built_in.values[0]) {
        assert!((a - b).abs() <= 1e-12 * b.abs().max(1.0), "{a} vs {b}");
    }
}

#[test]
fn a_formula_torque_is_the_built_in_viscous_friction_bit_for_bit() {
    let base = models::find("furuta").unwrap();
    let defined = [effect(
        "damping.arm",
        PlaceKind::Torque,
        "armJoint",
        "-b * armJoint.w",
        &["b"],
    )];
    let with = attach(base, &defined).unwrap();
    let t = grid(20.0, 0.01);
    let options = SolverOptions::default();
    let formula = with
        .simulate(&Run::new(
            &vector(with, &[("damping.arm.b", 0.003)]),
            &t,
            &[0, 1],
            &options,
        ))
        .unwrap();
    let built_in = base
        .simulate(&Run::new(
            &vector(base, &[("viscous_friction.arm", 0.003)]),
            &t,
            &[0, 1],
            &options,
        ))
        .unwrap();
    assert_eq!(formula.values, built_in.values);
    let free = base
        .simulate(&Run::new(&vector(base, &[]), &t, &[0, 1], &options))
        .unwrap();
    assert_ne!(formula.values, free.values, "the torque acts");
}

#[test]
fn an_output_formula_reads_other_outputs_and_time() {
    let base = models::find("furuta").unwrap();
    let defined = [effect(
        "mix",
        PlaceKind::Output,
        "armJoint.phi",
        "a * pendulumJoint.w * time",
        &["a"],
    )];
    let with = attach(base, &defined).unwrap();
    let t = grid(5.0, 0.1);
    let options = SolverOptions::default();
    // Only the transformed output is asked for: the one it reads is simulated too.
    let mixed = with
        .simulate(&Run::new(
            &vector(with, &[("mix.a", 0.5)]),
            &t,
            &[0],
            &options,
        ))
        .unwrap();
    let plain = base
        .simulate(&Run::new(&vector(base, &[]), &t, &[0, 3], &options))
        .unwrap();
    assert_eq!(mixed.values.len(), 1);
    for (i, &time) in t.iter().enumerate() {
        let want = plain.values[0][i] + 0.5 * plain.values[1][i] * time;
        assert_eq!(mixed.values[0][i], want);
    }
}

#[test]
fn the_same_definitions_are_compiled_once() {
    let base = models::find("furuta").unwrap();
    let defined = [effect(
        "bias.arm",
        PlaceKind::Torque,
        "armJoint",
        "t0",
        &["t0"],
    )];
    let a = attach(base, &defined).unwrap();
    let b = attach(base, &defined).unwrap();
    assert!(std::ptr::addr_eq(a, b));
    assert_eq!(a.user_effects(), &defined);
    assert_eq!(a.info().name, "furuta");
    assert_eq!(a.info().full_len(), base.info().full_len() + 1);
    let other = [effect(
        "bias.arm",
        PlaceKind::Torque,
        "armJoint",
        "-t0",
        &["t0"],
    )];
    assert!(!std::ptr::addr_eq(a, attach(base, &other).unwrap()));
}

#[test]
fn a_model_without_torques_refuses_one() {
    let base = models::find("hx_lowfi").unwrap();
    let defined = [effect("t", PlaceKind::Torque, "armJoint", "1", &[])];
    let e = attach(base, &defined).err().unwrap();
    assert_eq!(e.field, "effects[0].torque");
    assert!(e.message.contains("has no torque `armJoint`"), "{e}");
}

/// The failure of a Furuta swing with one user effect `formula` at `kind`/`place`.
fn failure_with(kind: PlaceKind, place: &str, formula: &str) -> SimulationError {
    let base = models::find("furuta").unwrap();
    let with = attach(base, &[effect("odd", kind, place, formula, &["b"])]).unwrap();
    let p = vector(with, &[("odd.b", 0.5)]);
    match with.simulate(&Run::new(
        &p,
        &grid(5.0, 0.01),
        &[0, 1],
        &SolverOptions::default(),
    )) {
        Ok(_) => panic!("{formula}: simulated"),
        Err(e) => e,
    }
}

#[test]
fn a_torque_or_output_term_that_is_not_a_number_fails_the_simulation_naming_it() {
    use PlaceKind::{Output, Torque};
    // NaN and inf from the start, after a time, and once the arm (pushed by the torque)
    // has swung past 0.1 rad: each fails where it is first not a number.
    for (kind, place, formula, value, after) in [
        (Torque, "armJoint", "b * sqrt(-1)", "NaN", 0.0),
        (Torque, "pendulumJoint", "b / (time - time)", "inf", 0.0),
        (Torque, "armJoint", "b * sqrt(0.5 - time)", "NaN", 0.5),
        (
            Torque,
            "armJoint",
            "b * sqrt(0.1 - abs(armJoint.phi))",
            "NaN",
            0.01,
        ),
        (Output, "armJoint.phi", "b * sqrt(-1)", "NaN", 0.0),
        (Output, "pendulumJoint.phi", "b / (time - 2)", "inf", 2.0),
    ] {
        let e = failure_with(kind, place, formula);
        let SimulationError::Failed { time, reason } = &e else {
            panic!("{formula}: {e}");
        };
        let what = if kind == Torque { "torque" } else { "term" };
        assert!(
            reason.starts_with(&format!(
                "the {what} of effect `odd` on `{place}` is {value}"
            )) && reason.ends_with(&format!("(formula `{formula}`)")),
            "{formula}: {reason}"
        );
        assert!(
            *time >= after && *time <= after + 0.5,
            "{formula}: at {time} s"
        );
    }
}
