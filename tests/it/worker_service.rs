//! The Simulator service as any client sees it: every bad request answered with the right
//! code naming the field, failures typed, floods refused, health and counters served.

use crate::common::cluster::TestWorker;
use calib_proto::v1 as proto;
use calib_proto::v1::simulator_client::SimulatorClient;
use tonic::transport::Channel;
use tonic::Code;

const V: u32 = calib_proto::PROTOCOL_VERSION;

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap()
}

async fn client(worker: &TestWorker) -> SimulatorClient<Channel> {
    SimulatorClient::connect(worker.url())
        .await
        .unwrap()
        .max_decoding_message_size(64 << 20)
        .max_encoding_message_size(64 << 20)
}

fn grid(stop: f64, step: f64) -> Vec<f64> {
    let n = (stop / step).round() as usize;
    (0..=n).map(|i| i as f64 * step).collect()
}

fn simulate_request() -> proto::SimulateRequest {
    proto::SimulateRequest {
        protocol_version: V,
        model: "furuta".into(),
        parameters: vec![proto::ParameterValue {
            name: "armFriction".into(),
            value: 0.01,
        }],
        times: grid(1.0, 0.01),
        outputs: vec!["armJoint.phi".into()],
        solver: None,
        fmu_hash: Vec::new(),
        inputs: vec![],
        effects: vec![],
    }
}

/// A measurement of one output on a short grid, with its hash.
fn measurement() -> (proto::Measurement, Vec<u8>) {
    let times = grid(1.0, 0.1);
    let values = vec![0.0; times.len()];
    let hash = calib_model::scoring::measurement_hash(&times, std::slice::from_ref(&values), &[]);
    (
        proto::Measurement {
            times,
            columns: vec![proto::Column { values }],
            inputs: vec![],
        },
        hash.to_vec(),
    )
}

fn evaluate_request(points: usize) -> proto::EvaluateRequest {
    let (measurement, hash) = measurement();
    proto::EvaluateRequest {
        protocol_version: V,
        model: "furuta".into(),
        parameters: Vec::new(),
        free_parameters: vec!["armFriction".into()],
        outputs: vec![proto::ComparedOutput {
            output: "armJoint.phi".into(),
            weight: 1.0,
        }],
        measurement_hash: hash,
        measurement: Some(measurement),
        points: (0..points)
            .map(|i| proto::Point {
                values: vec![0.01 + 1e-4 * i as f64],
            })
            .collect(),
        solver: None,
        fmu_hash: Vec::new(),
        residuals: false,
        effects: vec![],
    }
}

/// A bad request: what is wrong, how to spoil a good request, the code and field expected.
type Case<R> = (&'static str, Box<dyn Fn(&mut R)>, Code, &'static str);

/// Expect `code` with a message that starts with `field`.
fn expect(
    case: &str,
    result: Result<impl std::fmt::Debug, tonic::Status>,
    code: Code,
    field: &str,
) {
    let status = result.expect_err(case);
    assert_eq!(status.code(), code, "{case}: {}", status.message());
    assert!(
        status.message().starts_with(field),
        "{case}: `{}` does not name `{field}`",
        status.message()
    );
}

