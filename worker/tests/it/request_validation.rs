//! Properties of the worker's request checks: any request, however malformed, is answered
//! with a checked simulation or a refusal that says what to fix, never a panic; a valid
//! request is accepted, and a valid request with one mistake is refused as an invalid
//! argument naming the mistaken field.

use calib_model::{limits, models, validate, Model};
use calib_proto::v1 as proto;
use calib_worker::service::request::{Evaluation, Simulation};
use calib_worker::service::Error;
use proptest::prelude::*;
use proptest::sample::select;

const CASES: u32 = 128;

fn model_names() -> Vec<String> {
    models::all()
        .iter()
        .map(|m| m.info().name.clone())
        .collect()
}

fn hosted(name: &str) -> &'static dyn Model {
    models::find(name).expect("hosted model")
}

/// Floats that trip checks: signs, zeros, extremes, non-finite values, and plain ones.
fn any_float() -> impl Strategy<Value = f64> {
    prop_oneof![
        select(vec![
            0.0,
            -0.0,
            1.0,
            -1.0,
            1e-300,
            1e300,
            f64::MIN_POSITIVE,
            f64::MAX,
            f64::MIN,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e6,
            1e6 + 1.0,
        ]),
        any::<f64>(),
        -10.0..100.0f64,
    ]
}

/// A name a request could use: one the models know, a near miss, or anything.
fn any_name() -> impl Strategy<Value = String> {
    let mut known: Vec<String> = model_names();
    for m in models::all() {
        let info = m.info();
        known.extend(info.parameters.iter().map(|p| p.name.clone()));
        known.extend(info.effects.iter().map(|e| e.name.clone()));
        known.extend(info.outputs.iter().map(|o| o.name.clone()));
    }
    prop_oneof![
        3 => select(known.clone()),
        1 => select(known).prop_map(|k| format!("{k}x")),
        1 => "\\PC{0,12}",
    ]
}

fn any_solver() -> impl Strategy<Value = Option<proto::SolverOptions>> {
    use proptest::option::of;
    of(
        (of(any_float()), of(any_float()), of(any::<u64>())).prop_map(|(rtol, atol, max_steps)| {
            proto::SolverOptions {
                rtol,
                atol,
                max_steps,
                ..Default::default()
            }
        }),
    )
}

fn any_parameters() -> impl Strategy<Value = Vec<proto::ParameterValue>> {
    prop::collection::vec(
        (any_name(), any_float()).prop_map(|(name, value)| proto::ParameterValue { name, value }),
        0..4,
    )
}

fn any_version() -> impl Strategy<Value = u32> {
    prop_oneof![4 => Just(calib_proto::PROTOCOL_VERSION), 1 => any::<u32>()]
}

fn any_simulate_request() -> impl Strategy<Value = proto::SimulateRequest> {
    (
        any_version(),
        prop_oneof![3 => select(model_names()), 1 => any_name()],
        any_parameters(),
        prop::collection::vec(any_float(), 0..6),
        prop::collection::vec(any_name(), 0..3),
        any_solver(),
    )
        .prop_map(
            |(protocol_version, model, parameters, times, outputs, solver)| {
                proto::SimulateRequest {
                    protocol_version,
                    model,
                    parameters,
                    times,
                    outputs,
                    solver,
                    fmu_hash: Vec::new(),
                    inputs: vec![],
                    effects: vec![],
                }
            },
        )
}

fn any_evaluate_request() -> impl Strategy<Value = proto::EvaluateRequest> {
    let measurement = (
        prop::collection::vec(any_float(), 0..4),
        prop::collection::vec(prop::collection::vec(any_float(), 0..4), 0..3),
    )
        .prop_map(|(times, columns)| proto::Measurement {
            times,
            columns: columns
                .into_iter()
                .map(|values| proto::Column { values })
                .collect(),
            inputs: vec![],
        });
    (
        (
            any_version(),
            prop_oneof![3 => select(model_names()), 1 => any_name()],
            any_parameters(),
            prop::collection::vec(any_name(), 0..3),
        ),
        prop::collection::vec(
            (any_name(), any_float())
                .prop_map(|(output, weight)| proto::ComparedOutput { output, weight }),
            0..3,
        ),
        prop_oneof![
            Just(vec![0u8; 32]),
            prop::collection::vec(any::<u8>(), 0..40)
        ],
        proptest::option::of(measurement),
        prop::collection::vec(
            prop::collection::vec(any_float(), 0..3).prop_map(|values| proto::Point { values }),
            0..3,
        ),
        any_solver(),
    )
        .prop_map(
            |(
                (protocol_version, model, parameters, free_parameters),
                outputs,
                measurement_hash,
                measurement,
                points,
                solver,
            )| proto::EvaluateRequest {
                protocol_version,
                model,
                parameters,
                free_parameters,
                outputs,
                measurement_hash,
                measurement,
                points,
                solver,
                fmu_hash: Vec::new(),
                residuals: false,
                effects: vec![],
            },
        )
}

