//! The web app's JSON routes on a coordinator (`--http`): each answers what the gRPC
//! method it transcodes answers, on the same campaigns and workers; failures keep the
//! RPC's status and message. Its door (Host, same origin, login) is tested in
//! `tests/it/web_door.rs`.

use crate::common::cluster::*;
use crate::common::*;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_client::CalibrationClient;
use calib_service::server::{serve_coordinator, CoordinatorConfig, RunningCoordinator};
use std::io::{Read, Write};
use std::net::SocketAddr;
use std::path::Path;

struct Coordinator {
    runtime: tokio::runtime::Runtime,
    server: Option<RunningCoordinator>,
}

fn config(dir: &Path, workers: &[String]) -> CoordinatorConfig {
    let mut config = CoordinatorConfig::new(
        "127.0.0.1:0".parse().unwrap(),
        calib_sandbox::cluster::dispatch_config(workers),
    );
    config.store = Some(dir.join("db"));
    config.api = Some(dir.join("api"));
    config.http = Some("127.0.0.1:0".parse().unwrap());
    config
}

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

impl Coordinator {
    fn start(dir: &Path, workers: &[String]) -> Self {
        let runtime = runtime();
        let config = config(dir, workers);
        let server = runtime.block_on(async {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            serve_coordinator(listener, config).unwrap()
        });
        Self {
            runtime,
            server: Some(server),
        }
    }

    fn http(&self) -> SocketAddr {
        self.server
            .as_ref()
            .unwrap()
            .http_address()
            .expect("--http")
    }

    fn grpc<T>(
        &self,
        call: impl AsyncFnOnce(
            CalibrationClient<tonic::transport::Channel>,
        ) -> Result<tonic::Response<T>, tonic::Status>,
    ) -> T {
        let url = format!("http://{}", self.server.as_ref().unwrap().address());
        self.runtime.block_on(async {
            let client = CalibrationClient::connect(url).await.unwrap();
            call(client).await.unwrap().into_inner()
        })
    }
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        if let Some(server) = self.server.take() {
            self.runtime.block_on(server.shutdown());
        }
    }
}

/// One HTTP/1.1 request: the status code and the body.
fn http(address: SocketAddr, method: &str, path: &str, body: &[u8]) -> (u16, String) {
    let mut stream = std::net::TcpStream::connect(address).unwrap();
    write!(
        stream,
        "{method} {path} HTTP/1.1\r\nHost: {address}\r\nConnection: close\r\n\
         Content-Type: application/json\r\nContent-Length: {}\r\n\r\n",
        body.len()
    )
    .unwrap();
    stream.write_all(body).unwrap();
    let mut answer = Vec::new();
    stream.read_to_end(&mut answer).unwrap();
    let answer = String::from_utf8(answer).unwrap();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap();
    let code = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    (code, body.to_string())
}

fn post(address: SocketAddr, method: &str, request: serde_json::Value) -> (u16, String) {
    let body = serde_json::to_vec(&request).unwrap();
    http(address, "POST", &format!("/api/v1/{method}"), &body)
}