#[test]
fn every_bad_simulate_request_names_its_field() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        let cases: Vec<Case<proto::SimulateRequest>> = vec![
            (
                "unknown model",
                Box::new(|r| r.model = "furuta9".into()),
                Code::InvalidArgument,
                "model",
            ),
            (
                "unknown parameter",
                Box::new(|r| r.parameters[0].name = "armFrict".into()),
                Code::InvalidArgument,
                "parameters[0].name",
            ),
            (
                "NaN value",
                Box::new(|r| r.parameters[0].value = f64::NAN),
                Code::InvalidArgument,
                "parameters[0].value",
            ),
            (
                "infinite value",
                Box::new(|r| r.parameters[0].value = f64::INFINITY),
                Code::InvalidArgument,
                "parameters[0].value",
            ),
            (
                "value out of range",
                Box::new(|r| r.parameters[0].value = 5.0),
                Code::InvalidArgument,
                "parameters[0].value",
            ),
            (
                "negative stop time",
                Box::new(|r| r.times = vec![-1.0]),
                Code::InvalidArgument,
                "times",
            ),
            (
                "absurd stop time",
                Box::new(|r| r.times = vec![0.0, 1e9]),
                Code::InvalidArgument,
                "times",
            ),
            (
                "NaN time",
                Box::new(|r| r.times[3] = f64::NAN),
                Code::InvalidArgument,
                "times[3]",
            ),
            (
                "decreasing times",
                Box::new(|r| r.times.swap(3, 4)),
                Code::InvalidArgument,
                "times[4]",
            ),
            (
                "empty grid",
                Box::new(|r| r.times.clear()),
                Code::InvalidArgument,
                "times",
            ),
            (
                "too many points",
                Box::new(|r| r.times = vec![0.0; 500_001]),
                Code::InvalidArgument,
                "times",
            ),
            (
                "unknown output",
                Box::new(|r| r.outputs = vec!["armJoint.angle".into()]),
                Code::InvalidArgument,
                "outputs[0]",
            ),
            (
                "bad tolerance",
                Box::new(|r| {
                    r.solver = Some(proto::SolverOptions {
                        rtol: Some(0.0),
                        ..Default::default()
                    })
                }),
                Code::InvalidArgument,
                "solver.rtol",
            ),
            (
                "protocol version unset",
                Box::new(|r| r.protocol_version = 0),
                Code::FailedPrecondition,
                "protocol_version",
            ),
            (
                "protocol version ahead",
                Box::new(|r| r.protocol_version = V + 1),
                Code::FailedPrecondition,
                "protocol_version",
            ),
        ];
        for (case, change, code, field) in &cases {
            let mut request = simulate_request();
            change(&mut request);
            expect(case, c.simulate(request).await, *code, field);
        }
        // The unchanged request succeeds, and the worker simulated nothing else.
        let answer = c.simulate(simulate_request()).await.unwrap().into_inner();
        assert!(answer.failure.is_none());
        assert_eq!(answer.series[0].values.len(), 101);
        assert_eq!(worker.simulations(), 1);
    });
}

#[test]
fn every_bad_evaluate_request_names_its_field() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        let cases: Vec<Case<proto::EvaluateRequest>> = vec![
            (
                "unknown model",
                Box::new(|r| r.model = "nope".into()),
                Code::InvalidArgument,
                "model",
            ),
            (
                "unknown free parameter",
                Box::new(|r| r.free_parameters[0] = "nope".into()),
                Code::InvalidArgument,
                "free_parameters[0]",
            ),
            (
                "NaN point",
                Box::new(|r| r.points[1].values[0] = f64::NAN),
                Code::InvalidArgument,
                "points[1].values[0]",
            ),
            (
                "infinite point",
                Box::new(|r| r.points[0].values[0] = f64::NEG_INFINITY),
                Code::InvalidArgument,
                "points[0].values[0]",
            ),
            (
                "short point",
                Box::new(|r| r.points[0].values.clear()),
                Code::InvalidArgument,
                "points[0].values",
            ),
            (
                "no point",
                Box::new(|r| r.points.clear()),
                Code::InvalidArgument,
                "points",
            ),
            (
                "too many points",
                Box::new(|r| r.points = vec![proto::Point { values: vec![0.01] }; 10_001]),
                Code::InvalidArgument,
                "points",
            ),
            (
                "negative weight",
                Box::new(|r| r.outputs[0].weight = -1.0),
                Code::InvalidArgument,
                "outputs[0].weight",
            ),
            (
                "no output",
                Box::new(|r| r.outputs.clear()),
                Code::InvalidArgument,
                "outputs",
            ),
            (
                "short hash",
                Box::new(|r| r.measurement_hash.truncate(8)),
                Code::InvalidArgument,
                "measurement_hash",
            ),
            (
                "wrong hash",
                Box::new(|r| r.measurement_hash[0] ^= 1),
                Code::InvalidArgument,
                "measurement",
            ),
            (
                "empty measurement",
                Box::new(|r| r.measurement.as_mut().unwrap().times.clear()),
                Code::InvalidArgument,
                "measurement.times",
            ),
            (
                "ragged measurement",
                Box::new(|r| {
                    r.measurement.as_mut().unwrap().columns[0].values.pop();
                }),
                Code::InvalidArgument,
                "measurement.columns[0]",
            ),
            (
                "protocol mismatch",
                Box::new(|r| r.protocol_version = 7),
                Code::FailedPrecondition,
                "protocol_version",
            ),
            (
                "measurement not sent",
                Box::new(|r| r.measurement = None),
                Code::NotFound,
                "measurement_hash",
            ),
        ];
        for (case, change, code, field) in &cases {
            let mut request = evaluate_request(2);
            change(&mut request);
            expect(case, c.evaluate(request).await, *code, field);
        }
        assert_eq!(worker.simulations(), 0, "no bad request was simulated");
        // Once sent, the measurement is cached: the hash alone suffices.
        let answer = c.evaluate(evaluate_request(2)).await.unwrap().into_inner();
        assert_eq!(answer.results.len(), 2);
        let mut by_hash = evaluate_request(3);
        by_hash.measurement = None;
        let answer = c.evaluate(by_hash).await.unwrap().into_inner();
        assert_eq!(answer.results.len(), 3);
        assert!(answer
            .results
            .iter()
            .all(|r| r.failure.is_none() && r.objective > 0.0));
        let status = c
            .status(proto::StatusRequest {
                protocol_version: V,
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(status.simulations, 5);
        assert_eq!(status.evaluations, 5);
        assert_eq!(status.cached_measurements, 1);
    });
}