/// A refusal as a client sees it: an invalid argument (or another protocol version) with a
/// message that names the field.
fn assert_explained(e: &Error, version: u32) {
    let message = e.to_string();
    match e {
        Error::InvalidArgument { field, message: m } => {
            assert!(!field.is_empty() && !m.is_empty(), "{message}");
            let status = tonic::Status::from(e.clone());
            assert_eq!(status.code(), tonic::Code::InvalidArgument);
        }
        Error::ProtocolMismatch { .. } => {
            assert_ne!(version, calib_proto::PROTOCOL_VERSION, "{message}")
        }
        other => panic!("a request check answered {other:?}"),
    }
}

/// What an accepted simulation must satisfy.
fn assert_sound(s: &Simulation) {
    let info = s.model.info();
    assert_eq!(s.params.len(), info.full_len());
    for (i, v) in s.params.iter().enumerate() {
        assert!(validate::parameter_value(info, i, *v).is_ok(), "{v}");
    }
    assert!(validate::output_grid(&s.times).is_ok());
    assert!(s.outputs.iter().all(|&o| o < info.outputs.len()));
    assert!(limits::RTOL.contains(&s.solver.rtol));
    assert!(limits::ATOL.contains(&s.solver.atol));
    assert!(limits::MAX_STEPS.contains(&(s.solver.max_steps as u64)));
}

/// A request every check accepts: known names, values within bounds, a sorted grid.
fn valid_simulate_request() -> impl Strategy<Value = proto::SimulateRequest> {
    select(model_names())
        .prop_flat_map(|model| {
            let info = hosted(&model).info().clone();
            let slots = info.full_len();
            let values =
                prop::collection::vec((0..slots, 0.0..=1.0f64), 0..4).prop_map(move |picks| {
                    let mut seen = Vec::new();
                    picks
                        .into_iter()
                        .filter(|(i, _)| {
                            let first = !seen.contains(i);
                            seen.push(*i);
                            first
                        })
                        .map(|(i, u)| {
                            let (lo, hi) = info.bounds_at(i);
                            proto::ParameterValue {
                                name: info.name_at(i).to_string(),
                                value: lo + u * (hi - lo),
                            }
                        })
                        .collect::<Vec<_>>()
                });
            let outputs = hosted(&model).info().outputs.clone();
            let output_names = prop::sample::subsequence(
                outputs.iter().map(|o| o.name.clone()).collect::<Vec<_>>(),
                0..=outputs.len(),
            );
            let times = prop::collection::vec(0.0..1e3f64, 1..8).prop_map(|mut t| {
                t.sort_by(f64::total_cmp);
                t
            });
            use proptest::option::of;
            let solver = of(
                (of(1e-12..1e-2f64), of(1e-12..1e-2f64), of(1..1_000_000u64)).prop_map(
                    |(rtol, atol, max_steps)| proto::SolverOptions {
                        rtol,
                        atol,
                        max_steps,
                        ..Default::default()
                    },
                ),
            );
            (Just(model), values, times, output_names, solver)
        })
        .prop_map(
            |(model, parameters, times, outputs, solver)| proto::SimulateRequest {
                protocol_version: calib_proto::PROTOCOL_VERSION,
                model,
                parameters,
                times,
                outputs,
                solver,
                fmu_hash: Vec::new(),
                inputs: vec![],
                effects: vec![],
            },
        )
}

/// One mistake, and the field its refusal must name.
#[derive(Debug, Clone)]
enum Mistake {
    UnknownModel(String),
    UnknownParameter(String),
    ParameterOutOfRange(f64),
    ParameterNotFinite(f64),
    NegativeTime(f64),
    TimeNotFinite(f64),
    DecreasingTimes,
    EmptyGrid,
    UnknownOutput(String),
    Rtol(f64),
    Atol(f64),
    MaxSteps(u64),
}

fn any_mistake() -> impl Strategy<Value = Mistake> {
    let not_finite = select(vec![f64::NAN, f64::INFINITY, f64::NEG_INFINITY]);
    prop_oneof![
        "[a-z]{1,8}".prop_map(|s| Mistake::UnknownModel(format!("no_{s}"))),
        "[a-z]{1,8}".prop_map(|s| Mistake::UnknownParameter(format!("no_{s}"))),
        (1e3..1e9f64).prop_map(Mistake::ParameterOutOfRange),
        not_finite.clone().prop_map(Mistake::ParameterNotFinite),
        (-1e9..-1e-9f64).prop_map(Mistake::NegativeTime),
        not_finite.prop_map(Mistake::TimeNotFinite),
        Just(Mistake::DecreasingTimes),
        Just(Mistake::EmptyGrid),
        "[a-z]{1,8}".prop_map(|s| Mistake::UnknownOutput(format!("no_{s}"))),
        prop_oneof![Just(0.0), Just(-1e-8), 0.2..10.0f64, Just(f64::NAN)].prop_map(Mistake::Rtol),
        prop_oneof![Just(0.0), Just(-1.0), Just(f64::INFINITY)].prop_map(Mistake::Atol),
        prop_oneof![Just(0u64), 10_000_001..u64::MAX].prop_map(Mistake::MaxSteps),
    ]
}

