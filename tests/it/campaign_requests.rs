//! What a coordinator refuses at its doors (gRPC, the web app's JSON, the campaign file of
//! `calib calibrate`): searches that would size more memory than it holds, names that would
//! put results outside `--out`, windows past the data and columns the data lacks. Each is
//! refused when submitted, naming the request's field and the limit, never a path of the
//! server's, and the coordinator keeps serving; a stored campaign it can no longer run is
//! closed as failed when it restarts, and a cancelled campaign can be submitted again.

use crate::common::cluster::*;
use crate::common::*;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_client::CalibrationClient;
use calib_service::server::{serve_coordinator, CoordinatorConfig, RunningCoordinator};
use std::io::{Read, Write};
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A coordinator on a store with the web app, in this process.
struct Coordinator {
    runtime: tokio::runtime::Runtime,
    server: Option<RunningCoordinator>,
    /// The folder of its store and API files: no refusal may name it.
    dir: PathBuf,
}

impl Coordinator {
    fn start(dir: &Path, workers: &[String]) -> Self {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let mut config = CoordinatorConfig::new(
            "127.0.0.1:0".parse().unwrap(),
            calib_sandbox::cluster::dispatch_config(workers),
        );
        config.store = Some(dir.join("db"));
        config.api = Some(dir.join("api"));
        config.http = Some("127.0.0.1:0".parse().unwrap());
        let server = runtime.block_on(async {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            serve_coordinator(listener, config).unwrap()
        });
        Self {
            runtime,
            server: Some(server),
            dir: std::fs::canonicalize(dir).unwrap(),
        }
    }

    fn server(&self) -> &RunningCoordinator {
        self.server.as_ref().unwrap()
    }

    fn grpc<T>(
        &self,
        call: impl AsyncFnOnce(
            CalibrationClient<tonic::transport::Channel>,
        ) -> Result<tonic::Response<T>, tonic::Status>,
    ) -> Result<T, tonic::Status> {
        let url = format!("http://{}", self.server().address());
        self.runtime.block_on(async {
            let client = CalibrationClient::connect(url).await.unwrap();
            call(client).await.map(tonic::Response::into_inner)
        })
    }

    fn upload(&self) -> pb::Dataset {
        let chunk = pb::DatasetChunk {
            file_name: "record.csv".into(),
            time_column: "time_s".into(),
            data: std::fs::read(repo().join("examples/data/furuta_clean.csv")).unwrap(),
        };
        self.grpc(async move |mut c| c.upload_dataset(tokio_stream::iter([chunk])).await)
            .unwrap()
    }

    fn submit(&self, campaign: pb::Campaign) -> Result<pb::SubmitCampaignResponse, tonic::Status> {
        let request = pb::SubmitCampaignRequest {
            campaign: Some(campaign),
            idempotency_key: String::new(),
        };
        self.grpc(async move |mut c| c.submit_campaign(request).await)
    }

    /// `SubmitCampaign` over the web app's JSON route: the status code and the body.
    fn submit_json(&self, campaign: pb::Campaign) -> (u16, String) {
        let body = serde_json::to_vec(&pb::SubmitCampaignRequest {
            campaign: Some(campaign),
            idempotency_key: String::new(),
        })
        .unwrap();
        http_post(
            self.server().http_address().expect("--http"),
            "/api/v1/SubmitCampaign",
            &body,
        )
    }

    fn validate(&self, campaign: pb::Campaign) -> Vec<pb::CampaignProblem> {
        let request = pb::ValidateCampaignRequest {
            campaign: Some(campaign),
        };
        self.grpc(async move |mut c| c.validate_campaign(request).await)
            .unwrap()
            .problems
    }

    fn state(&self, id: &str) -> pb::CampaignState {
        let id = id.to_string();
        self.grpc(async move |mut c| c.get_campaign(pb::GetCampaignRequest { id }).await)
            .unwrap()
    }

    fn listed(&self) -> Vec<pb::CampaignState> {
        self.grpc(async |mut c| c.list_campaigns(pb::ListCampaignsRequest::default()).await)
            .unwrap()
            .campaigns
    }

    /// Submit `campaign` at both doors and expect both refused, each message naming every
    /// fragment and no path of this coordinator's; the coordinator still serving.
    fn expect_refused(&self, campaign: pb::Campaign, fragments: &[&str]) {
        let status = self.submit(campaign.clone()).unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
        let (code, body) = self.submit_json(campaign);
        assert_eq!(code, 400, "{body}");
        for message in [status.message(), &body] {
            for f in fragments {
                assert!(message.contains(f), "`{f}` missing from: {message}");
            }
            self.assert_no_path(message);
            assert!(message.len() < 4096, "{} bytes of refusal", message.len());
        }
        assert!(self.listed().is_empty(), "a refused campaign was started");
    }