/// A client that never computes a hash: it sends the measurement once without one, and
/// names it afterwards by the hash the worker answered with.
#[test]
fn the_worker_names_a_measurement_sent_without_a_hash() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        let (_, expected) = measurement();
        let mut first = evaluate_request(3);
        first.measurement_hash.clear();
        let answered = c.evaluate(first).await.unwrap().into_inner();
        assert_eq!(answered.measurement_hash, expected);
        let mut later = evaluate_request(3);
        later.measurement = None;
        later.measurement_hash = answered.measurement_hash.clone();
        let again = c.evaluate(later).await.unwrap().into_inner();
        assert_eq!(again.results, answered.results);
        assert_eq!(again.measurement_hash, expected);
    });
}

#[test]
fn a_failed_simulation_is_a_typed_answer() {
    use proto::simulation_failure::Kind;
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        let mut request = simulate_request();
        request.solver = Some(proto::SolverOptions {
            max_steps: Some(5),
            ..Default::default()
        });
        let answer = c.simulate(request).await.unwrap().into_inner();
        let failure = answer.failure.expect("a failure");
        assert_eq!(failure.kind, Kind::StepLimit as i32, "{failure:?}");
        assert!(answer.series.is_empty());

        let mut request = evaluate_request(2);
        request.solver = Some(proto::SolverOptions {
            max_steps: Some(5),
            ..Default::default()
        });
        let answer = c.evaluate(request).await.unwrap().into_inner();
        for r in &answer.results {
            assert_eq!(r.objective, calib_model::scoring::FAILURE_PENALTY);
            assert_eq!(r.failure.as_ref().unwrap().kind, Kind::StepLimit as i32);
        }
        // The worker is still there.
        assert!(c.simulate(simulate_request()).await.is_ok());
    });
}

