//! Arbitrary bytes and mutated valid requests to every JSON route of the app, through the
//! whole router (its door included): each gets an answer, 2xx or 4xx, never a panic or a
//! server error. The valid requests name no uploaded dataset or campaign, so nothing they
//! mutate into starts a campaign or a long simulation.

use super::door::DoorConfig;
use super::WebApp;
use crate::hosting::datasets::Datasets;
use crate::hosting::Campaigns;
use axum::body::Body;
use axum::http::{Request, StatusCode};
use axum::Router;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::store::MemoryStore;
use proptest::prelude::*;
use std::sync::Arc;
use tower::ServiceExt;

const BOUND: &str = "127.0.0.1:8080";

/// Requests each route accepts, to mutate.
fn valid_requests() -> Vec<(&'static str, String)> {
    let furuta = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/furuta.toml"
    ))
    .expect("examples/furuta.toml");
    let absent = "ab".repeat(32);
    let campaign = crate::api::spec::campaign_message(&furuta, &absent).expect("a campaign");
    let campaign = serde_json::to_value(&campaign).expect("plain data");
    let json = |v: serde_json::Value| v.to_string();
    vec![
        (
            "/api/v1/SubmitCampaign",
            json(serde_json::json!({ "campaign": campaign, "idempotency_key": "k" })),
        ),
        (
            "/api/v1/GetCampaign",
            json(serde_json::json!({ "id": absent })),
        ),
        (
            "/api/v1/ListCampaigns",
            json(serde_json::json!({ "page_token": "", "page_size": 10 })),
        ),
        (
            "/api/v1/CancelCampaign",
            json(serde_json::json!({ "id": absent })),
        ),
        (
            "/api/v1/Sensitivity",
            json(
                serde_json::json!({ "campaign": campaign, "method": "morris", "samples": 4, "seed": 1 }),
            ),
        ),
        (
            "/api/v1/Profile",
            json(serde_json::json!({ "id": absent, "parameters": ["a"], "max_steps": 3 })),
        ),
        ("/api/v1/ListModels", json(serde_json::json!({}))),
        (
            "/api/v1/Describe",
            json(serde_json::json!({ "protocol_version": 1, "model": "furuta" })),
        ),
        (
            "/api/v1/Simulate",
            json(
                serde_json::json!({ "protocol_version": 1, "model": "no-such-model",
                "times": [0.0, 0.5], "outputs": ["pendulumJoint.phi"] }),
            ),
        ),
        (
            "/ui/plot",
            json(
                serde_json::json!({ "title": "t", "series": [{ "label": "x", "x": [0.0, 1.0], "y": [1.0, 2.0] }] }),
            ),
        ),
        (
            "/api/v1/UploadDataset?file_name=rig.csv&time_column=time",
            "time,x\n0,1\n1,2\n".to_string(),
        ),
        (
            "/api/v1/UploadDataset?file_name=rig.mat&time_column=time",
            String::new(),
        ),
        (
            "/api/v1/UploadFmu?file_name=Model.fmu",
            "PK\u{3}\u{4}\u{14}\0\0\0\0\0modelDescription.xmlPK\u{5}\u{6}\0\0".to_string(),
        ),
        (
            "/api/v1/GetFmu",
            json(serde_json::json!({ "id": "0".repeat(64) })),
        ),
        (
            "/api/v1/SubmitCampaign",
            json(serde_json::json!({ "campaign": { "fmu_id": "0".repeat(64),
                "model": "Model.me@000000000000", "dataset_id": "0".repeat(64) } })),
        ),
    ]
}

/// One way to damage a request: truncate, overwrite, insert or delete bytes.
#[derive(Debug, Clone)]
enum Mutation {
    Truncate(usize),
    Overwrite(usize, u8),
    Insert(usize, Vec<u8>),
    Delete(usize, usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), any::<u8>()).prop_map(|(at, b)| Mutation::Overwrite(at, b)),
        (
            any::<usize>(),
            prop_oneof![
                proptest::collection::vec(any::<u8>(), 1..8),
                Just(b"null".to_vec()),
                Just(b"-1".to_vec()),
                Just(b"1e308".to_vec()),
                Just(b"\"\xff\"".to_vec()),
                Just(b"[[[[".to_vec()),
                Just(b"{\"\":".to_vec()),
            ]
        )
            .prop_map(|(at, bytes)| Mutation::Insert(at, bytes)),
        (any::<usize>(), 1usize..16).prop_map(|(at, n)| Mutation::Delete(at, n)),
    ]
}

