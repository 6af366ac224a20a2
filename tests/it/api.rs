//! The Calibration API: campaigns submitted to a coordinator over gRPC give the runs a local
//! calibration gives; submits are idempotent; cancels stop dispatching; bad requests are
//! named and leave the coordinator serving.

use crate::common::cluster::*;
use crate::common::coordinator::Coordinator;
use crate::common::*;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_client::CalibrationClient;
use serde_json::Value;
use std::path::Path;
use tonic::transport::Channel;

fn upload(c: &Coordinator, file: &Path) -> pb::Dataset {
    let bytes = std::fs::read(file).unwrap();
    let mut client = c.client();
    let chunks: Vec<pb::DatasetChunk> = bytes
        .chunks(4096)
        .enumerate()
        .map(|(i, data)| pb::DatasetChunk {
            file_name: if i == 0 {
                "record.csv".into()
            } else {
                String::new()
            },
            time_column: if i == 0 {
                "time_s".into()
            } else {
                String::new()
            },
            data: data.to_vec(),
        })
        .collect();
    c.runtime
        .block_on(client.upload_dataset(tokio_stream::iter(chunks)))
        .unwrap()
        .into_inner()
}

fn message(search: &str, dataset: &str) -> pb::Campaign {
    let text = clean_campaign(search);
    calib_service::api::spec::campaign_message(&text, dataset).unwrap()
}

/// Follow a campaign to its end; every state seen.
fn watch(c: &Coordinator, id: &str) -> Vec<pb::CampaignState> {
    let mut client = c.client();
    c.runtime.block_on(states_to_the_end(&mut client, id))
}

/// Every state a campaign's watch gives, to its end.
async fn states_to_the_end(
    client: &mut CalibrationClient<Channel>,
    id: &str,
) -> Vec<pb::CampaignState> {
    let mut stream = client
        .watch_campaign(pb::WatchCampaignRequest { id: id.into() })
        .await
        .unwrap()
        .into_inner();
    let mut states = Vec::new();
    while let Some(s) = stream.message().await.unwrap() {
        states.push(s);
    }
    states
}

fn runs_of(result: &Value) -> Vec<(String, u64, f64, Value)> {
    result["runs"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| {
            (
                r["method"].as_str().unwrap().to_string(),
                r["start"].as_u64().unwrap(),
                r["objective"].as_f64().unwrap(),
                r["parameters"].clone(),
            )
        })
        .collect()
}

fn local_runs(search: &str, dir: &Path) -> Vec<(String, u64, f64, Value)> {
    let campaign = write(dir, "local.toml", &clean_campaign(search));
    runs_of(&calibrate_json(
        &campaign,
        &dir.join("local-db"),
        &dir.join("local"),
        &[],
    ))
}

#[test]
fn calib_submit_gives_the_runs_of_calib_calibrate() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(2, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let search = "methods = [\"nelder-mead\", \"powell\"]\nstarts = 2\nmax_evaluations = 120";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let submitted = json_of(&calib(&[
        "submit",
        campaign.to_str().unwrap(),
        "--coordinator",
        &coordinator.url(),
        "--out",
        dir.path().join("submitted").to_str().unwrap(),
        "--json",
    ]));
    let local = calibrate_json(
        &campaign,
        &dir.path().join("local-db"),
        &dir.path().join("local"),
        &[],
    );
    assert_eq!(runs_of(&submitted), runs_of(&local));
    assert_eq!(submitted["best"], local["best"]);
    let folder = dir.path().join("submitted").join("clean");
    for file in ["result.json", "waterfall.svg", "armJoint.phi.svg"] {
        assert!(folder.join(file).exists(), "{file} not written");
    }
    assert!(cluster.simulations() > 0, "the workers simulated nothing");

    // `calib status` lists it as finished.
    let out = calib(&["status", "--coordinator", &coordinator.url()]);
    let listed = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && listed.contains("finished") && listed.contains("clean"));
}