#[test]
fn a_flood_beyond_the_queue_is_refused() {
    // One slot, two waiting. Requests keep coming, each sent once the worker has taken in
    // (or answered) the one before, until one finds the slot and the queue full: that one is
    // refused and nothing else is. No duration is assumed: a request answered before the
    // next arrives only means the flood goes on, until one finds the queue full (the 60 s
    // bound guards against a hang). The heat exchanger's fine model over 300 s is a
    // simulation many round trips long, so the flood fills the queue within a few requests.
    let worker = TestWorker::start(1, 2);
    runtime().block_on(async {
        let c = client(&worker).await;
        let long = proto::SimulateRequest {
            protocol_version: V,
            model: "hx_highfi".into(),
            parameters: Vec::new(),
            times: grid(300.0, 1.0),
            outputs: Vec::new(),
            solver: None,
            fmu_hash: Vec::new(),
            inputs: vec![],
            effects: vec![],
        };
        // Requests the worker has taken in: done, running or waiting.
        let taken_in = |c: &SimulatorClient<Channel>| {
            let mut c = c.clone();
            async move {
                let s = c
                    .status(proto::StatusRequest {
                        protocol_version: V,
                    })
                    .await
                    .unwrap()
                    .into_inner();
                s.simulations + u64::from(s.running) + u64::from(s.queued)
            }
        };
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        let (mut admitted, mut served) = (Vec::new(), 0);
        let refusal = loop {
            assert!(
                std::time::Instant::now() < deadline,
                "no request found the queue full ({} waiting, {served} served)",
                admitted.len()
            );
            let before = taken_in(&c).await;
            let (mut c2, request) = (c.clone(), long.clone());
            let call = tokio::spawn(async move { c2.simulate(request).await.map(|_| ()) });
            while !call.is_finished() && taken_in(&c).await == before {
                assert!(std::time::Instant::now() < deadline, "a request vanished");
                tokio::task::yield_now().await;
            }
            if call.is_finished() {
                match call.await.unwrap() {
                    Ok(()) => served += 1,
                    Err(refusal) => break refusal,
                }
            } else {
                admitted.push(call);
            }
        };
        assert_eq!(refusal.code(), Code::ResourceExhausted, "{refusal:?}");
        // Refused with the slot and the queue full: three taken in before it, every one
        // served.
        for call in admitted {
            call.await.unwrap().expect("a request taken in is served");
            served += 1;
        }
        assert!(served >= 3, "{served} served");
        // Once the flood has drained, a batch larger than slots plus queue is answered.
        let answer = c.clone().evaluate(evaluate_request(4)).await.unwrap();
        assert_eq!(answer.into_inner().results.len(), 4);
        // And the worker still serves.
        assert!(c.clone().simulate(simulate_request()).await.is_ok());
    });
}

#[test]
fn a_batch_larger_than_the_queue_is_answered_in_full_by_an_idle_worker() {
    // Two slots and 128 waiting: 131 points are more than the worker holds at once.
    let worker = TestWorker::start(2, 128);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        let whole = c
            .evaluate(evaluate_request(131))
            .await
            .unwrap()
            .into_inner();
        assert_eq!(whole.results.len(), 131);
        assert!(whole.results.iter().all(|r| r.failure.is_none()));
        // The same points in pieces of two and of 129 give the same answers, bit for bit.
        let all = evaluate_request(131).points;
        let mut pieces = Vec::new();
        for range in [0..2, 2..131] {
            let mut request = evaluate_request(0);
            request.points = all[range].to_vec();
            pieces.extend(c.evaluate(request).await.unwrap().into_inner().results);
        }
        assert_eq!(pieces.len(), 131);
        for (i, (a, b)) in whole.results.iter().zip(&pieces).enumerate() {
            assert_eq!(a.objective.to_bits(), b.objective.to_bits(), "point {i}");
            assert_eq!(a.sse, b.sse, "point {i}");
        }
        assert_eq!(worker.simulations(), 262);
    });
}

#[test]
fn a_client_setting_every_described_default_simulates_the_defaults() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        let models = c
            .list_models(proto::ListModelsRequest {
                protocol_version: V,
            })
            .await
            .unwrap()
            .into_inner()
            .models;
        let furuta = models.iter().find(|m| m.name == "furuta").unwrap();
        let effect = |name: &str| furuta.effects.iter().find(|e| e.name == name).unwrap();
        let parameter = |name: &str| furuta.parameters.iter().find(|p| p.name == name).unwrap();
        for (alias, of) in [
            ("coulomb_friction.arm", "armFriction"),
            ("coulomb_friction.pendulum", "pendulumFriction"),
        ] {
            assert_eq!(effect(alias).alias_of, of);
            assert_eq!(effect(alias).default_value, parameter(of).default_value);
            assert!(effect(alias).default_value > 0.0);
        }
        assert!(furuta.parameters.iter().all(|p| p.alias_of.is_empty()));
        assert_eq!(effect("viscous_friction.arm").alias_of, "");
        for model in &models {
            let described = |with: Vec<proto::ParameterValue>| proto::SimulateRequest {
                protocol_version: V,
                model: model.name.clone(),
                parameters: with,
                times: grid(2.0, 0.1),
                outputs: Vec::new(),
                solver: None,
                fmu_hash: Vec::new(),
                inputs: vec![],
                effects: vec![],
            };
            let untouched = c
                .simulate(described(Vec::new()))
                .await
                .unwrap()
                .into_inner();
            assert!(untouched.failure.is_none(), "{}", model.name);
            // Every described default, aliases skipped, as the proto says.
            let every = model
                .parameters
                .iter()
                .chain(&model.effects)
                .filter(|p| p.alias_of.is_empty())
                .map(|p| proto::ParameterValue {
                    name: p.name.clone(),
                    value: p.default_value,
                })
                .collect();
            let answer = c.simulate(described(every)).await.unwrap().into_inner();
            assert_eq!(answer.series, untouched.series, "{}", model.name);
            // An alias set to its described default changes nothing either.
            for alias in model.effects.iter().filter(|e| !e.alias_of.is_empty()) {
                let only = vec![proto::ParameterValue {
                    name: alias.name.clone(),
                    value: alias.default_value,
                }];
                let answer = c.simulate(described(only)).await.unwrap().into_inner();
                assert_eq!(answer.series, untouched.series, "{}", alias.name);
            }
        }
    });
}