fn mutate(mut body: Vec<u8>, mutations: &[Mutation]) -> Vec<u8> {
    for m in mutations {
        let at = |i: usize| {
            if body.is_empty() {
                0
            } else {
                i % (body.len() + 1)
            }
        };
        match m {
            Mutation::Truncate(i) => body.truncate(at(*i)),
            Mutation::Overwrite(i, b) => {
                if !body.is_empty() {
                    let i = *i % body.len();
                    body[i] = *b;
                }
            }
            Mutation::Insert(i, bytes) => {
                let i = at(*i);
                body.splice(i..i, bytes.iter().copied());
            }
            Mutation::Delete(i, n) => {
                let i = at(*i);
                let end = (i + n).min(body.len());
                body.drain(i..end);
            }
        }
    }
    body
}

struct App {
    _dir: tempfile::TempDir,
    runtime: tokio::runtime::Runtime,
    router: Router,
}

impl App {
    fn new() -> Self {
        let dir = tempfile::tempdir().unwrap();
        let campaigns = Arc::new(
            Campaigns::new(
                Arc::new(MemoryStore::new()),
                Arc::new(LocalEvaluator),
                Datasets::open(&dir.path().join("datasets")).unwrap(),
                dir.path().join("results"),
            )
            .with_fmus(crate::hosting::fmus::Fmus::open(&dir.path().join("fmus")).unwrap()),
        );
        let router = WebApp::new(campaigns, super::local::simulator())
            .with_door(DoorConfig::default())
            .router(BOUND.parse().unwrap());
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        Self {
            _dir: dir,
            runtime,
            router,
        }
    }

    /// POST `body` to `path`: the status and the body of the answer.
    fn post(&self, path: &str, body: Vec<u8>) -> (StatusCode, String) {
        let request = Request::post(path)
            .header("host", BOUND)
            .header("origin", format!("http://{BOUND}"))
            .header("content-type", "application/json")
            .body(Body::from(body))
            .unwrap();
        self.runtime.block_on(async {
            let answer = self.router.clone().oneshot(request).await.unwrap();
            let status = answer.status();
            let body = axum::body::to_bytes(answer.into_body(), 1 << 20)
                .await
                .unwrap();
            (status, String::from_utf8_lossy(&body).into_owned())
        })
    }
}

/// One app for every case (a static is never dropped, so its runtime outlives the tests).
fn app() -> &'static App {
    static APP: std::sync::OnceLock<App> = std::sync::OnceLock::new();
    APP.get_or_init(App::new)
}

fn assert_answered(path: &str, status: StatusCode, body: &str) {
    assert!(
        status.is_success() || status.is_client_error(),
        "{path}: {status} {body}"
    );
}

#[test]
fn the_valid_requests_are_valid() {
    let app = app();
    for (path, body) in valid_requests() {
        let (status, answer) = app.post(path, body.into_bytes());
        assert_answered(path, status, &answer);
        // Each gets past decoding: what refuses it is the missing dataset or campaign.
        assert!(
            !answer.contains("\"message\":\"request:"),
            "{path}: {answer}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn mutated_requests_get_an_answer_never_a_crash(
        route in 0usize..15,
        mutations in proptest::collection::vec(mutation(), 1..6),
    ) {
        let requests = valid_requests();
        let (path, body) = &requests[route % requests.len()];
        let body = mutate(body.clone().into_bytes(), &mutations);
        let (status, answer) = app().post(path, body);
        assert_answered(path, status, &answer);
    }

    #[test]
    fn arbitrary_bytes_get_an_answer_never_a_crash(
        route in 0usize..15,
        body in proptest::collection::vec(any::<u8>(), 0..512),
    ) {
        let requests = valid_requests();
        let (path, _) = &requests[route % requests.len()];
        let (status, answer) = app().post(path, body);
        assert_answered(path, status, &answer);
    }
}