    fn assert_no_path(&self, message: &str) {
        let dir = self.dir.display().to_string();
        assert!(!message.contains(&dir), "the server's folder in: {message}");
        for internal in ["submitted-campaign.toml", "datasets/", "calib-api"] {
            assert!(!message.contains(internal), "`{internal}` in: {message}");
        }
    }
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        if let Some(server) = self.server.take() {
            self.runtime.block_on(server.shutdown());
        }
    }
}

/// One HTTP/1.1 POST from the page's own origin: the status code and the body.
fn http_post(address: SocketAddr, path: &str, body: &[u8]) -> (u16, String) {
    let mut stream = std::net::TcpStream::connect(address).unwrap();
    write!(
        stream,
        "POST {path} HTTP/1.1\r\nHost: {address}\r\nOrigin: http://{address}\r\n\
         Connection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n",
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

const SEARCH: &str = "methods = [\"nelder-mead\"]\nmax_evaluations = 40";

fn message(search: &str, dataset: &str) -> pb::Campaign {
    calib_service::api::spec::campaign_message(&clean_campaign(search), dataset).unwrap()
}

/// The clean campaign file with `search`, after one replacement.
fn campaign_file(dir: &Path, search: &str, from: &str, to: &str) -> PathBuf {
    let text = clean_campaign(search);
    let changed = text.replacen(from, to, 1);
    assert_ne!(changed, text, "`{from}` not in the campaign");
    write(dir, "c.toml", &changed)
}

/// `calib calibrate` on `campaign`: expect exit code 2 and every fragment on stderr.
fn expect_bad_input(campaign: &Path, out: &Path, fragments: &[&str]) {
    let result = calib(&[
        "calibrate",
        campaign.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(2), "stderr: {stderr}");
    for f in fragments {
        assert!(stderr.contains(f), "`{f}` missing from: {stderr}");
    }
}

#[test]
fn searches_beyond_the_limits_are_refused_naming_the_field_and_the_coordinator_keeps_serving() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), &[]);
    let dataset = c.upload();
    let search = |s: &str| message(&format!("{SEARCH}\n{s}"), &dataset.id);
    c.expect_refused(
        message(
            "methods = [\"nelder-mead\"]\nstarts = 1000000000",
            &dataset.id,
        ),
        &["campaign.search.starts", "1000000000", "1000 starts"],
    );
    c.expect_refused(
        search("screening = 1000000000000"),
        &["campaign.search.screening", "65535"],
    );
    c.expect_refused(
        message(
            "methods = [\"nelder-mead\"]\nmax_evaluations = 1000000000000",
            &dataset.id,
        ),
        &["campaign.search.max_evaluations", "1000000"],
    );
    let mut many = search("");
    many.parameters = vec![many.parameters[0].clone(); 65];
    c.expect_refused(many, &["campaign.parameters", "64"]);
    let mut many = search("");
    many.outputs = vec![many.outputs[0].clone(); 33];
    c.expect_refused(many, &["campaign.outputs", "32"]);
    let mut refits = search("");
    refits.diagnosis = Some(pb::DiagnosisSettings {
        refit: Some(1 << 40),
        ..Default::default()
    });
    c.expect_refused(refits, &["campaign.diagnosis.refit", "10"]);

    // Analyses: samples and profile steps.
    let campaign = search("");
    let status = c
        .grpc(async move |mut client| {
            client
                .sensitivity(pb::SensitivityRequest {
                    campaign: Some(campaign),
                    samples: u32::MAX as _,
                    ..Default::default()
                })
                .await
        })
        .expect_err("refused");
    assert!(status.message().starts_with("samples"), "{status:?}");
    let status = c
        .grpc(async |mut client| {
            client
                .profile(pb::ProfileRequest {
                    id: "0".repeat(64),
                    max_steps: u32::MAX as _,
                    ..Default::default()
                })
                .await
        })
        .expect_err("refused");
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    assert!(status.message().starts_with("max_steps"), "{status:?}");

    // A key the coordinator would keep for as long as it runs.
    let request = pb::SubmitCampaignRequest {
        campaign: Some(search("")),
        idempotency_key: "k".repeat(1 << 20),
    };
    let status = c
        .grpc(async move |mut client| client.submit_campaign(request).await)
        .expect_err("refused");
    assert!(
        status
            .message()
            .starts_with("idempotency_key: 1048576 bytes"),
        "{status:?}"
    );

    // Still serving: the data is there, nothing was started.
    assert!(c.listed().is_empty());
    assert_eq!(c.upload(), dataset);
}

#[test]
fn calib_calibrate_refuses_a_search_beyond_the_limits_with_exit_code_2() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    for (from, to, field) in [
        (
            "max_evaluations = 40",
            "starts = 1000000000",
            "search.starts",
        ),
        (
            "max_evaluations = 40",
            "max_evaluations = 40\nscreening = 1000000000000",
            "search.screening",
        ),
    ] {
        let c = campaign_file(dir.path(), SEARCH, from, to);
        expect_bad_input(&c, &out, &["c.toml", field, "more than the"]);
    }
    assert!(!out.exists(), "a refused campaign wrote results");
}