/// Two experiments fitted together: a free swing, and a record driven by its measured arm
/// torque through the model's `armTorque` input.
fn experiments_campaign(swing: &Path, driven: &Path) -> String {
    format!(
        r#"
name = "pair"
[model]
name = "furuta"
{FURUTA_OUTPUTS}{FURUTA_FRICTIONS}[[experiments]]
name = "swing"
file = "{}"
time_column = "time_s"
window = {{ start = 0.0, stop = 10.0 }}
fixed = {{ theta0 = 0.5235987755983 }}
[[experiments]]
name = "driven"
file = "{}"
time_column = "time_s"
windows = [[0.0, 4.0], [5.0, 10.0]]
fixed = {{ theta0 = 0.2 }}
inputs = [ {{ model = "armTorque", measured = "motor_torque_Nm" }} ]
[search]
methods = ["nelder-mead"]
starts = 2
max_evaluations = 150
seed = 1
"#,
        swing.display(),
        driven.display()
    )
}

/// A campaign of two experiments, one driven by a measured torque, submitted with `calib
/// submit` (each record uploaded as a dataset, the input mapped) ends at the best point and
/// objective of the same file calibrated in this process, bit for bit; its frictions are the
/// records' truth.
#[test]
fn calib_submit_of_experiments_with_an_input_equals_the_local_calibration() {
    let dir = tempfile::tempdir().unwrap();
    let swing = furuta_record(
        &dir.path().join("swing.csv"),
        std::f64::consts::FRAC_PI_6,
        10.0,
        3,
        None,
    );
    let driven = furuta_record(
        &dir.path().join("driven.csv"),
        0.2,
        10.0,
        4,
        Some(&arm_torque),
    );
    let campaign = write(
        dir.path(),
        "pair.toml",
        &experiments_campaign(&swing, &driven),
    );
    let local = calib_engine::calibration::calibrate(
        &calib_engine::campaign::Campaign::load(&campaign).unwrap(),
        calib_engine::evaluator::LocalEvaluator,
        &calib_engine::optim::problem::Silent,
    )
    .unwrap();
    let summary = calib_analysis::report::table::summary(&local);
    let local = calib_analysis::report::result_json(&local);

    let cluster = TestCluster::start(2, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let out = calib(&[
        "submit",
        campaign.to_str().unwrap(),
        "--coordinator",
        &coordinator.url(),
        "--out",
        dir.path().join("submitted").to_str().unwrap(),
        "--json",
    ]);
    let submitted = json_of(&out);
    let uploads = String::from_utf8_lossy(&out.stderr)
        .matches(": dataset ")
        .count();
    assert_eq!(uploads, 2, "one upload per record");
    for key in ["parameters", "objective"] {
        assert_eq!(submitted["best"][key], local["best"][key], "best {key}");
    }
    let objective = |v: &Value| v["best"]["objective"].as_f64().unwrap();
    assert_eq!(
        objective(&submitted).to_bits(),
        objective(&local).to_bits(),
        "the objective bit for bit"
    );
    assert_eq!(runs_of(&submitted), runs_of(&local));
    let experiments = submitted["experiments"].as_array().unwrap();
    assert_eq!(experiments.len(), 2);
    assert_eq!(experiments[1]["inputs"][0]["model"], "armTorque");
    assert_eq!(
        experiments[1]["windows"],
        serde_json::json!([[0.0, 4.0], [5.0, 10.0]])
    );
    let (arm, pendulum) = true_frictions();
    let best = &submitted["best"]["parameters"];
    let arm_found = best["armFriction"].as_f64().unwrap();
    let pendulum_found = best["pendulumFriction"].as_f64().unwrap();
    println!(
        "armFriction {arm_found:.6e} (truth {arm:.6e}), pendulumFriction {pendulum_found:.6e} \
         (truth {pendulum:.6e}), objective {:.6e}",
        objective(&submitted)
    );
    assert!((arm_found / arm - 1.0).abs() < 0.02, "{arm_found} vs {arm}");
    assert!(
        (pendulum_found / pendulum - 1.0).abs() < 0.02,
        "{pendulum_found} vs {pendulum}"
    );
    // Submitted again (the coordinator answers the finished campaign), the summary `calib
    // calibrate` prints, but for the line of evaluations from the store and seconds.
    let out = calib(&[
        "submit",
        campaign.to_str().unwrap(),
        "--coordinator",
        &coordinator.url(),
        "--out",
        dir.path().join("submitted").to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let printed = String::from_utf8(out.stdout).unwrap();
    let same = |text: &str| -> Vec<String> {
        text.lines()
            .filter(|l| !l.contains("distinct minima") && !l.starts_with("wrote "))
            .map(str::to_string)
            .collect()
    };
    assert_eq!(same(&printed), same(&summary), "{printed}");
    for series in ["swing: armJoint.phi", "driven: pendulumJoint.phi"] {
        assert!(printed.contains(&format!("rms {series}")), "{printed}");
    }
    let folder = dir.path().join("submitted").join("pair");
    for file in [
        "swing.armJoint.phi.svg",
        "driven.pendulumJoint.phi.svg",
        "driven.input.armTorque.svg",
    ] {
        assert!(folder.join(file).exists(), "{file} not written");
    }
}

#[test]
fn two_campaigns_at_once_both_equal_their_local_runs_and_a_retried_submit_starts_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(2, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let dataset = upload(&coordinator, &repo().join("examples/data/furuta_clean.csv"));
    assert_eq!(dataset.id.len(), 64);
    assert!(dataset.columns.contains(&"arm_angle_rad".to_string()));
    // The same bytes again: the same dataset.
    assert_eq!(
        upload(&coordinator, &repo().join("examples/data/furuta_clean.csv")),
        dataset
    );

    let searches = [
        "methods = [\"nelder-mead\"]\nstarts = 3\nmax_evaluations = 100\nseed = 5",
        "methods = [\"powell\"]\nstarts = 2\nmax_evaluations = 100\nseed = 9",
    ];
    let mut client = coordinator.client();
    let mut ids = Vec::new();
    for (i, search) in searches.iter().enumerate() {
        let reply = coordinator
            .runtime
            .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
                campaign: Some(message(search, &dataset.id)),
                idempotency_key: format!("key-{i}"),
            }))
            .unwrap()
            .into_inner();
        assert!(reply.started);
        ids.push(reply.id);
    }
    assert_ne!(ids[0], ids[1]);
    // A retried submit, with the same key or the same campaign, returns the same id and
    // starts nothing.
    let again = coordinator
        .runtime
        .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
            campaign: Some(message(searches[1], &dataset.id)),
            idempotency_key: "key-0".into(),
        }))
        .unwrap()
        .into_inner();
    assert_eq!((again.id.as_str(), again.started), (ids[0].as_str(), false));
    let same = coordinator
        .runtime
        .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
            campaign: Some(message(searches[1], &dataset.id)),
            idempotency_key: String::new(),
        }))
        .unwrap()
        .into_inner();
    assert_eq!((same.id.as_str(), same.started), (ids[1].as_str(), false));

    for (id, search) in ids.iter().zip(searches) {
        let states = watch(&coordinator, id);
        let last = states.last().unwrap();
        assert_eq!(last.phase(), pb::CampaignPhase::Finished, "{last:?}");
        // Every state is whole: evaluations never go back.
        assert!(states
            .windows(2)
            .all(|w| w[0].evaluations <= w[1].evaluations));
        let result: Value = serde_json::from_str(&last.result_json).unwrap();
        assert_eq!(runs_of(&result), local_runs(search, dir.path()), "{search}");
        assert_eq!(last.run_best.len(), runs_of(&result).len());
        // Fetched again, or watched after the end: the same result.
        let fetched = coordinator
            .runtime
            .block_on(client.get_campaign(pb::GetCampaignRequest { id: id.clone() }))
            .unwrap()
            .into_inner();
        assert_eq!(fetched.result_json, last.result_json);
    }
}