#[test]
fn solver_options_are_taken_field_by_field() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        let models = c
            .list_models(proto::ListModelsRequest {
                protocol_version: V,
            })
            .await
            .unwrap()
            .into_inner()
            .models;
        let own = |name: &str| {
            let m = models.iter().find(|m| m.name == name).unwrap();
            let s = m.default_solver.unwrap();
            (s.rtol.unwrap(), s.atol.unwrap(), s.max_steps.unwrap())
        };
        assert_eq!(own("furuta"), (1e-8, 1e-10, 200_000));
        assert_eq!(own("hx_lowfi"), (1e-6, 1e-8, 200_000));
        assert_eq!(own("hx_highfi"), (1e-6, 1e-8, 200_000));
        // Only rtol set: accepted, with the model's own atol and max_steps.
        let with = |solver| {
            let mut r = simulate_request();
            r.solver = Some(solver);
            r
        };
        let only_rtol = c
            .simulate(with(proto::SolverOptions {
                rtol: Some(1e-6),
                ..Default::default()
            }))
            .await
            .unwrap()
            .into_inner();
        assert!(only_rtol.failure.is_none());
        let (_, atol, max_steps) = own("furuta");
        let spelled_out = c
            .simulate(with(proto::SolverOptions {
                rtol: Some(1e-6),
                atol: Some(atol),
                max_steps: Some(max_steps),
                ..Default::default()
            }))
            .await
            .unwrap()
            .into_inner();
        assert_eq!(only_rtol.series, spelled_out.series);
        assert_eq!(only_rtol.statistics, spelled_out.statistics);
        // And it differs from the model's own rtol: the field was taken.
        let own_rtol = c.simulate(simulate_request()).await.unwrap().into_inner();
        assert_ne!(only_rtol.statistics, own_rtol.statistics);
        // A field set to 0 is checked, not taken for unset.
        expect(
            "atol 0",
            c.simulate(with(proto::SolverOptions {
                atol: Some(0.0),
                ..Default::default()
            }))
            .await,
            Code::InvalidArgument,
            "solver.atol",
        );
    });
}

#[test]
fn read_only_calls_accept_the_protocol_version_unset() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        for version in [0, V] {
            let models = c
                .list_models(proto::ListModelsRequest {
                    protocol_version: version,
                })
                .await
                .unwrap()
                .into_inner()
                .models;
            assert_eq!(models.len(), 3);
            let furuta = c
                .describe(proto::DescribeRequest {
                    protocol_version: version,
                    model: "furuta".into(),
                })
                .await
                .unwrap()
                .into_inner();
            assert_eq!(furuta.model.unwrap().name, "furuta");
            let status = c
                .status(proto::StatusRequest {
                    protocol_version: version,
                })
                .await
                .unwrap()
                .into_inner();
            assert_eq!(status.protocol_version, V);
        }
        // Another version is refused by every call.
        let other = V + 1;
        let list = c
            .list_models(proto::ListModelsRequest {
                protocol_version: other,
            })
            .await;
        expect("list", list, Code::FailedPrecondition, "protocol_version");
        let describe = c
            .describe(proto::DescribeRequest {
                protocol_version: other,
                model: "furuta".into(),
            })
            .await;
        expect(
            "describe",
            describe,
            Code::FailedPrecondition,
            "protocol_version",
        );
        let status = c
            .status(proto::StatusRequest {
                protocol_version: other,
            })
            .await;
        expect(
            "status",
            status,
            Code::FailedPrecondition,
            "protocol_version",
        );
        // Requests that simulate still require the version.
        let mut simulate = simulate_request();
        simulate.protocol_version = 0;
        let answer = c.simulate(simulate).await;
        expect(
            "simulate",
            answer,
            Code::FailedPrecondition,
            "protocol_version",
        );
        let mut evaluate = evaluate_request(1);
        evaluate.protocol_version = 0;
        let answer = c.evaluate(evaluate).await;
        expect(
            "evaluate",
            answer,
            Code::FailedPrecondition,
            "protocol_version",
        );
        assert_eq!(worker.simulations(), 0);
    });
}

