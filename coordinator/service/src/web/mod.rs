//! The web app: Model, Measurement, Calibration and Diagnosis tabs in a browser, served by
//! the process itself (`calib ui`, `calib coordinator --http`).
//!
//! **One implementation.** Every route under `/api/v1/` transcodes one RPC: the request
//! message arrives as JSON (the proto's field names), the very service object the gRPC
//! server runs answers it ([`CalibrationApi`], the worker's [`SimulatorService`]), and its
//! answer goes back as JSON; a failure is the RPC's status as an HTTP status with
//! `{"code", "message"}`. Server streams (`WatchCampaign`, `Diagnose`) are Server-Sent
//! Events, one whole message per event. HTTP JSON rather than gRPC-web: the page would need a
//! protobuf codec in JavaScript, and without npm it would be hand-written. Routes under
//! `/ui/` only draw: SVG plots through the report's plotting code ([`plots`]; `/ui/compare`
//! draws several finished campaigns' fits of one output over its measured data), the
//! campaign file of a campaign, what is kept of an uploaded dataset, and a column of an
//! uploaded dataset with its times (which
//! the Model tab drives a model's input with, through `Simulate`'s `inputs`).
//!
//! The page (`assets/`) is hand-written HTML, CSS and JavaScript (ES modules, one per tab,
//! no build step) compiled into the binary: nothing is loaded from elsewhere. Every route
//! is behind the [`door`]: the Host check, the same-origin check and, on a server with a
//! token, the login.

pub mod door;
#[cfg(test)]
mod fuzz;
pub mod local;
pub mod login;
pub mod plots;
#[cfg(test)]
mod readable;

use crate::api::CalibrationApi;
use crate::hosting::Campaigns;
use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Path, RawQuery, State};
use axum::http::{header, StatusCode};
use axum::response::sse::{Event, KeepAlive, Sse};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::Router;
use calib_engine::limits::MAX_DATASET_BYTES;
use calib_engine::limits::MAX_FMU_BYTES;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_server::Calibration;
use calib_proto::v1::simulator_server::Simulator;
use calib_worker::service::simulator::SimulatorService;
use door::{Door, DoorConfig};
use serde::de::DeserializeOwned;
use serde::Serialize;
use std::convert::Infallible;
use std::sync::Arc;
use std::time::Duration;
use tokio_stream::wrappers::ReceiverStream;
use tokio_stream::{Stream, StreamExt};
use tonic::{Code, Request, Status};

const INDEX_HTML: &str = include_str!("assets/index.html");
/// The page's ES modules (`<script type="module">`, no build step): `main.js` wires the
/// page, one module per tab over `common.js`. Served as `/js/<name>`.
const SCRIPTS: &[(&str, &str)] = &[
    ("main.js", include_str!("assets/js/main.js")),
    ("common.js", include_str!("assets/js/common.js")),
    ("model.js", include_str!("assets/js/model.js")),
    ("measurement.js", include_str!("assets/js/measurement.js")),
    ("calibration.js", include_str!("assets/js/calibration.js")),
    ("experiments.js", include_str!("assets/js/experiments.js")),
    ("analysis.js", include_str!("assets/js/analysis.js")),
    ("diagnosis.js", include_str!("assets/js/diagnosis.js")),
    ("discovery.js", include_str!("assets/js/discovery.js")),
    ("effects.js", include_str!("assets/js/effects.js")),
    ("route.js", include_str!("assets/js/route.js")),
    ("runs.js", include_str!("assets/js/runs.js")),
    ("reopen.js", include_str!("assets/js/reopen.js")),
    ("forms.js", include_str!("assets/js/forms.js")),
    ("compare.js", include_str!("assets/js/compare.js")),
];
const APP_CSS: &str = include_str!("assets/app.css");

/// Shortest interval between two events of a stream: a campaign changes with every batch,
/// a page redraws a few times a second at most.
const EVENT_INTERVAL: Duration = Duration::from_millis(200);