/// Two campaigns that ask for the same points at once (one search on one record, under two
/// names) run through the coordinator's one dispatcher: each point is simulated once for
/// both, counted by the campaign that sent it, so that together they simulate the points
/// one campaign alone does; both end on the runs of `calib calibrate`.
#[test]
fn two_campaigns_asking_for_the_same_points_at_once_simulate_each_point_once() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(2, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let dataset = upload(&coordinator, &repo().join("examples/data/furuta_clean.csv"));
    let search = "methods = [\"nelder-mead\"]\nstarts = 3\nmax_evaluations = 100\nseed = 5";
    let mut client = coordinator.client();
    let ids: Vec<String> = ["twin-a", "twin-b"]
        .iter()
        .map(|name| {
            let mut campaign = message(search, &dataset.id);
            campaign.name = name.to_string();
            let request = pb::SubmitCampaignRequest {
                campaign: Some(campaign),
                idempotency_key: String::new(),
            };
            let reply = coordinator
                .runtime
                .block_on(client.submit_campaign(request));
            reply.unwrap().into_inner().id
        })
        .collect();
    assert_ne!(ids[0], ids[1]);
    let lasts: Vec<pb::CampaignState> = ids
        .iter()
        .map(|id| watch(&coordinator, id).pop().unwrap())
        .collect();
    let campaign = write(dir.path(), "local.toml", &clean_campaign(search));
    let local = calibrate_json(
        &campaign,
        &dir.path().join("local-db"),
        &dir.path().join("local"),
        &[],
    );
    for last in &lasts {
        assert_eq!(last.phase(), pb::CampaignPhase::Finished, "{last:?}");
        let result: Value = serde_json::from_str(&last.result_json).unwrap();
        assert_eq!(runs_of(&result), runs_of(&local));
    }
    let simulated: Vec<u64> = lasts.iter().map(|s| s.simulated).collect();
    eprintln!(
        "shared-points: simulated {simulated:?}, alone {}, on the workers {}",
        local["simulated"],
        cluster.simulations()
    );
    assert_eq!(
        simulated.iter().sum::<u64>(),
        local["simulated"].as_u64().unwrap(),
        "each point simulated once for both campaigns"
    );
}