#[test]
fn calib_sensitivity_and_calib_profile_refuse_counts_beyond_their_limits() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = write(dir.path(), "c.toml", &clean_campaign(SEARCH));
    let campaign = campaign.to_str().unwrap();
    let out = dir.path().join("out");
    let out = out.to_str().unwrap();
    for (args, field) in [
        (
            vec![
                "sensitivity",
                campaign,
                "--samples",
                "1000000000",
                "--out",
                out,
            ],
            "samples: 1000000000 is not between 2 and 4096",
        ),
        (
            vec![
                "profile",
                campaign,
                "--max-steps",
                "1000000000",
                "--out",
                out,
            ],
            "max_steps: 1000000000 is not between 1 and 1000",
        ),
    ] {
        let result = calib(&args);
        let stderr = String::from_utf8_lossy(&result.stderr);
        assert_eq!(result.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(stderr.contains(field), "{args:?}: {stderr}");
    }
}

#[test]
fn campaign_names_that_leave_the_results_folder_are_refused_at_every_door() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), &[]);
    let dataset = c.upload();
    let long = "n".repeat(1_000_000);
    for name in [
        "../../x",
        "/tmp/x",
        "a/b",
        "..",
        ".calib-db",
        "tab\tname",
        &long,
    ] {
        let mut campaign = message(SEARCH, &dataset.id);
        campaign.name = name.to_string();
        c.expect_refused(campaign, &["campaign.name"]);
    }

    // The campaign file of `calib calibrate`: nothing written outside --out (or inside).
    let files = dir.path().join("files");
    let out = files.join("a").join("b").join("out");
    std::fs::create_dir_all(&files).unwrap();
    for name in ["../../x", "/tmp/calib-escape-x", &long] {
        let campaign = campaign_file(
            &files,
            SEARCH,
            "name = \"clean\"",
            &format!("name = \"{name}\""),
        );
        expect_bad_input(&campaign, &out, &["c.toml", "`name`"]);
    }
    assert!(!files.join("a").join("x").exists());
    assert!(!out.exists());
}

#[test]
fn a_window_past_the_data_and_a_column_it_lacks_are_refused_at_submit_naming_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), &[]);
    let dataset = c.upload();
    assert_eq!((dataset.start_time, dataset.stop_time), (0.0, 40.0));

    let mut late = message(SEARCH, &dataset.id);
    late.window_stop = 50.0;
    c.expect_refused(
        late,
        &["campaign.window_stop", "50", "time runs from 0 to 40 s"],
    );
    let mut early = message(SEARCH, &dataset.id);
    early.window_start = -5.0;
    c.expect_refused(early, &["campaign.window_start", "-5"]);

    let mut missing = message(SEARCH, &dataset.id);
    missing.outputs[1].measured = "no_such_column".into();
    c.expect_refused(
        missing,
        &[
            "campaign.outputs[1].measured",
            "no_such_column",
            "arm_angle_rad",
        ],
    );

    // A window of one sample: refused when submitted, not once running.
    let mut short = message(SEARCH, &dataset.id);
    (short.window_start, short.window_stop) = (10.0, 10.001);
    c.expect_refused(short, &["campaign.window", "too few"]);
}

#[test]
fn a_cancelled_campaign_can_be_submitted_again() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 1);
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let dataset = c.upload();
    let search = "methods = [\"differential-evolution\"]\nstarts = 2\nmax_evaluations = 100000";
    let campaign = message(search, &dataset.id);
    let first = c.submit(campaign.clone()).unwrap();
    assert!(first.started);
    let cancel = |id: &str| {
        let id = id.to_string();
        c.grpc(async move |mut client| {
            client
                .cancel_campaign(pb::CancelCampaignRequest { id })
                .await
        })
        .unwrap();
        await_condition("the campaign cancelled", Duration::from_secs(60), || {
            c.state(&first.id).phase() == pb::CampaignPhase::Cancelled
        });
    };
    await_condition("the campaign evaluating", Duration::from_secs(60), || {
        c.state(&first.id).evaluations > 0
    });
    cancel(&first.id);

    let again = c.submit(campaign.clone()).unwrap();
    assert_eq!(again.id, first.id, "the same campaign, the same id");
    assert!(again.started, "a cancelled campaign was not started again");
    assert_eq!(c.state(&again.id).phase(), pb::CampaignPhase::Running);
    // Submitted once more while it runs: the running campaign is the answer.
    assert!(!c.submit(campaign).unwrap().started);
    cancel(&again.id);
}