/// What the web app's routes call: the Calibration service, the Simulator service, and the
/// campaigns behind them (for plots of uploaded datasets and campaign files).
#[derive(Clone)]
pub struct WebApp {
    calibration: Arc<CalibrationApi>,
    simulator: Arc<SimulatorService>,
    campaigns: Arc<Campaigns>,
    door: DoorConfig,
    /// Whether the Model tab may simulate uploaded FMUs here (their code runs in this
    /// machine's host processes).
    simulates_fmus: bool,
}

impl WebApp {
    pub fn new(campaigns: Arc<Campaigns>, simulator: Arc<SimulatorService>) -> Self {
        Self {
            calibration: Arc::new(CalibrationApi::new(campaigns.clone())),
            simulator,
            campaigns,
            door: DoorConfig::default(),
            simulates_fmus: false,
        }
    }

    /// Let the Model tab simulate uploaded FMUs (`simulator` must take them): `calib ui`,
    /// and a coordinator behind a token. Otherwise such a simulation is refused and FMUs
    /// run only on workers, in campaigns.
    pub fn with_fmu_simulation(mut self, yes: bool) -> Self {
        self.simulates_fmus = yes;
        self
    }

    /// Who may come in besides the bound address's own page, and the token required.
    pub fn with_door(mut self, door: DoorConfig) -> Self {
        self.door = door;
        self
    }

    /// Every route of the app, behind the door of a server bound to `bound`.
    pub fn router(self, bound: std::net::SocketAddr) -> Router {
        let gate = Arc::new(Door::new(self.door.clone(), bound));
        let login = Router::new()
            .route("/login", get(door::login_state).post(door::login))
            .route("/logout", post(door::logout))
            .with_state(gate.clone());
        Router::new()
            .route(
                "/",
                get(|| async { asset("text/html; charset=utf-8", INDEX_HTML) }),
            )
            .route("/js/{name}", get(script))
            .route(
                "/app.css",
                get(|| async { asset("text/css; charset=utf-8", APP_CSS) }),
            )
            .route(
                "/api/v1/UploadDataset",
                post(upload_dataset).layer(DefaultBodyLimit::max(MAX_DATASET_BYTES)),
            )
            .route(
                "/api/v1/UploadFmu",
                post(upload_fmu).layer(DefaultBodyLimit::max(MAX_FMU_BYTES)),
            )
            .route("/api/v1/GetFmu", post(get_fmu))
            .route("/api/v1/SubmitCampaign", post(submit_campaign))
            .route("/api/v1/ValidateCampaign", post(validate_campaign))
            .route("/api/v1/GetCampaign", post(get_campaign))
            .route("/api/v1/ListCampaigns", post(list_campaigns))
            .route("/api/v1/CancelCampaign", post(cancel_campaign))
            .route("/api/v1/WatchCampaign/{id}", get(watch_campaign))
            .route("/api/v1/Diagnose/{id}", get(diagnose))
            .route("/api/v1/Sensitivity", post(sensitivity))
            .route("/api/v1/Profile", post(profile))
            .route("/api/v1/WatchAnalysis/{id}", get(watch_analysis))
            .route("/api/v1/ListModels", post(list_models))
            .route("/api/v1/Describe", post(describe))
            .route("/api/v1/Simulate", post(simulate))
            .route("/ui/plot", post(plots::plot))
            .route("/ui/compare", post(plots::compare))
            .route("/ui/datasets/{id}", get(dataset_info))
            .route("/ui/datasets/{id}/plot/{column}", get(plots::dataset_plot))
            .route(
                "/ui/datasets/{id}/column/{column}",
                get(plots::dataset_column),
            )
            .route("/ui/campaigns/{id}/campaign.toml", get(campaign_file))
            .with_state(self)
            .merge(login)
            .layer(axum::middleware::from_fn_with_state(gate, door::guard))
            .layer(axum::middleware::map_response(json_rejections))
    }
}

/// The body limit's refusal (413, which axum answers in plain text) as every other error
/// is answered: JSON naming the limits.
async fn json_rejections(response: Response) -> Response {
    if response.status() != StatusCode::PAYLOAD_TOO_LARGE {
        return response;
    }
    let mut refused = ApiError(Status::resource_exhausted(format!(
        "the request is larger than this route takes: {} MiB for a dataset, {} MiB for an \
         FMU, 2 MiB for any other request",
        MAX_DATASET_BYTES >> 20,
        MAX_FMU_BYTES >> 20
    )))
    .into_response();
    *refused.status_mut() = StatusCode::PAYLOAD_TOO_LARGE;
    refused
}