#[test]
fn a_cancelled_campaign_stops_dispatching() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let dataset = upload(&coordinator, &repo().join("examples/data/furuta_clean.csv"));
    let search = "methods = [\"differential-evolution\"]\nstarts = 4\nmax_evaluations = 100000";
    let mut client = coordinator.client();
    let id = coordinator
        .runtime
        .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
            campaign: Some(message(search, &dataset.id)),
            idempotency_key: String::new(),
        }))
        .unwrap()
        .into_inner()
        .id;
    await_condition(
        "the campaign to evaluate",
        std::time::Duration::from_secs(60),
        || {
            let s = coordinator
                .runtime
                .block_on(client.get_campaign(pb::GetCampaignRequest { id: id.clone() }))
                .unwrap()
                .into_inner();
            s.evaluations > 50
        },
    );
    let state = coordinator
        .runtime
        .block_on(client.cancel_campaign(pb::CancelCampaignRequest { id: id.clone() }))
        .unwrap()
        .into_inner();
    assert_eq!(state.id, id);
    let last = watch(&coordinator, &id).pop().unwrap();
    assert_eq!(last.phase(), pb::CampaignPhase::Cancelled, "{last:?}");
    assert!(last.result_json.is_empty());
    // Once cancelled, nothing more is simulated: while another campaign runs to its end on
    // the same coordinator and workers, the workers simulate that campaign's points alone.
    let simulated = cluster.settled_simulations();
    let next = "methods = [\"nelder-mead\"]\nmax_evaluations = 40\nseed = 5";
    let next_id = coordinator
        .runtime
        .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
            campaign: Some(message(next, &dataset.id)),
            idempotency_key: String::new(),
        }))
        .unwrap()
        .into_inner()
        .id;
    let next_last = watch(&coordinator, &next_id).pop().unwrap();
    assert_eq!(
        next_last.phase(),
        pb::CampaignPhase::Finished,
        "{next_last:?}"
    );
    let next_result: Value = serde_json::from_str(&next_last.result_json).unwrap();
    let next_simulated = next_result["simulated"].as_u64().unwrap();
    assert!(next_simulated > 0, "{next_result}");
    assert_eq!(cluster.settled_simulations(), simulated + next_simulated);
    assert!(
        last.evaluations < 100_000,
        "{} evaluations: the campaign ran to its end",
        last.evaluations
    );
}