#[test]
fn a_stored_campaign_beyond_the_limits_is_closed_as_failed_when_the_coordinator_restarts() {
    use calib_engine::store::{CampaignRecord, CampaignStatus, SledStore, Store};
    let dir = tempfile::tempdir().unwrap();
    // As an earlier coordinator, with no limit on starts, left it: running.
    let text = clean_campaign("methods = [\"nelder-mead\"]\nstarts = 1000000000");
    let source = write(dir.path(), "huge.toml", &text);
    let id = [7u8; 32];
    {
        let store = SledStore::open(&dir.path().join("db")).unwrap();
        let record = CampaignRecord {
            name: "clean".into(),
            spec: text,
            source,
            dataset: "00".repeat(32),
            status: CampaignStatus::Running,
            runs: Vec::new(),
            result: None,
            failure: None,
            message: None,
            free: Vec::new(),
            history: Vec::new(),
        };
        store.put_campaign(&id, &record).unwrap();
    }
    let cluster = TestCluster::start(1, 1);
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let hex = calib_engine::store::hex(&id);
    await_condition("the campaign closed", Duration::from_secs(60), || {
        c.state(&hex).phase() == pb::CampaignPhase::Failed
    });
    let failure = c.state(&hex).failure;
    assert!(failure.contains("search.starts"), "{failure}");
    // Serving, and it stays closed.
    assert_eq!(c.listed().len(), 1);
    assert_eq!(c.upload().columns.len(), 2);
    drop(c);
    let c = Coordinator::start(dir.path(), &cluster.urls());
    assert_eq!(c.state(&hex).phase(), pb::CampaignPhase::Failed);
}

/// Whether a problem's message speaks to someone filling in a form: no campaign file's words.
fn in_plain_words(message: &str) -> bool {
    !["[[", "entry", ".toml", "[model", "[search"]
        .iter()
        .any(|toml| message.contains(toml))
}

#[test]
fn validate_campaign_names_the_field_of_each_problem_and_submit_refuses_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), &[]);
    let dataset = c.upload();
    let good = message(SEARCH, &dataset.id);
    assert_eq!(
        c.validate(good.clone()),
        [],
        "a good campaign has no problem"
    );

    type Change = fn(&mut pb::Campaign);
    let cases: [(Change, &str, &str); 13] = [
        (
            |m| m.search.as_mut().unwrap().methods.clear(),
            "search.methods",
            "choose at least one method",
        ),
        (
            |m| m.window_stop = 50.0,
            "window_stop",
            "time runs from 0 to 40 s",
        ),
        (|m| m.window_start = -5.0, "window_start", "-5"),
        (
            |m| (m.window_start, m.window_stop) = (30.0, 20.0),
            "window_stop",
            "end after it starts",
        ),
        (
            |m| m.outputs[1].measured = "no_such_column".into(),
            "outputs[1].measured",
            "arm_angle_rad",
        ),
        (
            |m| m.outputs[0].measured.clear(),
            "outputs[0].measured",
            "choose the measured column",
        ),
        (
            |m| m.outputs.clear(),
            "outputs",
            "choose at least one output to compare",
        ),
        (
            |m| m.parameters[0].max = -1.0,
            "parameters[0].max",
            "above the lower bound 0",
        ),
        (
            |m| m.parameters[1].nominal = Some(2.0),
            "parameters[1].nominal",
            "outside the bounds [0, 0.9]",
        ),
        // Found by the campaign's loader, past the form's checks: the field without the
        // parameter's name, the message without the file's words.
        (
            |m| m.parameters[1].name = "no_such_parameter".into(),
            "parameters[1]",
            "no_such_parameter",
        ),
        (
            |m| (m.window_start, m.window_stop) = (10.0, 10.001),
            "window_stop",
            "too few",
        ),
        (
            |m| m.dataset_id = "0".repeat(64),
            "dataset_id",
            "upload the measurement again",
        ),
        // An effect defined by a formula is named in the message's own list.
        (
            |m| {
                m.defined_effects.push(pb::DefinedEffect {
                    name: "cogging.arm".into(),
                    torque: "armJoint".into(),
                    formula: "a * sin(8 * armJoint.ph)".into(),
                    parameters: vec![pb::DefinedEffectParameter {
                        name: "a".into(),
                        min: -0.02,
                        max: 0.02,
                        ..Default::default()
                    }],
                    ..Default::default()
                })
            },
            "defined_effects[0].formula",
            "armJoint.phi",
        ),
    ];
    for (change, field, fragment) in cases {
        let mut campaign = good.clone();
        change(&mut campaign);
        let problems = c.validate(campaign.clone());
        let [problem] = &problems[..] else {
            panic!("{field}: one problem expected, got {problems:?}");
        };
        assert_eq!(problem.field, field, "{problem:?}");
        assert!(problem.message.contains(fragment), "{problem:?}");
        assert!(in_plain_words(&problem.message), "{problem:?}");
        c.assert_no_path(&problem.message);
        // SubmitCampaign refuses it with the same problem, at both doors.
        // (A refusal of the campaign's loader names the parameter after its index too, and
        // a window by both its ends.)
        let status = c.submit(campaign.clone()).unwrap_err();
        let refused = status.message();
        let (named, _) = refused.split_once(": ").unwrap();
        assert!(
            named.contains(&problem.field),
            "{refused} is not {problem:?}"
        );
        assert!(!problem.message.contains(&dataset.id), "{problem:?}");
        let expected = if field == "dataset_id" {
            (tonic::Code::NotFound, 404)
        } else {
            (tonic::Code::InvalidArgument, 400)
        };
        assert_eq!(status.code(), expected.0, "{status:?}");
        let (code, body) = c.submit_json(campaign);
        assert_eq!(code, expected.1, "{body}");
        assert!(body.contains(&problem.field), "{body}");
    }

    // Several problems at once: each at its field, in the form's order.
    let mut many = good.clone();
    many.search.as_mut().unwrap().methods.clear();
    many.outputs[1].measured = "no_such_column".into();
    many.window_stop = 50.0;
    many.parameters[0].max = -1.0;
    let fields: Vec<String> = c
        .validate(many.clone())
        .into_iter()
        .map(|p| p.field)
        .collect();
    assert_eq!(
        fields,
        [
            "search.methods",
            "parameters[0].max",
            "outputs[1].measured",
            "window_stop"
        ]
    );
    let status = c.submit(many.clone()).unwrap_err();
    assert!(
        status.message().starts_with("campaign.search.methods: "),
        "{status:?}"
    );

    // The web app's route answers the same problems as JSON.
    let body = serde_json::to_vec(&pb::ValidateCampaignRequest {
        campaign: Some(many),
    })
    .unwrap();
    let (code, body) = http_post(
        c.server().http_address().expect("--http"),
        "/api/v1/ValidateCampaign",
        &body,
    );
    assert_eq!(code, 200, "{body}");
    let answer: serde_json::Value = serde_json::from_str(&body).unwrap();
    let problems = answer["problems"].as_array().unwrap();
    assert_eq!(problems.len(), 4, "{body}");
    assert_eq!(problems[0]["field"], "search.methods", "{body}");
    assert_eq!(
        problems[0]["message"], "choose at least one method",
        "{body}"
    );
    assert!(c.listed().is_empty(), "nothing was started");

    // A campaign without `search` takes the default method, as a campaign file does; the
    // good campaign is started.
    let mut defaults = good.clone();
    defaults.search = None;
    assert_eq!(c.validate(defaults), []);
    assert!(c.submit(good).unwrap().started);
}