/// Serve `router` on `listener` until `shutdown` resolves.
pub async fn serve(
    listener: tokio::net::TcpListener,
    router: Router,
    shutdown: impl std::future::Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    // The client's address reaches the door, which throttles wrong tokens by it.
    let service = router.into_make_service_with_connect_info::<std::net::SocketAddr>();
    axum::serve(listener, service)
        .with_graceful_shutdown(shutdown)
        .await
}

fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}

/// `GET /js/{name}`: one of the page's modules.
async fn script(Path(name): Path<String>) -> Response {
    match SCRIPTS.iter().find(|(n, _)| *n == name) {
        Some((_, body)) => asset("text/javascript; charset=utf-8", body),
        None => StatusCode::NOT_FOUND.into_response(),
    }
}

/// An RPC's failure as an HTTP answer.
pub struct ApiError(Status);

impl From<Status> for ApiError {
    fn from(s: Status) -> Self {
        Self(s)
    }
}

/// The HTTP status of a gRPC status code.
pub fn http_status(code: Code) -> StatusCode {
    match code {
        Code::InvalidArgument | Code::OutOfRange => StatusCode::BAD_REQUEST,
        Code::NotFound => StatusCode::NOT_FOUND,
        Code::FailedPrecondition => StatusCode::PRECONDITION_FAILED,
        Code::ResourceExhausted => StatusCode::TOO_MANY_REQUESTS,
        Code::Unauthenticated => StatusCode::UNAUTHORIZED,
        Code::PermissionDenied => StatusCode::FORBIDDEN,
        Code::Unavailable => StatusCode::SERVICE_UNAVAILABLE,
        Code::Unimplemented => StatusCode::NOT_IMPLEMENTED,
        _ => StatusCode::INTERNAL_SERVER_ERROR,
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        let body = serde_json::json!({
            "code": format!("{:?}", self.0.code()),
            "message": self.0.message(),
        });
        (
            http_status(self.0.code()),
            [(header::CONTENT_TYPE, "application/json")],
            body.to_string(),
        )
            .into_response()
    }
}

/// A request message from its JSON.
fn decode<T: DeserializeOwned>(body: &[u8]) -> Result<T, ApiError> {
    let body = if body.iter().all(u8::is_ascii_whitespace) {
        b"{}".as_slice()
    } else {
        body
    };
    serde_json::from_slice(body)
        .map_err(|e| ApiError(Status::invalid_argument(format!("request: {e}"))))
}

/// An answer message as JSON.
fn json<T: Serialize>(message: &T) -> Response {
    (
        [(header::CONTENT_TYPE, "application/json")],
        serde_json::to_string(message).expect("messages are plain data"),
    )
        .into_response()
}

/// `POST /api/v1/UploadDataset?file_name=NAME&time_column=COLUMN` with the file as the
/// body: the client stream of `DatasetChunk`s in one piece.
async fn upload_dataset(
    State(app): State<WebApp>,
    RawQuery(query): RawQuery,
    body: Bytes,
) -> Result<Response, ApiError> {
    let (mut file_name, mut time_column) = (String::new(), String::new());
    for pair in query.as_deref().unwrap_or("").split('&') {
        let (key, value) = pair.split_once('=').unwrap_or((pair, ""));
        let value = percent_encoding::percent_decode_str(&value.replace('+', " "))
            .decode_utf8_lossy()
            .into_owned();
        match key {
            "file_name" => file_name = value,
            "time_column" => time_column = value,
            _ => {}
        }
    }
    let dataset = app
        .calibration
        .upload(file_name, time_column, body.to_vec())
        .await?;
    Ok(json(&dataset))
}

/// `POST /api/v1/UploadFmu?file_name=NAME` with the archive as the body: the client stream
/// of `FmuChunk`s in one piece.
async fn upload_fmu(
    State(app): State<WebApp>,
    RawQuery(query): RawQuery,
    body: Bytes,
) -> Result<Response, ApiError> {
    let file_name = query_value(query.as_deref(), "file_name");
    let fmu = app
        .calibration
        .upload_fmu_bytes(file_name, body.to_vec())
        .await?;
    Ok(json(&fmu))
}