#[test]
fn malformed_requests_name_the_field_and_the_coordinator_keeps_serving() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let dataset = upload(&coordinator, &repo().join("examples/data/furuta_clean.csv"));
    let mut client = coordinator.client();
    let search = "methods = [\"nelder-mead\"]\nmax_evaluations = 10";
    let submit = |client: &mut CalibrationClient<Channel>, campaign: Option<pb::Campaign>| {
        coordinator
            .runtime
            .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
                campaign,
                idempotency_key: String::new(),
            }))
            .unwrap_err()
    };
    let experiments = |swing: &str, driven: &str| {
        let text = experiments_campaign(Path::new("swing.csv"), Path::new("driven.csv"));
        let ids = [swing.to_string(), driven.to_string()];
        calib_service::api::spec::campaign_message_on(&text, "", &ids).unwrap()
    };
    let cases: Vec<(Option<pb::Campaign>, tonic::Code, &str)> = vec![
        (None, tonic::Code::InvalidArgument, "campaign"),
        (
            Some(pb::Campaign {
                model: "pendulum".into(),
                ..message(search, &dataset.id)
            }),
            tonic::Code::InvalidArgument,
            "model",
        ),
        (
            Some({
                let mut m = message(search, &dataset.id);
                m.parameters[1].min = 0.9;
                m.parameters[1].max = 0.1;
                m
            }),
            tonic::Code::InvalidArgument,
            "parameters",
        ),
        (
            Some({
                let mut m = message(search, &dataset.id);
                m.outputs[0].measured = "no_such_column".into();
                m
            }),
            tonic::Code::InvalidArgument,
            "no_such_column",
        ),
        (
            Some(message(search, &"0".repeat(64))),
            tonic::Code::NotFound,
            "campaign.dataset_id",
        ),
        (
            Some(message(search, "")),
            tonic::Code::InvalidArgument,
            "campaign.dataset_id",
        ),
        // Experiments: each names its own dataset, which holds what it maps.
        (
            Some(experiments(&dataset.id, &dataset.id)),
            tonic::Code::InvalidArgument,
            "campaign.experiments[1].inputs[0].measured: dataset",
        ),
        (
            Some(experiments(&dataset.id, &"0".repeat(64))),
            tonic::Code::NotFound,
            "campaign.experiments[1].dataset_id",
        ),
        (
            Some(experiments(&dataset.id, "")),
            tonic::Code::InvalidArgument,
            "campaign.experiments[1].dataset_id: missing",
        ),
        (
            Some(pb::Campaign {
                dataset_id: dataset.id.clone(),
                ..experiments(&dataset.id, &dataset.id)
            }),
            tonic::Code::InvalidArgument,
            "campaign.dataset_id: with experiments",
        ),
        (
            Some({
                let mut m = experiments(&dataset.id, &dataset.id);
                m.experiments[1].inputs.clear();
                m.experiments[1].windows[1].stop = 99.0;
                m
            }),
            tonic::Code::InvalidArgument,
            "campaign.experiments[1].windows[1].stop: 99 s lies outside",
        ),
        (
            Some({
                let mut m = experiments(&dataset.id, &dataset.id);
                m.experiments[1].inputs[0].measured = "arm_angle_rad".into();
                m.experiments[1].inputs[0].interpolation = "cubic".into();
                m
            }),
            tonic::Code::InvalidArgument,
            "campaign.experiments[1] (driven).inputs[0] (armTorque): unknown interpolation",
        ),
    ];
    for (campaign, code, field) in cases {
        let status = submit(&mut client, campaign);
        assert_eq!(status.code(), code, "{status:?}");
        assert!(
            status.message().contains(field),
            "{field}: {}",
            status.message()
        );
    }
    // Uploads: no file name, an oversized chunk, a file that is not a record.
    let upload_err = |chunks: Vec<pb::DatasetChunk>| {
        let mut client = coordinator.client();
        coordinator
            .runtime
            .block_on(client.upload_dataset(tokio_stream::iter(chunks)))
            .unwrap_err()
    };
    let e = upload_err(vec![pb::DatasetChunk {
        data: b"time,a\n0,1\n".to_vec(),
        ..Default::default()
    }]);
    assert!(e.message().starts_with("file_name"), "{e:?}");
    let e = upload_err(vec![pb::DatasetChunk {
        file_name: "big.csv".into(),
        data: vec![b'1'; (1 << 20) + 1],
        ..Default::default()
    }]);
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    assert!(e.message().starts_with("data"), "{e:?}");
    let e = upload_err(vec![pb::DatasetChunk {
        file_name: "r.csv".into(),
        time_column: "t".into(),
        data: b"time,a\n0,1\n".to_vec(),
    }]);
    assert_eq!(e.code(), tonic::Code::InvalidArgument);
    assert!(e.message().contains("\"t\""), "{e:?}");
    for id in ["", "nonsense", &"f".repeat(64)] {
        let e = coordinator
            .runtime
            .block_on(client.get_campaign(pb::GetCampaignRequest { id: id.into() }))
            .unwrap_err();
        assert_eq!(e.code(), tonic::Code::NotFound, "{e:?}");
    }
    // Still serving.
    let listed = coordinator
        .runtime
        .block_on(client.list_campaigns(pb::ListCampaignsRequest::default()))
        .unwrap()
        .into_inner();
    assert!(listed.campaigns.is_empty());
}