#[test]
fn an_upload_without_a_time_column_gets_the_guessed_one() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), &[]);
    let data = std::fs::read(repo().join("examples/data/furuta_clean.csv")).unwrap();
    let upload = |time_column: &str| {
        let chunk = pb::DatasetChunk {
            file_name: "record.csv".into(),
            time_column: time_column.into(),
            data: data.clone(),
        };
        c.grpc(async move |mut c| c.upload_dataset(tokio_stream::iter([chunk])).await)
    };
    let guessed = upload("").unwrap();
    assert_eq!(guessed.time_column, "time_s");
    assert!(guessed.time_column_guessed);
    let named = upload("time_s").unwrap();
    assert!(!named.time_column_guessed);
    // The same dataset as the upload that names the column.
    assert_eq!(
        (&guessed.id, &guessed.columns, guessed.stop_time),
        (&named.id, &named.columns, named.stop_time)
    );
    assert!(!guessed.columns.contains(&"time_s".to_string()));
    // A column that is not a time axis is refused, naming it.
    let status = upload("arm_angle_rad").unwrap_err();
    assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
    c.assert_no_path(status.message());
}

/// 2,000 nested parentheses around a joint's speed (4 KB): the formula that overflowed the
/// stack of whatever parsed it.
fn nested_formula(depth: usize) -> String {
    format!("-b * {}armJoint.w{}", "(".repeat(depth), ")".repeat(depth))
}

fn deep_effect(formula: &str) -> pb::DefinedEffect {
    pb::DefinedEffect {
        name: "damping.arm".into(),
        torque: "armJoint".into(),
        formula: formula.into(),
        parameters: vec![pb::DefinedEffectParameter {
            name: "b".into(),
            nominal: Some(0.001),
            min: 0.0,
            max: 1.0,
            fixed: false,
        }],
        ..Default::default()
    }
}