#[test]
fn the_coordinators_json_routes_answer_what_its_grpc_methods_answer() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 2);
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let web = c.http();

    // The page itself, compiled in.
    let (code, page) = http(web, "GET", "/", b"");
    assert_eq!(code, 200);
    assert!(page.contains("<title>calib</title>") && page.contains("/js/main.js"));
    assert_eq!(http(web, "GET", "/js/common.js", b"").0, 200);

    // Upload over HTTP: the dataset gRPC names for the same bytes.
    let bytes = std::fs::read(repo().join("examples/data/furuta_clean.csv")).unwrap();
    let (code, body) = http(
        web,
        "POST",
        "/api/v1/UploadDataset?file_name=record.csv&time_column=time_s",
        &bytes,
    );
    assert_eq!(code, 200, "{body}");
    let dataset: pb::Dataset = serde_json::from_str(&body).unwrap();
    let chunk = pb::DatasetChunk {
        file_name: "record.csv".into(),
        time_column: "time_s".into(),
        data: bytes,
    };
    let over_grpc =
        c.grpc(async move |mut client| client.upload_dataset(tokio_stream::iter([chunk])).await);
    assert_eq!(dataset, over_grpc);

    // Submit over HTTP, follow over gRPC: one campaign, run on the workers.
    let search = "methods = [\"nelder-mead\"]\nstarts = 2\nmax_evaluations = 80\nseed = 3";
    let text = clean_campaign(search);
    let campaign = calib_service::api::spec::campaign_message(&text, &dataset.id).unwrap();
    let (code, body) = post(
        web,
        "SubmitCampaign",
        serde_json::to_value(pb::SubmitCampaignRequest {
            campaign: Some(campaign),
            idempotency_key: String::new(),
        })
        .unwrap(),
    );
    assert_eq!(code, 200, "{body}");
    let submitted: pb::SubmitCampaignResponse = serde_json::from_str(&body).unwrap();
    assert!(submitted.started);
    let id = submitted.id.clone();
    let states = c.grpc(async |mut client| {
        let mut stream = client
            .watch_campaign(pb::WatchCampaignRequest { id: id.clone() })
            .await?
            .into_inner();
        let mut last = None;
        while let Some(s) = stream.message().await? {
            last = Some(s);
        }
        Ok(tonic::Response::new(last.unwrap()))
    });
    assert_eq!(
        states.phase,
        pb::CampaignPhase::Finished as i32,
        "{states:?}"
    );
    assert!(cluster.simulations() > 0, "the workers simulated nothing");

    // GetCampaign and ListCampaigns over HTTP equal their gRPC answers.
    let request = pb::GetCampaignRequest { id: id.clone() };
    let (code, body) = post(web, "GetCampaign", serde_json::to_value(&request).unwrap());
    assert_eq!(code, 200, "{body}");
    // (As JSON: a run's best before its first point is +inf in the progress history, null
    // in JSON, which no JSON decoder reads back as a number.)
    let over_http: serde_json::Value = serde_json::from_str(&body).unwrap();
    let over_grpc = c.grpc(async |mut client| client.get_campaign(request.clone()).await);
    assert_eq!(over_http, serde_json::to_value(&over_grpc).unwrap());
    assert!(over_grpc.plots.contains_key("waterfall.svg"));
    let (_, body) = post(
        web,
        "ListCampaigns",
        serde_json::to_value(pb::ListCampaignsRequest::default()).unwrap(),
    );
    // Lists leave each campaign's progress history out.
    let listed: serde_json::Value = serde_json::from_str(&body).unwrap();
    let without_history = pb::CampaignState {
        history: Vec::new(),
        ..over_grpc.clone()
    };
    assert_eq!(
        listed["campaigns"],
        serde_json::to_value(vec![without_history]).unwrap()
    );

    // WatchCampaign as Server-Sent Events: the finished state, then the stream ends.
    let (code, body) = http(web, "GET", &format!("/api/v1/WatchCampaign/{id}"), b"");
    assert_eq!(code, 200);
    let data: Vec<&str> = body
        .lines()
        .filter_map(|l| l.strip_prefix("data: "))
        .collect();
    assert_eq!(data.len(), 1, "{body}");
    let watched: serde_json::Value = serde_json::from_str(data[0]).unwrap();
    assert_eq!(watched, serde_json::to_value(&over_grpc).unwrap());

    // The campaign file it ran from.
    let (code, toml) = http(
        web,
        "GET",
        &format!("/ui/campaigns/{id}/campaign.toml"),
        b"",
    );
    assert_eq!(code, 200);
    assert!(
        toml.contains("armFriction") && toml.contains("max_evaluations = 80"),
        "{toml}"
    );

    // The Simulator's Describe and Simulate.
    let (code, body) = post(
        web,
        "Describe",
        serde_json::to_value(pb::DescribeRequest {
            protocol_version: 0,
            model: "furuta".into(),
        })
        .unwrap(),
    );
    assert_eq!(code, 200, "{body}");
    let described: pb::DescribeResponse = serde_json::from_str(&body).unwrap();
    assert!(described
        .model
        .unwrap()
        .parameters
        .iter()
        .any(|p| p.name == "armFriction" && p.unit == "N.m"));
    let (code, body) = post(
        web,
        "Simulate",
        serde_json::json!({"protocol_version": 1, "model": "furuta",
            "times": [0.0, 0.5, 1.0], "outputs": ["pendulumJoint.phi"]}),
    );
    assert_eq!(code, 200, "{body}");
    let simulated: pb::SimulateResponse = serde_json::from_str(&body).unwrap();
    assert_eq!(simulated.series.len(), 1);
    let theta = &simulated.series[0].values;
    // The pendulum starts at π/6 from upright and falls.
    assert!((theta[0] - std::f64::consts::FRAC_PI_6).abs() < 1e-12 && theta[2] > theta[0]);
}