/// `calib coordinator` on a store, in a process of its own; its address.
fn spawn_coordinator(dir: &Path, workers: &str) -> (std::process::Child, String) {
    let db = dir.join("db");
    let api = dir.join("api");
    let store = [
        "--db",
        db.to_str().unwrap(),
        "--api-dir",
        api.to_str().unwrap(),
    ];
    spawn_coordinator_in(dir, workers, &store)
}

/// `calib coordinator` started in the folder `cwd` with the store arguments `store`.
fn spawn_coordinator_in(
    cwd: &Path,
    workers: &str,
    store: &[&str],
) -> (std::process::Child, String) {
    use std::io::{BufRead, BufReader};
    let mut child = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .current_dir(cwd)
        .args([
            "coordinator",
            "--listen",
            "127.0.0.1:0",
            "--workers",
            workers,
        ])
        .args(store)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let address = line
        .trim()
        .strip_prefix("coordinator listening on ")
        .unwrap_or_else(|| panic!("unexpected first line: {line}"))
        .to_string();
    (child, format!("http://{address}"))
}

/// Every state of a campaign's watch on the coordinator at `url`, to its end.
fn watch_url(url: &str, id: &str) -> Vec<pb::CampaignState> {
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let mut client = CalibrationClient::connect(url.to_string()).await.unwrap();
        states_to_the_end(&mut client, id).await
    })
}

fn get(url: &str, id: &str) -> pb::CampaignState {
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let mut client = CalibrationClient::connect(url.to_string()).await.unwrap();
        client
            .get_campaign(pb::GetCampaignRequest { id: id.into() })
            .await
            .unwrap()
            .into_inner()
    })
}

#[test]
fn a_submitted_campaign_survives_a_killed_coordinator() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(2, 1);
    let search = "methods = [\"differential-evolution\", \"nelder-mead\"]\nstarts = 2\nmax_evaluations = 600";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let (mut first, url) = spawn_coordinator(dir.path(), &cluster.workers_arg());
    let submit = |url: &str| {
        let out = calib(&[
            "submit",
            campaign.to_str().unwrap(),
            "--coordinator",
            url,
            "--detach",
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).trim().to_string()
    };
    let id = submit(&url);
    let mut under_way = get(&url, &id);
    await_condition(
        "the campaign to be under way",
        std::time::Duration::from_secs(120),
        || {
            under_way = get(&url, &id);
            under_way.evaluations > 200
        },
    );
    first.kill().unwrap();
    assert_eq!(
        under_way.phase(),
        pb::CampaignPhase::Running,
        "{under_way:?}"
    );
    first.wait().unwrap();

    // A new coordinator on the same store finishes it, live: a client watching it sees it
    // run and end. Submitted again, it is the same campaign and starts nothing.
    let (mut second, url) = spawn_coordinator(dir.path(), &cluster.workers_arg());
    assert_eq!(submit(&url), id);
    let states = watch_url(&url, &id);
    let last = states.last().unwrap().clone();
    assert_eq!(last.phase(), pb::CampaignPhase::Finished, "{last:?}");
    assert!(
        states
            .iter()
            .any(|s| s.phase() == pb::CampaignPhase::Running && s.evaluations > 0),
        "the watch saw no progress of the resumed campaign: {states:?}"
    );
    second.kill().unwrap();
    second.wait().unwrap();
    let result: Value = serde_json::from_str(&last.result_json).unwrap();
    let local = calibrate_json(
        &campaign,
        &dir.path().join("local-db"),
        &dir.path().join("local"),
        &[],
    );
    assert_eq!(runs_of(&result), runs_of(&local));
}