#[test]
fn formulas_too_deep_or_too_long_are_refused_at_every_door_and_nothing_overflows() {
    let dir = tempfile::tempdir().unwrap();
    let cluster = TestCluster::start(1, 1);
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let dataset = c.upload();
    let deep = nested_formula(2_000);
    assert!(deep.len() > 4_000);
    let long = format!("b{}", " + b".repeat(35_000));
    let with = |formula: &str| {
        let mut campaign = message(SEARCH, &dataset.id);
        campaign.defined_effects = vec![deep_effect(formula)];
        campaign
    };

    // The coordinator's gRPC and JSON doors: a problem naming the field, then a refusal.
    for (formula, says) in [
        (&deep, "nests more than 200 levels"),
        (&long, "more than 10000"),
    ] {
        let problems = c.validate(with(formula));
        assert_eq!(problems.len(), 1, "{problems:?}");
        assert_eq!(
            problems[0].field, "defined_effects[0].formula",
            "{problems:?}"
        );
        assert!(problems[0].message.contains(says), "{problems:?}");
        let body = serde_json::to_vec(&pb::ValidateCampaignRequest {
            campaign: Some(with(formula)),
        })
        .unwrap();
        let http = c.server().http_address().unwrap();
        let (code, body) = http_post(http, "/api/v1/ValidateCampaign", &body);
        assert_eq!(code, 200, "{body}");
        assert!(
            body.contains("defined_effects[0].formula") && body.contains(says),
            "{body}"
        );
        c.expect_refused(with(formula), &["defined_effects[0].formula", says]);
    }

    // `calib ui`'s route, on campaigns of its own process.
    let ui_runtime = tokio::runtime::Runtime::new().unwrap();
    let ui = ui_runtime
        .block_on(calib_service::web::local::start_ui(
            calib_service::web::local::UiConfig {
                listen: "127.0.0.1:0".parse().unwrap(),
                store: dir.path().join("ui-db"),
                api: Some(dir.path().join("ui-api")),
                allow_hosts: Vec::new(),
            },
        ))
        .unwrap();
    let csv = std::fs::read(repo().join("examples/data/furuta_clean.csv")).unwrap();
    let upload = "/api/v1/UploadDataset?file_name=record.csv&time_column=time_s";
    let (code, body) = http_post(ui.address(), upload, &csv);
    assert!(code == 200 && body.contains(&dataset.id), "{body}");
    let body = serde_json::to_vec(&pb::ValidateCampaignRequest {
        campaign: Some(with(&deep)),
    })
    .unwrap();
    let (code, body) = http_post(ui.address(), "/api/v1/ValidateCampaign", &body);
    assert_eq!(code, 200, "{body}");
    assert!(body.contains("defined_effects[0].formula"), "{body}");
    ui_runtime.block_on(ui.shutdown());

    // A worker's Simulate: refused naming the field; the worker serves on.
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let worker = cluster.urls()[0].clone();
    let simulate = |formula: &str| {
        use calib_proto::v1::simulator_client::SimulatorClient;
        let request = pb_worker_simulate(formula);
        let worker = worker.clone();
        runtime.block_on(async move {
            let mut client = SimulatorClient::connect(worker).await.unwrap();
            client
                .simulate(request)
                .await
                .map(tonic::Response::into_inner)
        })
    };
    for formula in [&deep, &long] {
        let status = simulate(formula).unwrap_err();
        assert_eq!(status.code(), tonic::Code::InvalidArgument, "{status:?}");
        assert!(
            status.message().contains("effects[0].formula"),
            "{status:?}"
        );
    }
    let served = simulate("-b * armJoint.w").unwrap();
    assert_eq!(served.series.len(), 1);
    assert!(served.failure.is_none());

    // `calib calibrate`, at a depth its main thread's larger stack once accepted.
    let out = dir.path().join("out");
    let effect = format!(
        "[[effects]]\nname = \"damping.arm\"\ntorque = \"armJoint\"\nformula = \"{}\"\n\
         parameters = [ {{ name = \"b\", nominal = 0.001, min = 0.0, max = 1.0 }} ]\n[window]",
        nested_formula(3_000)
    );
    let file = campaign_file(dir.path(), SEARCH, "[window]", &effect);
    expect_bad_input(
        &file,
        &out,
        &["c.toml", "effects[0].formula", "nests more than"],
    );
    assert!(c.listed().is_empty());
    assert_eq!(c.upload(), dataset);
}

/// A Simulate request of the Furuta arm with a damping formula on it.
fn pb_worker_simulate(formula: &str) -> calib_proto::v1::SimulateRequest {
    use calib_proto::v1 as w;
    w::SimulateRequest {
        protocol_version: calib_proto::PROTOCOL_VERSION,
        model: "furuta".into(),
        parameters: vec![w::ParameterValue {
            name: "damping.arm.b".into(),
            value: 0.01,
        }],
        times: (0..=100).map(|i| i as f64 * 0.01).collect(),
        outputs: vec!["armJoint.phi".into()],
        effects: vec![w::UserEffect {
            name: "damping.arm".into(),
            torque: "armJoint".into(),
            output: String::new(),
            formula: formula.into(),
            parameters: vec![w::UserEffectParameter {
                name: "b".into(),
                nominal: 0.0,
                min: 0.0,
                max: 1.0,
            }],
        }],
        ..Default::default()
    }
}