#[test]
fn json_routes_fail_with_the_rpcs_status_and_message() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), &[]);
    let web = c.http();
    let (code, body) = http(
        web,
        "POST",
        "/api/v1/UploadDataset?file_name=rig.csv&time_column=time_s",
        b"time_s,a\n0,1\n0.01,two\n",
    );
    assert_eq!(code, 400, "{body}");
    let error: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(error["code"], "InvalidArgument");
    let message = error["message"].as_str().unwrap();
    assert!(message.starts_with("data: rig.csv line 3"), "{message}");

    // Complete but for its dataset: the reference to nothing is what is refused.
    let mut campaign = pb::Campaign {
        model: "furuta".into(),
        dataset_id: "0".repeat(64),
        outputs: vec![pb::Output {
            model: "armJoint.phi".into(),
            measured: "arm_angle_rad".into(),
            ..Default::default()
        }],
        parameters: vec![pb::Parameter {
            name: "armFriction".into(),
            min: 0.0,
            max: 0.9,
            ..Default::default()
        }],
        window_stop: 10.0,
        ..Default::default()
    };
    let (code, body) = post(
        web,
        "SubmitCampaign",
        serde_json::to_value(pb::SubmitCampaignRequest {
            campaign: Some(campaign.clone()),
            idempotency_key: String::new(),
        })
        .unwrap(),
    );
    assert_eq!(code, 404, "{body}");
    assert!(body.contains("campaign.dataset_id: no dataset"), "{body}");
    campaign.dataset_id.clear();
    let (code, body) = post(
        web,
        "SubmitCampaign",
        serde_json::to_value(pb::SubmitCampaignRequest {
            campaign: Some(campaign),
            idempotency_key: String::new(),
        })
        .unwrap(),
    );
    assert_eq!(code, 400, "{body}");
    assert!(body.contains("campaign.dataset_id: missing"), "{body}");
    let (code, body) = http(web, "POST", "/api/v1/GetCampaign", b"{\"id\": 7}");
    assert_eq!(code, 400, "{body}");
    assert!(body.contains("request:"), "{body}");
    let (code, body) = http(
        web,
        "GET",
        &format!("/api/v1/Diagnose/{}", "a".repeat(64)),
        b"",
    );
    assert_eq!(code, 404, "{body}");

    // A body over the route's limit: refused in JSON too.
    let (code, body) = http(web, "POST", "/api/v1/ListCampaigns", &vec![b' '; 3 << 20]);
    assert_eq!(code, 413, "{body}");
    let error: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(error["code"], "ResourceExhausted");
    assert!(
        error["message"].as_str().unwrap().contains("2 MiB"),
        "{body}"
    );
}

#[test]
fn calib_ui_finishes_the_campaigns_its_store_holds_unfinished() {
    use calib_engine::store::{CampaignStatus, SledStore, Store};
    use calib_service::web::local::{start_ui, UiConfig};
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\"]\nstarts = 2\nmax_evaluations = 60\nseed = 4";
    let campaign = write(dir.path(), "clean.toml", &clean_campaign(search));
    let db = dir.path().join("db");
    let done = calibrate_json(&campaign, &db, &dir.path().join("out"), &[]);
    // As a killed run leaves it: the campaign still running in the store.
    let id = {
        let store = SledStore::open(&db).unwrap();
        let (id, mut record) = store.campaigns().unwrap().pop().unwrap();
        record.status = CampaignStatus::Running;
        record.result = None;
        store.put_campaign(&id, &record).unwrap();
        calib_engine::store::hex(&id)
    };

    let runtime = runtime();
    let ui = runtime
        .block_on(start_ui(UiConfig {
            listen: "127.0.0.1:0".parse().unwrap(),
            store: db,
            api: Some(dir.path().join("api")),
            allow_hosts: Vec::new(),
        }))
        .unwrap();
    let web = ui.address();
    // Until it has run, its objectives are +inf: `null` in JSON.
    let mut state = serde_json::Value::Null;
    await_condition(
        "the campaign finished again",
        std::time::Duration::from_secs(120),
        || {
            let (code, body) = post(web, "GetCampaign", serde_json::json!({ "id": id }));
            assert_eq!(code, 200, "{body}");
            state = serde_json::from_str(&body).unwrap();
            state["phase"] == pb::CampaignPhase::Finished.as_str_name()
        },
    );
    let result: serde_json::Value =
        serde_json::from_str(state["result_json"].as_str().unwrap()).unwrap();
    assert_eq!(result["best"], done["best"]);
    assert_eq!(result["simulated"], 0, "replayed from the store");
    runtime.block_on(ui.shutdown());
}