#[test]
fn a_coordinator_on_a_relative_store_path_finds_the_data_uploaded_to_it() {
    // `--db db` from the coordinator's working directory: the API folder defaults to
    // `calib-api/` beside it, and a submitted campaign must find its dataset there.
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 1);
    let (mut coordinator, url) =
        spawn_coordinator_in(dir.path(), &cluster.workers_arg(), &["--db", "db"]);
    let search = "methods = [\"nelder-mead\"]\nstarts = 1\nmax_evaluations = 40";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let out = calib(&[
        "submit",
        campaign.to_str().unwrap(),
        "--coordinator",
        &url,
        "--out",
        dir.path().join("submitted").to_str().unwrap(),
        "--json",
    ]);
    coordinator.kill().unwrap();
    coordinator.wait().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.path().join("calib-api/datasets").is_dir());
    let local = calibrate_json(
        &campaign,
        &dir.path().join("local-db"),
        &dir.path().join("local"),
        &[],
    );
    assert_eq!(runs_of(&json_of(&out)), runs_of(&local));
}

#[test]
fn a_finished_campaign_is_diagnosed_on_the_coordinator() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(2, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let bytes = std::fs::read(repo().join("examples/data/furuta_viscous_arm.csv")).unwrap();
    let mut client = coordinator.client();
    let dataset = coordinator
        .runtime
        .block_on(
            client.upload_dataset(tokio_stream::iter(vec![pb::DatasetChunk {
                file_name: "furuta_viscous_arm.csv".into(),
                time_column: "time_s".into(),
                data: bytes,
            }])),
        )
        .unwrap()
        .into_inner();
    let text = std::fs::read_to_string(repo().join("examples/furuta_viscous_arm.toml")).unwrap();
    let campaign = calib_service::api::spec::campaign_message(&text, &dataset.id).unwrap();
    assert!(
        campaign.diagnosis.is_some(),
        "the [diagnosis] section travels"
    );
    let id = coordinator
        .runtime
        .block_on(client.submit_campaign(pb::SubmitCampaignRequest {
            campaign: Some(campaign),
            idempotency_key: String::new(),
        }))
        .unwrap()
        .into_inner()
        .id;
    let diagnose = |client: &mut CalibrationClient<Channel>| {
        coordinator.runtime.block_on(async {
            let mut stream = client
                .diagnose(pb::DiagnoseRequest {
                    id: id.clone(),
                    discover: false,
                })
                .await?
                .into_inner();
            let mut states = Vec::new();
            while let Some(s) = stream.message().await? {
                states.push(s);
            }
            Ok::<_, tonic::Status>(states)
        })
    };
    // Not before the campaign has finished.
    let early = diagnose(&mut client);
    if let Err(e) = &early {
        assert_eq!(e.code(), tonic::Code::InvalidArgument, "{e:?}");
        assert!(e.message().contains("not finished"), "{e:?}");
    }
    let last = watch(&coordinator, &id).pop().unwrap();
    assert_eq!(last.phase(), pb::CampaignPhase::Finished);

    let states = diagnose(&mut client).unwrap();
    let done = states.last().unwrap();
    assert_eq!(done.phase(), pb::CampaignPhase::Finished, "{done:?}");
    let report: Value = serde_json::from_str(&done.report_json).unwrap();
    assert_eq!(
        report["selected"],
        serde_json::json!(["viscous_friction.arm"])
    );
    assert_typed_twin(done.report.as_ref(), &done.report_json, &[]);
    assert_eq!(
        done.report.as_ref().unwrap().selected,
        vec!["viscous_friction.arm".to_string()]
    );
    assert!(done.files.contains_key("diagnosis.md"));
    // Asked again: the finished diagnosis, at once.
    let again = diagnose(&mut client).unwrap();
    assert_eq!(again.len(), 1);
    assert_eq!(again[0].report_json, done.report_json);
    let unknown = coordinator.runtime.block_on(async {
        client
            .diagnose(pb::DiagnoseRequest {
                id: "0".repeat(64),
                discover: false,
            })
            .await
            .map(|_| ())
    });
    assert_eq!(unknown.unwrap_err().code(), tonic::Code::NotFound);

    // Its profile, typed as its report_json.
    let profile = coordinator.runtime.block_on(async {
        let mut stream = client
            .profile(pb::ProfileRequest {
                id: id.clone(),
                parameters: vec!["armFriction".into()],
                max_steps: 3,
            })
            .await
            .unwrap()
            .into_inner();
        let mut last = None;
        while let Some(s) = stream.message().await.unwrap() {
            last = Some(s);
        }
        last.unwrap()
    });
    assert_eq!(profile.phase(), pb::CampaignPhase::Finished, "{profile:?}");
    assert_typed_twin(profile.profile.as_ref(), &profile.report_json, &[]);
    let typed = profile.profile.as_ref().unwrap();
    assert_eq!(typed.parameters[0].name, "armFriction");
    assert!(!typed.parameters[0].low.as_ref().unwrap().points.is_empty());
}