/// Put `mistake` into `r`; the field prefix the refusal must name.
fn make(mistake: &Mistake, r: &mut proto::SimulateRequest) -> &'static str {
    let solver = |r: &mut proto::SimulateRequest| {
        r.solver.get_or_insert(proto::SolverOptions {
            rtol: Some(1e-8),
            atol: Some(1e-10),
            max_steps: Some(1000),
            ..Default::default()
        });
    };
    match mistake.clone() {
        Mistake::UnknownModel(name) => {
            r.model = name;
            "model"
        }
        Mistake::UnknownParameter(name) => {
            r.parameters
                .push(proto::ParameterValue { name, value: 0.0 });
            "parameters["
        }
        Mistake::ParameterOutOfRange(value) | Mistake::ParameterNotFinite(value) => {
            // Every hosted model's first parameter is bounded well within 1e3.
            let name = hosted(&r.model).info().parameters[0].name.clone();
            r.parameters.retain(|p| p.name != name);
            r.parameters.push(proto::ParameterValue { name, value });
            "parameters["
        }
        Mistake::NegativeTime(t) | Mistake::TimeNotFinite(t) => {
            r.times.insert(0, t);
            "times"
        }
        Mistake::DecreasingTimes => {
            let last = *r.times.last().unwrap();
            r.times.push(last - 1.0);
            "times"
        }
        Mistake::EmptyGrid => {
            r.times.clear();
            "times"
        }
        Mistake::UnknownOutput(name) => {
            r.outputs.push(name);
            "outputs["
        }
        Mistake::Rtol(v) => {
            solver(r);
            r.solver.as_mut().unwrap().rtol = Some(v);
            "solver.rtol"
        }
        Mistake::Atol(v) => {
            solver(r);
            r.solver.as_mut().unwrap().atol = Some(v);
            "solver.atol"
        }
        Mistake::MaxSteps(v) => {
            solver(r);
            r.solver.as_mut().unwrap().max_steps = Some(v);
            "solver.max_steps"
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(CASES))]

    #[test]
    fn any_simulate_request_is_accepted_soundly_or_refused_with_a_reason(
        r in any_simulate_request()
    ) {
        let version = r.protocol_version;
        match Simulation::try_from(r) {
            Ok(s) => assert_sound(&s),
            Err(e) => assert_explained(&e, version),
        }
    }

    #[test]
    fn any_evaluate_request_is_accepted_or_refused_with_a_reason(r in any_evaluate_request()) {
        let version = r.protocol_version;
        match Evaluation::try_from(r) {
            Ok(e) => {
                prop_assert!(!e.points.is_empty() && e.points.len() <= limits::MAX_POINTS);
                prop_assert!(e.points.iter().all(|p| p.len() == e.free.len()));
                prop_assert!(e.weights.iter().all(|w| w.is_finite() && *w >= 0.0));
            }
            Err(e) => assert_explained(&e, version),
        }
    }

    #[test]
    fn a_valid_simulate_request_is_accepted(r in valid_simulate_request()) {
        let s = Simulation::try_from(r.clone());
        prop_assert!(s.is_ok(), "{:?} refused: {}", r, s.err().unwrap());
        let s = s.unwrap();
        assert_sound(&s);
        // Each option left unset is the model's own.
        let own = s.model.default_options();
        let given = r.solver.unwrap_or_default();
        prop_assert_eq!(s.solver.rtol, given.rtol.unwrap_or(own.rtol));
        prop_assert_eq!(s.solver.atol, given.atol.unwrap_or(own.atol));
        prop_assert_eq!(
            s.solver.max_steps as u64,
            given.max_steps.unwrap_or(own.max_steps as u64)
        );
    }

    #[test]
    fn one_mistake_is_refused_naming_its_field(
        r in valid_simulate_request(),
        mistake in any_mistake(),
    ) {
        let mut r = r;
        let field = make(&mistake, &mut r);
        match Simulation::try_from(r) {
            Ok(_) => prop_assert!(false, "{:?} was accepted", mistake),
            Err(Error::InvalidArgument { field: f, message }) => {
                prop_assert!(f.starts_with(field), "{:?}: {}: {}", mistake, f, message);
                prop_assert!(!message.is_empty());
            }
            Err(other) => prop_assert!(false, "{:?}: {:?}", mistake, other),
        }
    }
}