/// The value of `key` in a query string, percent-decoded; empty when absent.
fn query_value(query: Option<&str>, key: &str) -> String {
    query
        .unwrap_or("")
        .split('&')
        .filter_map(|pair| {
            let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
            (k == key).then(|| {
                percent_encoding::percent_decode_str(&v.replace('+', " "))
                    .decode_utf8_lossy()
                    .into_owned()
            })
        })
        .next_back()
        .unwrap_or_default()
}

macro_rules! unary {
    ($name:ident, $service:ident, $method:ident, $request:ty) => {
        async fn $name(State(app): State<WebApp>, body: Bytes) -> Result<Response, ApiError> {
            let request: $request = decode(&body)?;
            let answer = app.$service.$method(Request::new(request)).await?;
            Ok(json(answer.get_ref()))
        }
    };
}

unary!(
    submit_campaign,
    calibration,
    submit_campaign,
    pb::SubmitCampaignRequest
);
unary!(
    validate_campaign,
    calibration,
    validate_campaign,
    pb::ValidateCampaignRequest
);
unary!(
    get_campaign,
    calibration,
    get_campaign,
    pb::GetCampaignRequest
);
unary!(
    list_campaigns,
    calibration,
    list_campaigns,
    pb::ListCampaignsRequest
);
unary!(
    cancel_campaign,
    calibration,
    cancel_campaign,
    pb::CancelCampaignRequest
);
unary!(get_fmu, calibration, get_fmu, pb::GetFmuRequest);
unary!(list_models, simulator, list_models, pb::ListModelsRequest);
unary!(describe, simulator, describe, pb::DescribeRequest);

/// `POST /api/v1/Simulate`: the Simulator's `Simulate`; an uploaded FMU only where the app
/// may run FMU code ([`WebApp::with_fmu_simulation`]).
async fn simulate(State(app): State<WebApp>, body: Bytes) -> Result<Response, ApiError> {
    let request: pb::SimulateRequest = decode(&body)?;
    if !request.fmu_hash.is_empty() && !app.simulates_fmus {
        return Err(ApiError(Status::permission_denied(
            "fmu_hash: this coordinator runs no FMU code for the web app without a token \
             (--token-file); campaigns on the FMU run on its workers",
        )));
    }
    let answer = app.simulator.simulate(Request::new(request)).await?;
    Ok(json(answer.get_ref()))
}

type EventStream =
    Sse<axum::response::sse::KeepAliveStream<ReceiverStream<Result<Event, Infallible>>>>;

/// `GET /api/v1/WatchCampaign/{id}`: the `WatchCampaign` stream as Server-Sent Events.
async fn watch_campaign(
    State(app): State<WebApp>,
    Path(id): Path<String>,
) -> Result<EventStream, ApiError> {
    let stream = app
        .calibration
        .watch_campaign(Request::new(pb::WatchCampaignRequest { id }))
        .await?
        .into_inner();
    Ok(events(stream))
}

/// `GET /api/v1/Diagnose/{id}[?discover=true]`: the `Diagnose` stream as Server-Sent
/// Events.
async fn diagnose(
    State(app): State<WebApp>,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
) -> Result<EventStream, ApiError> {
    let discover = query_value(query.as_deref(), "discover") == "true";
    let stream = app
        .calibration
        .diagnose(Request::new(pb::DiagnoseRequest { id, discover }))
        .await?
        .into_inner();
    Ok(events(stream))
}

/// `POST /api/v1/Sensitivity`: starts (or joins) the analysis and answers with the
/// stream's first state, which names it; `WatchAnalysis/{id}` follows it.
async fn sensitivity(State(app): State<WebApp>, body: Bytes) -> Result<Response, ApiError> {
    let request: pb::SensitivityRequest = decode(&body)?;
    let stream = app
        .calibration
        .sensitivity(Request::new(request))
        .await?
        .into_inner();
    first_state(stream).await
}