#[test]
fn a_sensitivity_analysis_over_the_api_equals_calib_sensitivitys_and_is_not_simulated_twice() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(2, 1);
    let coordinator = Coordinator::start(dir.path(), &cluster.urls());
    let dataset = upload(&coordinator, &repo().join("examples/data/furuta_clean.csv"));
    let search = "methods = [\"nelder-mead\"]\nstarts = 1\nmax_evaluations = 100";
    let request = pb::SensitivityRequest {
        campaign: Some(message(search, &dataset.id)),
        method: String::new(),
        samples: 16,
        seed: 3,
    };
    let mut client = coordinator.client();
    let analyse = |client: &mut CalibrationClient<Channel>| {
        coordinator.runtime.block_on(async {
            let mut stream = client
                .sensitivity(request.clone())
                .await
                .unwrap()
                .into_inner();
            let mut states = Vec::new();
            while let Some(s) = stream.message().await.unwrap() {
                states.push(s);
            }
            states
        })
    };
    let states = analyse(&mut client);
    let done = states.last().unwrap();
    assert_eq!(done.phase(), pb::CampaignPhase::Finished, "{done:?}");
    // Morris 16 · 3 points, Sobol 16 · 4.
    assert_eq!(done.planned, 16 * 3 + 16 * 4);
    assert_eq!(done.evaluations, done.planned);
    assert!(states
        .windows(2)
        .all(|w| w[0].evaluations <= w[1].evaluations));
    let report: Value = serde_json::from_str(&done.report_json).unwrap();
    assert_typed_twin(done.sensitivity.as_ref(), &done.report_json, &[]);
    assert!(done.profile.is_none());
    assert!(done.files.contains_key("sensitivity_objective.svg"));
    assert_eq!(report["conclusion"].as_str().unwrap(), done.conclusion);

    // The same analysis as `calib sensitivity` on the same campaign file, in one process.
    let campaign = write(dir.path(), "local.toml", &clean_campaign(search));
    let out = calib(&[
        "sensitivity",
        campaign.to_str().unwrap(),
        "--samples",
        "16",
        "--seed",
        "3",
        "--json",
        "--db",
        dir.path().join("local-db").to_str().unwrap(),
        "--out",
        dir.path().join("local").to_str().unwrap(),
    ]);
    let local = json_of(&out);
    assert_eq!(report["parameters"], local["parameters"]);
    assert_eq!(report["conclusion"], local["conclusion"]);

    // Asked again: the same analysis, finished, nothing simulated.
    let simulated = cluster.simulations();
    let again = analyse(&mut client);
    assert_eq!(again.len(), 1);
    assert_eq!(again[0].id, done.id);
    assert_eq!(again[0].report_json, done.report_json);
    let watched = coordinator.runtime.block_on(async {
        let mut stream = client
            .watch_analysis(pb::WatchAnalysisRequest {
                id: done.id.clone(),
            })
            .await
            .unwrap()
            .into_inner();
        stream.message().await.unwrap().unwrap()
    });
    assert_eq!(watched.report_json, done.report_json);
    assert_eq!(cluster.simulations(), simulated);

    // A bad request names its field.
    let mut bad = request.clone();
    bad.method = "fast".into();
    let refused = coordinator
        .runtime
        .block_on(async { client.sensitivity(bad).await.map(|_| ()) })
        .unwrap_err();
    assert_eq!(refused.code(), tonic::Code::InvalidArgument);
    assert!(refused.message().starts_with("method:"), "{refused:?}");
    let unknown = coordinator
        .runtime
        .block_on(async {
            client
                .watch_analysis(pb::WatchAnalysisRequest { id: "0".repeat(64) })
                .await
                .map(|_| ())
        })
        .unwrap_err();
    assert_eq!(unknown.code(), tonic::Code::NotFound);
    let no_campaign = coordinator
        .runtime
        .block_on(async {
            client
                .profile(pb::ProfileRequest {
                    id: "0".repeat(64),
                    ..Default::default()
                })
                .await
                .map(|_| ())
        })
        .unwrap_err();
    assert_eq!(no_campaign.code(), tonic::Code::NotFound);
}