/// Submit `text` on dataset `dataset` over HTTP and wait until the campaign ends: its id.
fn run_campaign(c: &Coordinator, text: &str, dataset: &str) -> String {
    let campaign = calib_service::api::spec::campaign_message(text, dataset).unwrap();
    let (code, body) = post(
        c.http(),
        "SubmitCampaign",
        serde_json::to_value(pb::SubmitCampaignRequest {
            campaign: Some(campaign),
            idempotency_key: String::new(),
        })
        .unwrap(),
    );
    assert_eq!(code, 200, "{body}");
    let id = serde_json::from_str::<pb::SubmitCampaignResponse>(&body)
        .unwrap()
        .id;
    let (code, body) = http(c.http(), "GET", &format!("/api/v1/WatchCampaign/{id}"), b"");
    assert_eq!(code, 200);
    let last = body
        .lines()
        .filter_map(|l| l.strip_prefix("data: "))
        .next_back()
        .unwrap();
    // Read as a JSON client reads it: a run's best before its first point is `null` (+inf),
    // which the proto types cannot hold.
    let state: serde_json::Value = serde_json::from_str(last).unwrap();
    assert_eq!(
        state["phase"],
        pb::CampaignPhase::Finished.as_str_name(),
        "{state}"
    );
    id
}

#[test]
fn two_campaigns_fits_are_drawn_over_the_measured_data_once() {
    use calib_analysis::report::chart::anatomy;
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 2);
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let web = c.http();
    let bytes = std::fs::read(repo().join("examples/data/furuta_clean.csv")).unwrap();
    let (code, body) = http(
        web,
        "POST",
        "/api/v1/UploadDataset?file_name=record.csv&time_column=time_s",
        &bytes,
    );
    assert_eq!(code, 200, "{body}");
    let dataset: pb::Dataset = serde_json::from_str(&body).unwrap();
    // A short search and a longer one, both called "clean".
    let short = run_campaign(
        &c,
        &clean_campaign("methods = [\"powell\"]\nstarts = 1\nmax_evaluations = 12\nseed = 3"),
        &dataset.id,
    );
    let long = run_campaign(
        &c,
        &clean_campaign("methods = [\"nelder-mead\"]\nstarts = 2\nmax_evaluations = 80\nseed = 3"),
        &dataset.id,
    );

    let request = serde_json::json!({"campaigns": [short, long], "output": "armJoint.phi"});
    let (code, svg) = http(
        web,
        "POST",
        "/ui/compare",
        &serde_json::to_vec(&request).unwrap(),
    );
    assert_eq!(code, 200, "{svg}");
    let a = anatomy(&svg);
    assert!(a.faults().is_empty(), "{:?}", a.faults());
    // The measured data once, each campaign's fit labelled by its name (the second one's
    // id added, the names being equal), the output's unit on the axis.
    assert_eq!(svg.matches(">measured</text>").count(), 1, "{svg}");
    assert!(svg.contains("clean: objective"), "{svg}");
    assert!(
        svg.contains(&format!("clean ({}): objective", &long[..8])),
        "{svg}"
    );
    assert!(svg.contains("armJoint.phi [rad]"), "{svg}");

    // Refusals name the field.
    for (request, field) in [
        (
            serde_json::json!({"campaigns": [short], "output": "armJoint.phi"}),
            "campaigns:",
        ),
        (
            serde_json::json!({"campaigns": [short, long], "output": "nowhere"}),
            "output:",
        ),
    ] {
        let (code, body) = http(
            web,
            "POST",
            "/ui/compare",
            &serde_json::to_vec(&request).unwrap(),
        );
        assert_eq!(code, 400, "{body}");
        let error: serde_json::Value = serde_json::from_str(&body).unwrap();
        assert!(
            error["message"].as_str().unwrap().starts_with(field),
            "{body}"
        );
    }
    let (code, _) = http(
        web,
        "POST",
        "/ui/compare",
        &serde_json::to_vec(
            &serde_json::json!({"campaigns": [short, "b".repeat(64)], "output": "armJoint.phi"}),
        )
        .unwrap(),
    );
    assert_eq!(code, 404);

    // The waterfall the campaign left names each run by method and start.
    let (_, body) = post(web, "GetCampaign", serde_json::json!({"id": long}));
    let state: serde_json::Value = serde_json::from_str(&body).unwrap();
    let waterfall = anatomy(state["plots"]["waterfall.svg"].as_str().unwrap());
    let mut runs = waterfall.x_ticks.clone();
    runs.sort();
    assert_eq!(runs, ["nelder-mead #0", "nelder-mead #1"]);
}