#[test]
fn a_stored_campaign_with_a_formula_too_deep_is_closed_as_failed_at_restart() {
    use calib_engine::store::{CampaignRecord, CampaignStatus, SledStore, Store};
    let dir = tempfile::tempdir().unwrap();
    // As a coordinator without the limit left it: running, with a 4 KB formula.
    let effect = format!(
        "[[effects]]\nname = \"damping.arm\"\ntorque = \"armJoint\"\nformula = \"{}\"\n\
         parameters = [ {{ name = \"b\", nominal = 0.001, min = 0.0, max = 1.0 }} ]\n[window]",
        nested_formula(2_000)
    );
    let text = clean_campaign(SEARCH).replacen("[window]", &effect, 1);
    let source = write(dir.path(), "deep.toml", &text);
    let id = [9u8; 32];
    {
        let store = SledStore::open(&dir.path().join("db")).unwrap();
        let record = CampaignRecord {
            name: "clean".into(),
            spec: text,
            source,
            dataset: "00".repeat(32),
            status: CampaignStatus::Running,
            runs: Vec::new(),
            result: None,
            failure: None,
            message: None,
            free: Vec::new(),
            history: Vec::new(),
        };
        store.put_campaign(&id, &record).unwrap();
    }
    let cluster = TestCluster::start(1, 1);
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let hex = calib_engine::store::hex(&id);
    await_condition("the campaign closed", Duration::from_secs(60), || {
        c.state(&hex).phase() == pb::CampaignPhase::Failed
    });
    let failure = c.state(&hex).failure;
    assert!(failure.contains("effects[0].formula"), "{failure}");
    assert!(failure.contains("nests more than"), "{failure}");
    assert_eq!(c.upload().columns.len(), 2, "still serving");
}

/// A driven record of 3.2 million rows (51 MB): its input alone, times and torques, is
/// 6.4 million numbers, more than one request to a worker carries.
fn oversized_driven_record(dir: &Path) -> PathBuf {
    use std::io::BufWriter;
    let path = dir.join("long.csv");
    let mut out = BufWriter::new(std::fs::File::create(&path).unwrap());
    writeln!(
        out,
        "time_s,arm_angle_rad,pendulum_angle_rad,motor_torque_Nm"
    )
    .unwrap();
    for i in 0..3_200_000u32 {
        writeln!(out, "{:.5},0,0.5,0", f64::from(i) * 1e-5).unwrap();
    }
    out.into_inner().unwrap();
    path
}

#[test]
fn a_record_larger_than_a_workers_request_is_refused_at_every_door_naming_the_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let csv = oversized_driven_record(dir.path());
    let text = driven_friction_campaign("long", &csv, SEARCH).replace("stop = 20.0", "stop = 1.0");
    let file = write(dir.path(), "c.toml", &text);
    let out = dir.path().join("out");
    let says = [
        "inputs",
        "6700003 numbers",
        "more than the 6291456 one request",
    ];

    // `calib calibrate`, locally and on workers: refused alike, before anything runs.
    let cluster = TestCluster::start(1, 1);
    let workers = cluster.urls().join(",");
    for extra in [vec![], vec!["--workers", workers.as_str()]] {
        let mut args = vec![
            "calibrate",
            file.to_str().unwrap(),
            "--out",
            out.to_str().unwrap(),
        ];
        args.extend(&extra);
        let run = calib(&args);
        let stderr = String::from_utf8_lossy(&run.stderr);
        assert_eq!(run.status.code(), Some(2), "{stderr}");
        for s in says {
            assert!(stderr.contains(s), "`{s}` missing from: {stderr}");
        }
    }
    assert!(!out.exists());

    // Submitted: refused naming the field, not left waiting for workers.
    let c = Coordinator::start(dir.path(), &cluster.urls());
    let data = std::fs::read(&csv).unwrap();
    let chunks: Vec<pb::DatasetChunk> = data
        .chunks(1 << 20)
        .enumerate()
        .map(|(i, part)| pb::DatasetChunk {
            file_name: if i == 0 {
                "long.csv".into()
            } else {
                String::new()
            },
            time_column: if i == 0 {
                "time_s".into()
            } else {
                String::new()
            },
            data: part.to_vec(),
        })
        .collect();
    let dataset = c
        .grpc(async move |mut client| client.upload_dataset(tokio_stream::iter(chunks)).await)
        .unwrap();
    let campaign = calib_service::api::spec::campaign_message(&text, &dataset.id).unwrap();
    c.expect_refused(campaign, &["campaign.inputs", "more than the 6291456"]);
}

/// The anonymous memory of process `pid` (its heaps, maps and stacks; not the pages of its
/// binary, which vary with the code a run touched) [bytes].
fn anonymous(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/smaps_rollup")).unwrap();
    let line = status
        .lines()
        .find(|l| l.starts_with("Anonymous:"))
        .unwrap();
    line.split_whitespace()
        .nth(1)
        .unwrap()
        .parse::<u64>()
        .unwrap()
        * 1024
}