#[test]
fn health_and_models_are_served() {
    use tonic_health::pb::health_client::HealthClient;
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut health = HealthClient::new(
            Channel::from_shared(worker.url())
                .unwrap()
                .connect()
                .await
                .unwrap(),
        );
        for service in ["", "calib.v1.Simulator"] {
            let answer = health
                .check(tonic_health::pb::HealthCheckRequest {
                    service: service.into(),
                })
                .await
                .unwrap()
                .into_inner();
            assert_eq!(
                answer.status,
                tonic_health::pb::health_check_response::ServingStatus::Serving as i32
            );
        }
        let mut c = client(&worker).await;
        let models = c
            .list_models(proto::ListModelsRequest {
                protocol_version: V,
            })
            .await
            .unwrap()
            .into_inner()
            .models;
        let names: Vec<_> = models.iter().map(|m| m.name.as_str()).collect();
        assert_eq!(names, ["furuta", "hx_highfi", "hx_lowfi"]);
        let furuta = c
            .describe(proto::DescribeRequest {
                protocol_version: V,
                model: "furuta".into(),
            })
            .await
            .unwrap()
            .into_inner()
            .model
            .unwrap();
        assert!(furuta
            .parameters
            .iter()
            .any(|p| p.name == "armFriction" && p.unit.contains('N')));
        expect(
            "describe unknown",
            c.describe(proto::DescribeRequest {
                protocol_version: V,
                model: "x".into(),
            })
            .await,
            Code::InvalidArgument,
            "model",
        );
    });
}

/// The services a reflection client of protocol version `$v` (v1 or v1alpha) lists.
macro_rules! listed_services {
    ($v:ident, $channel:expr) => {{
        use tonic_reflection::pb::$v::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::$v::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::$v::server_reflection_response::MessageResponse;
        use tonic_reflection::pb::$v::ServerReflectionRequest;
        let request = ServerReflectionRequest {
            host: String::new(),
            message_request: Some(MessageRequest::ListServices(String::new())),
        };
        let mut answers = ServerReflectionClient::new($channel)
            .server_reflection_info(tokio_stream::iter(vec![request]))
            .await
            .unwrap()
            .into_inner();
        let answer = answers.message().await.unwrap().unwrap();
        let Some(MessageResponse::ListServicesResponse(list)) = answer.message_response else {
            panic!("unexpected answer {answer:?}");
        };
        let mut names: Vec<String> = list.service.into_iter().map(|s| s.name).collect();
        names.sort();
        names
    }};
}

#[test]
fn reflection_lists_exactly_the_served_services_in_both_versions() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let channel = Channel::from_shared(worker.url())
            .unwrap()
            .connect()
            .await
            .unwrap();
        let expected = [
            "calib.v1.Simulator",
            "grpc.health.v1.Health",
            "grpc.reflection.v1.ServerReflection",
            "grpc.reflection.v1alpha.ServerReflection",
        ];
        assert_eq!(listed_services!(v1, channel.clone()), expected);
        assert_eq!(listed_services!(v1alpha, channel.clone()), expected);
        assert_eq!(calib_worker::service::SERVED, expected);
        // The Registry is the coordinator's: a worker does not answer it.
        let mut registry = calib_proto::v1::registry_client::RegistryClient::new(channel.clone());
        let status = registry
            .register(proto::RegisterRequest::default())
            .await
            .unwrap_err();
        assert_eq!(status.code(), Code::Unimplemented);
    });
}