/// `POST /api/v1/Profile`: starts (or joins) the profiles and answers with the stream's
/// first state, which names them; `WatchAnalysis/{id}` follows them.
async fn profile(State(app): State<WebApp>, body: Bytes) -> Result<Response, ApiError> {
    let request: pb::ProfileRequest = decode(&body)?;
    let stream = app
        .calibration
        .profile(Request::new(request))
        .await?
        .into_inner();
    first_state(stream).await
}

/// The first state of an analysis' stream as the JSON answer (the analysis goes on).
async fn first_state<S>(mut stream: S) -> Result<Response, ApiError>
where
    S: Stream<Item = Result<pb::AnalysisState, Status>> + Unpin,
{
    match stream.next().await {
        Some(first) => Ok(json(&first?)),
        None => Err(ApiError(Status::internal("the analysis sent no state"))),
    }
}

/// `GET /api/v1/WatchAnalysis/{id}`: the `WatchAnalysis` stream as Server-Sent Events.
async fn watch_analysis(
    State(app): State<WebApp>,
    Path(id): Path<String>,
) -> Result<EventStream, ApiError> {
    let stream = app
        .calibration
        .watch_analysis(Request::new(pb::WatchAnalysisRequest { id }))
        .await?
        .into_inner();
    Ok(events(stream))
}

/// A stream of whole states as events, at most one per [`EVENT_INTERVAL`]: states that
/// arrive meanwhile are skipped but the last, so the final one is always sent. A failure
/// mid-stream is an `error` event with its message. The stream then ends.
fn events<T, S>(mut states: S) -> EventStream
where
    T: Serialize + Send + 'static,
    S: Stream<Item = Result<T, Status>> + Send + Unpin + 'static,
{
    let (tx, rx) = tokio::sync::mpsc::channel(1);
    tokio::spawn(async move {
        while let Some(mut item) = states.next().await {
            // Whatever else is ready now: only the newest counts.
            while let Ok(Some(newer)) = tokio::time::timeout(Duration::ZERO, states.next()).await {
                item = newer;
            }
            let (event, last) = match item {
                Ok(state) => (
                    Event::default().data(serde_json::to_string(&state).expect("plain data")),
                    false,
                ),
                Err(status) => (Event::default().event("error").data(status.message()), true),
            };
            if tx.send(Ok(event)).await.is_err() || last {
                break;
            }
            tokio::time::sleep(EVENT_INTERVAL).await;
        }
    });
    Sse::new(ReceiverStream::new(rx)).keep_alive(KeepAlive::default())
}

/// `GET /ui/datasets/{id}`: what is kept of an uploaded dataset (its file's name, time
/// column, columns, samples, first and last time), for a page that names it in its URL or
/// reopens a campaign on it.
async fn dataset_info(
    State(app): State<WebApp>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let campaigns = app.campaigns.clone();
    let found = {
        let id = id.clone();
        tokio::task::spawn_blocking(move || campaigns.datasets().get(&id))
            .await
            .map_err(|e| ApiError(Status::internal(e.to_string())))?
            .map_err(|e| ApiError(Status::invalid_argument(e.to_string())))?
    };
    match found {
        Some(info) => Ok(json(&info)),
        None => Err(ApiError(Status::not_found(format!(
            "id: no dataset `{id}` here: upload the file again"
        )))),
    }
}

/// `GET /ui/campaigns/{id}/campaign.toml`: the campaign file a campaign was run from.
async fn campaign_file(
    State(app): State<WebApp>,
    Path(id): Path<String>,
) -> Result<Response, ApiError> {
    let campaigns = app.campaigns.clone();
    let found = {
        let id = id.clone();
        tokio::task::spawn_blocking(move || campaigns.spec(&id))
            .await
            .map_err(|e| ApiError(Status::internal(e.to_string())))?
            .map_err(|e| ApiError(Status::internal(e.to_string())))?
    };
    let Some(spec) = found else {
        return Err(ApiError(Status::not_found(format!(
            "id: no campaign `{id}` here"
        ))));
    };
    Ok((
        [
            (header::CONTENT_TYPE, "application/toml; charset=utf-8"),
            (
                header::CONTENT_DISPOSITION,
                "attachment; filename=\"campaign.toml\"",
            ),
        ],
        spec,
    )
        .into_response())
}