/// A coordinator that ran a campaign on a record near the largest it takes (2.9 million rows,
/// 93 MB as columns) holds less than a tenth of that record more than before, once the
/// campaign has ended: neither its store's cache, nor the record in the form workers take
/// it, nor freed heap is kept (it kept 230–370 MB; then, with freed heap trimmed, 23–80 MB
/// more, as glibc served large blocks from its heaps after the first was freed).
#[test]
fn a_coordinator_gives_back_the_memory_of_a_large_campaign_once_it_ends() {
    let dir = tempfile::tempdir().unwrap();
    let full = oversized_driven_record(dir.path());
    let text = std::fs::read_to_string(&full).unwrap();
    let rows: String = text
        .lines()
        .take(2_900_001)
        .flat_map(|l| [l, "\n"])
        .collect();
    let csv = write(dir.path(), "near.csv", &rows);
    let search = "methods = [\"nelder-mead\"]\nmax_evaluations = 12";
    let campaign =
        driven_friction_campaign("near", &csv, search).replace("stop = 20.0", "stop = 1.0");
    let campaign = write(dir.path(), "near.toml", &campaign);
    let db = dir.path().join("db");
    let (mut coordinator, address) = spawn_server(
        &[
            "coordinator",
            "--listen",
            "127.0.0.1:0",
            "--db",
            db.to_str().unwrap(),
        ],
        "coordinator listening on ",
        &dir.path().join("coordinator.log"),
    );
    let url = format!("http://{address}");
    let (mut worker, _) = spawn_server(
        &[
            "worker",
            "--listen",
            "127.0.0.1:0",
            "--slots",
            "2",
            "--register",
            &url,
        ],
        "worker listening on ",
        &dir.path().join("worker.log"),
    );
    let out = dir.path().join("out");
    let before = anonymous(coordinator.id());
    let run = calib(&[
        "submit",
        campaign.to_str().unwrap(),
        "--coordinator",
        &url,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let allowed = 2_900_000 * 4 * 8 / 10;
    // The campaign's thread ends just after its result is served: wait for it.
    let mut kept = anonymous(coordinator.id()).saturating_sub(before);
    for _ in 0..100 {
        if kept < allowed {
            break;
        }
        std::thread::sleep(Duration::from_millis(100));
        kept = anonymous(coordinator.id()).saturating_sub(before);
    }
    eprintln!(
        "memory-test: the coordinator keeps {:.1} MB more than before the campaign",
        kept as f64 / 1e6
    );
    for child in [&mut worker, &mut coordinator] {
        child.kill().unwrap();
        child.wait().unwrap();
    }
    assert!(
        kept < allowed,
        "the coordinator keeps {} MB more than before",
        kept >> 20
    );
}

/// A campaign the user cancels ends as cancelled, and the coordinator's log says so without
/// an error (it logged the cancel as ERROR).
#[test]
fn a_cancel_is_logged_as_what_the_user_asked_not_as_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("coordinator.log");
    let db = dir.path().join("db");
    let (mut coordinator, address) = spawn_server(
        &[
            "coordinator",
            "--listen",
            "127.0.0.1:0",
            "--db",
            db.to_str().unwrap(),
        ],
        "coordinator listening on ",
        &log,
    );
    let url = format!("http://{address}");
    let (mut worker, _) = spawn_server(
        &[
            "worker",
            "--listen",
            "127.0.0.1:0",
            "--slots",
            "1",
            "--register",
            &url,
        ],
        "worker listening on ",
        &dir.path().join("worker.log"),
    );
    let search = "methods = [\"differential-evolution\"]\nmax_evaluations = 100000";
    let file = write(dir.path(), "long.toml", &clean_campaign(search));
    let submitted = calib(&[
        "submit",
        file.to_str().unwrap(),
        "--coordinator",
        &url,
        "--detach",
    ]);
    let id = String::from_utf8_lossy(&submitted.stdout)
        .trim()
        .to_string();
    assert!(submitted.status.success() && id.len() == 64, "{id}");
    let status = || {
        std::thread::sleep(Duration::from_millis(200));
        let out = calib(&["status", &id, "--coordinator", &url]);
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    await_condition("the campaign running", Duration::from_secs(60), || {
        status().contains("running")
    });
    assert!(calib(&["cancel", &id, "--coordinator", &url])
        .status
        .success());
    await_condition("the campaign cancelled", Duration::from_secs(60), || {
        status().contains("cancelled")
    });
    for child in [&mut worker, &mut coordinator] {
        child.kill().unwrap();
        child.wait().unwrap();
    }
    let text = std::fs::read_to_string(&log).unwrap();
    assert!(!text.contains("ERROR"), "{text}");
}