/// Whether a reflection client of protocol version `$v` gets the file that defines
/// `$symbol`, and which file that is (or the refusal).
macro_rules! file_containing {
    ($v:ident, $channel:expr, $symbol:expr) => {{
        use tonic_reflection::pb::$v::server_reflection_client::ServerReflectionClient;
        use tonic_reflection::pb::$v::server_reflection_request::MessageRequest;
        use tonic_reflection::pb::$v::server_reflection_response::MessageResponse;
        use tonic_reflection::pb::$v::ServerReflectionRequest;
        let request = ServerReflectionRequest {
            host: String::new(),
            message_request: Some(MessageRequest::FileContainingSymbol($symbol.to_string())),
        };
        let mut answers = ServerReflectionClient::new($channel)
            .server_reflection_info(tokio_stream::iter(vec![request]))
            .await
            .unwrap()
            .into_inner();
        let answer = answers.message().await.unwrap().unwrap();
        match answer.message_response {
            Some(MessageResponse::FileDescriptorResponse(files)) => {
                Ok(files.file_descriptor_proto.len())
            }
            Some(MessageResponse::ErrorResponse(error)) => {
                Err(format!("{}: {}", error.error_code, error.error_message))
            }
            other => panic!("unexpected answer {other:?}"),
        }
    }};
}

/// Every service a server lists can be described, in both versions of the protocol.
async fn assert_every_listed_service_is_described(channel: Channel, server: &str) {
    let listed = listed_services!(v1, channel.clone());
    assert!(
        listed.contains(&"grpc.reflection.v1alpha.ServerReflection".to_string()),
        "{server}: {listed:?}"
    );
    for service in &listed {
        let v1 = file_containing!(v1, channel.clone(), service);
        let v1alpha = file_containing!(v1alpha, channel.clone(), service);
        assert!(
            matches!(v1, Ok(n) if n > 0),
            "{server}, v1, {service}: {v1:?}"
        );
        assert!(
            matches!(v1alpha, Ok(n) if n > 0),
            "{server}, v1alpha, {service}: {v1alpha:?}"
        );
    }
}

#[test]
fn reflection_describes_every_listed_service_in_both_versions() {
    let worker = TestWorker::start(1, 16);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let channel = Channel::from_shared(worker.url())
            .unwrap()
            .connect()
            .await
            .unwrap();
        assert_every_listed_service_is_described(channel, "worker").await;
    });
    let coordinator = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let config = calib_service::server::CoordinatorConfig::new(
            "127.0.0.1:0".parse().unwrap(),
            calib_sandbox::cluster::dispatch_config(&[worker.url()]),
        );
        calib_service::server::serve_coordinator(listener, config).unwrap()
    });
    runtime.block_on(async {
        let channel = Channel::from_shared(format!("http://{}", coordinator.address()))
            .unwrap()
            .connect()
            .await
            .unwrap();
        assert_every_listed_service_is_described(channel, "coordinator").await;
        coordinator.shutdown().await;
    });
}

#[test]
fn answers_larger_than_one_message_are_refused_before_anything_is_simulated() {
    let worker = TestWorker::start(1, 16);
    runtime().block_on(async {
        let mut c = client(&worker).await;
        // 10,000 points with the residuals of 2,001 samples: 20 million numbers.
        let mut evaluate = evaluate_request(10_000);
        let times = grid(20.0, 0.01);
        let column = proto::Column {
            values: vec![0.0; times.len()],
        };
        evaluate.measurement = Some(proto::Measurement {
            times,
            columns: vec![column],
            inputs: vec![],
        });
        evaluate.measurement_hash.clear();
        evaluate.points = vec![proto::Point { values: vec![0.01] }; 10_000];
        evaluate.residuals = true;
        let status = c.evaluate(evaluate.clone()).await.unwrap_err();
        assert_eq!(status.code(), Code::InvalidArgument, "{status:?}");
        assert!(
            status
                .message()
                .starts_with("points: the answer would carry 10000 × 2001")
                && status.message().contains("ask for at most 3668 at once"),
            "{}",
            status.message()
        );
        // Without residuals the same request is a few numbers per point: answered.
        evaluate.residuals = false;
        evaluate.points.truncate(3);
        assert_eq!(
            c.evaluate(evaluate)
                .await
                .unwrap()
                .into_inner()
                .results
                .len(),
            3
        );

        let status = c
            .status(proto::StatusRequest {
                protocol_version: V,
            })
            .await
            .unwrap()
            .into_inner();
        assert_eq!(
            status.simulations, 3,
            "only the three points answered were simulated"
        );
    });
}
