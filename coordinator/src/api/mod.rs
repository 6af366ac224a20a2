//! The `calib.v1.Calibration` gRPC service: campaigns for clients in any language. A thin
//! layer: messages are checked and converted here, the work is [`crate::campaigns`]'.

pub mod spec;

use crate::campaigns::analyses::AnalysisSnapshot;
use crate::campaigns::datasets::DatasetInfo;
use crate::campaigns::diagnoses::DiagnosisSnapshot;
use crate::campaigns::fmus::FmuInfo;
use crate::campaigns::{Campaigns, Phase, Snapshot, Watched};
use crate::error::Error;
use crate::limits::{MAX_DATASET_BYTES, MAX_FMU_BYTES, MAX_IDEMPOTENCY_KEY_BYTES};
use crate::sensitivity::{Methods, Settings, DEFAULT_SAMPLES};
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_server::Calibration;
use calib_worker::fmu;
use calib_worker::service::simulator::describe;
use std::pin::Pin;
use std::sync::Arc;
use tokio_stream::wrappers::ReceiverStream;
use tonic::{Request, Response, Status, Streaming};

pub use crate::limits::{MAX_CHUNK_BYTES, MAX_PAGE, MAX_SENSITIVITY_SAMPLES};

pub struct CalibrationApi {
    campaigns: Arc<Campaigns>,
}

impl CalibrationApi {
    pub fn new(campaigns: Arc<Campaigns>) -> Self {
        Self { campaigns }
    }

    /// The end of `UploadDataset`, once the chunks are joined: check the file's name, parse
    /// and keep it. The web app's upload route, which receives the file whole, calls it too.
    pub async fn upload(
        &self,
        file_name: String,
        mut time_column: String,
        bytes: Vec<u8>,
    ) -> Result<pb::Dataset, Status> {
        if file_name.is_empty() {
            return Err(Status::invalid_argument(
                "file_name: the first chunk must name the file (its extension picks the parser)",
            ));
        }
        if bytes.is_empty() {
            return Err(Status::invalid_argument("data: the file is empty"));
        }
        if time_column.is_empty() {
            time_column = "time".into();
        }
        let campaigns = self.campaigns.clone();
        let info = self
            .blocking(move || campaigns.datasets().put(&file_name, &time_column, &bytes))
            .await?;
        Ok(pb::Dataset {
            id: info.id,
            columns: info.columns,
            samples: info.samples as u64,
            start_time: info.start_time,
            stop_time: info.stop_time,
        })
    }

    /// The end of `UploadFmu`, once the chunks are joined: check the archive and keep it.
    /// The web app's upload route, which receives the file whole, calls it too.
    pub async fn upload_fmu_bytes(
        &self,
        file_name: String,
        bytes: Vec<u8>,
    ) -> Result<pb::Fmu, Status> {
        if file_name.is_empty() {
            return Err(Status::invalid_argument(
                "file_name: the first chunk must name the file (e.g. Model.fmu)",
            ));
        }
        if bytes.is_empty() {
            return Err(Status::invalid_argument("data: the file is empty"));
        }
        let campaigns = self.campaigns.clone();
        let info = self
            .blocking(move || campaigns.fmus()?.put(&file_name, &bytes))
            .await?;
        Ok(fmu_message(&info))
    }

    /// The uploaded FMU `id`, or NOT_FOUND.
    async fn fmu(&self, id: &str, field: &str) -> Result<FmuInfo, Status> {
        let campaigns = self.campaigns.clone();
        let found = {
            let id = id.to_string();
            self.blocking(move || campaigns.fmus()?.get(&id)).await?
        };
        found.ok_or_else(|| {
            Status::not_found(format!(
                "{field}: no FMU `{id}` on this coordinator; upload it with UploadFmu"
            ))
        })
    }

    /// The campaign file of a campaign message, its measurement the uploaded dataset it
    /// names.
    async fn campaign_file(&self, campaign: &pb::Campaign) -> Result<String, Status> {
        if campaign.dataset_id.is_empty() {
            return Err(Status::invalid_argument(
                "campaign.dataset_id: missing; upload the data with UploadDataset first",
            ));
        }
        let dataset = {
            let campaigns = self.campaigns.clone();
            let id = campaign.dataset_id.clone();
            self.blocking(move || campaigns.datasets().get(&id)).await?
        };
        let Some(dataset) = dataset else {
            return Err(Status::not_found(format!(
                "campaign.dataset_id: no dataset `{}` on this coordinator; upload it with \
                 UploadDataset",
                campaign.dataset_id
            )));
        };
        check_against_dataset(campaign, &dataset)?;
        let file = self.campaigns.datasets().file(&dataset);
        if campaign.fmu_id.is_empty() {
            if fmu::interface_in_name(&campaign.model).is_some() {
                return Err(Status::invalid_argument(format!(
                    "campaign.fmu_id: missing; `{}` is an FMU's model: name the FMU by the \
                     id UploadFmu answered",
                    campaign.model
                )));
            }
            return spec::campaign_file(campaign, &file, &dataset.time_column)
                .map_err(Status::invalid_argument);
        }
        let info = self.fmu(&campaign.fmu_id, "campaign.fmu_id").await?;
        let mut campaign = campaign.clone();
        if !campaign.model.is_empty() {
            let names: Vec<&str> = info.models.iter().map(|m| m.info().name.as_str()).collect();
            if !names.contains(&campaign.model.as_str()) {
                return Err(Status::invalid_argument(format!(
                    "campaign.model: `{}` is not a model of FMU `{}` (its models: {}); leave \
                     it empty for the FMU's default",
                    campaign.model,
                    info.id,
                    names.join(", ")
                )));
            }
            let named = match fmu::interface_in_name(&campaign.model) {
                Some(fmu::Interface::ModelExchange) => "model-exchange",
                _ => "co-simulation",
            };
            if !campaign.fmu_interface.is_empty() && campaign.fmu_interface != named {
                return Err(Status::invalid_argument(format!(
                    "campaign.fmu_interface: `{}`, but campaign.model `{}` runs through {named}",
                    campaign.fmu_interface, campaign.model
                )));
            }
            campaign.fmu_interface = named.into();
        }
        let archive = self
            .campaigns
            .fmus()
            .ok()
            .and_then(|f| f.file(&info.id))
            .ok_or_else(|| Status::internal("the FMU's archive has no path"))?;
        spec::campaign_file_on(&campaign, &file, &dataset.time_column, Some(&archive))
            .map_err(Status::invalid_argument)
    }

    /// [`blocking`], its refusals worded for a client: no path of this server in them.
    async fn blocking<T: Send + 'static>(
        &self,
        work: impl FnOnce() -> Result<T, Error> + Send + 'static,
    ) -> Result<T, Status> {
        blocking(work)
            .await
            .map_err(|s| Status::new(s.code(), self.campaigns.public(s.message())))
    }
}

/// Most column names a refusal lists.
const LISTED_COLUMNS: usize = 20;

/// The campaign's fields checked against the dataset it names, before anything is parsed
/// or run: every mapped column is one of the dataset's, the window lies inside its data.
fn check_against_dataset(campaign: &pb::Campaign, dataset: &DatasetInfo) -> Result<(), Status> {
    for (i, output) in campaign.outputs.iter().enumerate() {
        if !dataset.columns.contains(&output.measured) {
            let mut listed: Vec<String> = dataset
                .columns
                .iter()
                .take(LISTED_COLUMNS)
                .map(|c| format!("{c:?}"))
                .collect();
            if dataset.columns.len() > LISTED_COLUMNS {
                listed.push(format!("… ({} in all)", dataset.columns.len()));
            }
            return Err(Status::invalid_argument(format!(
                "campaign.outputs[{i}].measured: dataset `{}` has no column {:?}; its columns \
                 are: {}",
                dataset.id,
                output.measured,
                listed.join(", ")
            )));
        }
    }
    let (start, stop) = (campaign.window_start, campaign.window_stop);
    let (first, last) = (dataset.start_time, dataset.stop_time);
    let slack = 1e-9 * last.abs().max(1.0);
    let outside = |field: &str, value: f64| {
        Status::invalid_argument(format!(
            "campaign.{field}: {value} s lies outside the data of dataset `{}` (time runs \
             from {first} to {last} s)",
            dataset.id
        ))
    };
    // A window of 0 to 0 is no window: the campaign's check names it missing.
    if start != 0.0 || stop != 0.0 {
        if stop > last + slack {
            return Err(outside("window_stop", stop));
        }
        if start < first - slack {
            return Err(outside("window_start", start));
        }
    }
    Ok(())
}

/// The campaign message's name of a campaign file's field (`model.stop_time` is the
/// message's `stop_time`), for refusals that name what the client sent.
fn message_field(field: &str) -> String {
    let renamed = match field {
        "" => return "campaign".into(),
        "window" => "window_start, campaign.window_stop",
        "window.start" => "window_start",
        "window.stop" => "window_stop",
        "model.name" | "model" => "model",
        "model.stop_time" => "stop_time",
        other => {
            if let Some(name) = other.strip_prefix("model.parameters.") {
                return format!("campaign.model_parameters[{name:?}]");
            }
            other.strip_prefix("solver.").unwrap_or(other)
        }
    };
    format!("campaign.{renamed}")
}

/// How an error of the domain reads to a client.
fn status(e: Error) -> Status {
    match e {
        Error::Campaign(c) => {
            Status::invalid_argument(format!("{}: {}", message_field(&c.field), c.message))
        }
        Error::Measurement(m) => Status::invalid_argument(format!("data: {m}")),
        Error::InvalidRequest(m) => Status::invalid_argument(m),
        other => Status::internal(other.to_string()),
    }
}

fn phase(p: Phase) -> pb::CampaignPhase {
    match p {
        Phase::Running => pb::CampaignPhase::Running,
        Phase::Finished => pb::CampaignPhase::Finished,
        Phase::Failed => pb::CampaignPhase::Failed,
        Phase::Cancelled => pb::CampaignPhase::Cancelled,
    }
}

fn state(s: &Snapshot) -> pb::CampaignState {
    pb::CampaignState {
        id: s.id.clone(),
        name: s.name.clone(),
        phase: phase(s.phase).into(),
        evaluations: s.evaluations,
        run_best: s.run_best.clone(),
        best_objective: s.best_objective,
        failure: s.failure.clone().unwrap_or_default(),
        result_json: s
            .result
            .as_ref()
            .map(|r| serde_json::to_string_pretty(r).expect("plain data"))
            .unwrap_or_default(),
        plots: s.plots.iter().cloned().collect(),
    }
}

/// The answer of `UploadFmu` and `GetFmu`.
fn fmu_message(info: &FmuInfo) -> pb::Fmu {
    pb::Fmu {
        id: info.id.clone(),
        file_name: info.file_name.clone(),
        size: info.size,
        models: info.models.iter().map(|m| describe(*m)).collect(),
    }
}

fn not_found(id: &str) -> Status {
    Status::not_found(format!("id: no campaign `{id}` on this coordinator"))
}

/// Run blocking domain work off the async runtime.
async fn blocking<T: Send + 'static>(
    work: impl FnOnce() -> Result<T, Error> + Send + 'static,
) -> Result<T, Status> {
    tokio::task::spawn_blocking(work)
        .await
        .map_err(|e| Status::internal(format!("task failed: {e}")))?
        .map_err(status)
}

type DiagnosisStream =
    Pin<Box<dyn tokio_stream::Stream<Item = Result<pb::DiagnosisState, Status>> + Send>>;

fn diagnosis_state(s: &DiagnosisSnapshot) -> pb::DiagnosisState {
    pb::DiagnosisState {
        campaign_id: s.campaign_id.clone(),
        phase: phase(s.phase).into(),
        evaluations: s.evaluations,
        failure: s.failure.clone().unwrap_or_default(),
        report_json: s
            .report
            .as_ref()
            .map(|r| serde_json::to_string_pretty(r).expect("plain data"))
            .unwrap_or_default(),
        files: s.files.iter().cloned().collect(),
    }
}

fn analysis_state(s: &AnalysisSnapshot) -> pb::AnalysisState {
    pb::AnalysisState {
        id: s.id.clone(),
        phase: phase(s.phase).into(),
        evaluations: s.evaluations,
        planned: s.planned,
        failure: s.failure.clone().unwrap_or_default(),
        report_json: s
            .report
            .as_ref()
            .map(|r| serde_json::to_string_pretty(r).expect("plain data"))
            .unwrap_or_default(),
        conclusion: s.conclusion.clone(),
        files: s.files.iter().cloned().collect(),
    }
}

type AnalysisStream =
    Pin<Box<dyn tokio_stream::Stream<Item = Result<pb::AnalysisState, Status>> + Send>>;

/// Every state of `receiver` as a message, from the current one to the one that `ended`.
fn follow<S, M>(
    mut receiver: tokio::sync::watch::Receiver<S>,
    message: fn(&S) -> M,
    ended: fn(&S) -> bool,
) -> Pin<Box<dyn tokio_stream::Stream<Item = Result<M, Status>> + Send>>
where
    S: Clone + Send + Sync + 'static,
    M: Send + 'static,
{
    let (tx, rx) = tokio::sync::mpsc::channel(16);
    tokio::spawn(async move {
        loop {
            let snapshot = receiver.borrow_and_update().clone();
            if tx.send(Ok(message(&snapshot))).await.is_err() || ended(&snapshot) {
                break;
            }
            if receiver.changed().await.is_err() {
                break;
            }
        }
    });
    Box::pin(ReceiverStream::new(rx))
}

/// Every state of an analysis, to its end.
fn follow_analysis(receiver: tokio::sync::watch::Receiver<AnalysisSnapshot>) -> AnalysisStream {
    follow(receiver, analysis_state, |s| s.phase.ended())
}

type StateStream =
    Pin<Box<dyn tokio_stream::Stream<Item = Result<pb::CampaignState, Status>> + Send>>;

#[tonic::async_trait]
impl Calibration for CalibrationApi {
    async fn upload_dataset(
        &self,
        request: Request<Streaming<pb::DatasetChunk>>,
    ) -> Result<Response<pb::Dataset>, Status> {
        let mut chunks = request.into_inner();
        let mut bytes = Vec::new();
        let (mut file_name, mut time_column) = (String::new(), String::new());
        let mut first = true;
        while let Some(chunk) = chunks.message().await? {
            if first {
                file_name = chunk.file_name;
                time_column = chunk.time_column;
                first = false;
            }
            if chunk.data.len() > MAX_CHUNK_BYTES {
                return Err(Status::invalid_argument(format!(
                    "data: a chunk of {} bytes is more than the {MAX_CHUNK_BYTES} accepted",
                    chunk.data.len()
                )));
            }
            if bytes.len() + chunk.data.len() > MAX_DATASET_BYTES {
                return Err(Status::invalid_argument(format!(
                    "data: the file is more than the {MAX_DATASET_BYTES} bytes accepted"
                )));
            }
            bytes.extend_from_slice(&chunk.data);
        }
        self.upload(file_name, time_column, bytes)
            .await
            .map(Response::new)
    }

    async fn upload_fmu(
        &self,
        request: Request<Streaming<pb::FmuChunk>>,
    ) -> Result<Response<pb::Fmu>, Status> {
        let mut chunks = request.into_inner();
        let mut bytes = Vec::new();
        let mut file_name = String::new();
        let mut first = true;
        while let Some(chunk) = chunks.message().await? {
            if first {
                file_name = chunk.file_name;
                first = false;
            }
            if chunk.data.len() > MAX_CHUNK_BYTES {
                return Err(Status::invalid_argument(format!(
                    "data: a chunk of {} bytes is more than the {MAX_CHUNK_BYTES} accepted",
                    chunk.data.len()
                )));
            }
            if bytes.len() + chunk.data.len() > MAX_FMU_BYTES {
                return Err(Status::invalid_argument(format!(
                    "fmu: the archive is more than the {MAX_FMU_BYTES} bytes accepted (what a \
                     worker's UploadFmu carries)"
                )));
            }
            bytes.extend_from_slice(&chunk.data);
        }
        self.upload_fmu_bytes(file_name, bytes)
            .await
            .map(Response::new)
    }

    async fn get_fmu(
        &self,
        request: Request<pb::GetFmuRequest>,
    ) -> Result<Response<pb::Fmu>, Status> {
        let id = request.into_inner().id;
        let info = self.fmu(&id, "id").await?;
        Ok(Response::new(fmu_message(&info)))
    }

    async fn submit_campaign(
        &self,
        request: Request<pb::SubmitCampaignRequest>,
    ) -> Result<Response<pb::SubmitCampaignResponse>, Status> {
        let request = request.into_inner();
        let campaign = request
            .campaign
            .ok_or_else(|| Status::invalid_argument("campaign: missing"))?;
        if request.idempotency_key.len() > MAX_IDEMPOTENCY_KEY_BYTES {
            return Err(Status::invalid_argument(format!(
                "idempotency_key: {} bytes, more than the {MAX_IDEMPOTENCY_KEY_BYTES} accepted",
                request.idempotency_key.len()
            )));
        }
        let text = self.campaign_file(&campaign).await?;
        let campaigns = self.campaigns.clone();
        let key = Some(request.idempotency_key).filter(|k| !k.is_empty());
        let (id, started) = self
            .blocking(move || campaigns.submit(&text, key.as_deref()))
            .await?;
        Ok(Response::new(pb::SubmitCampaignResponse { id, started }))
    }

    type WatchCampaignStream = StateStream;

    async fn watch_campaign(
        &self,
        request: Request<pb::WatchCampaignRequest>,
    ) -> Result<Response<Self::WatchCampaignStream>, Status> {
        let id = request.into_inner().id;
        let campaigns = self.campaigns.clone();
        let watched = {
            let id = id.clone();
            self.blocking(move || campaigns.watch(&id)).await?
        };
        match watched.ok_or_else(|| not_found(&id))? {
            Watched::Stored(snapshot) => {
                let message = Ok(state(&snapshot));
                Ok(Response::new(Box::pin(tokio_stream::once(message))))
            }
            Watched::Live(receiver) => {
                Ok(Response::new(follow(receiver, state, |s| s.phase.ended())))
            }
        }
    }

    type DiagnoseStream = DiagnosisStream;

    async fn diagnose(
        &self,
        request: Request<pb::DiagnoseRequest>,
    ) -> Result<Response<Self::DiagnoseStream>, Status> {
        let id = request.into_inner().id;
        let campaigns = self.campaigns.clone();
        let watched = {
            let id = id.clone();
            self.blocking(move || campaigns.diagnose(&id)).await?
        };
        let receiver = watched.ok_or_else(|| not_found(&id))?;
        Ok(Response::new(follow(receiver, diagnosis_state, |s| {
            s.phase.ended()
        })))
    }

    async fn get_campaign(
        &self,
        request: Request<pb::GetCampaignRequest>,
    ) -> Result<Response<pb::CampaignState>, Status> {
        let id = request.into_inner().id;
        let campaigns = self.campaigns.clone();
        let found = {
            let id = id.clone();
            self.blocking(move || campaigns.get(&id)).await?
        };
        found
            .map(|s| Response::new(state(&s)))
            .ok_or_else(|| not_found(&id))
    }

    async fn list_campaigns(
        &self,
        request: Request<pb::ListCampaignsRequest>,
    ) -> Result<Response<pb::ListCampaignsResponse>, Status> {
        let request = request.into_inner();
        let size = match request.page_size as usize {
            0 => MAX_PAGE,
            n => n.min(MAX_PAGE),
        };
        let from: usize = if request.page_token.is_empty() {
            0
        } else {
            request.page_token.parse().map_err(|_| {
                Status::invalid_argument(format!(
                    "page_token: `{}` is not a token this coordinator gave",
                    request.page_token
                ))
            })?
        };
        let campaigns = self.campaigns.clone();
        let all = self.blocking(move || campaigns.list()).await?;
        let page: Vec<pb::CampaignState> = all.iter().skip(from).take(size).map(state).collect();
        let next = from + page.len();
        Ok(Response::new(pb::ListCampaignsResponse {
            campaigns: page,
            next_page_token: if next < all.len() {
                next.to_string()
            } else {
                String::new()
            },
        }))
    }

    async fn cancel_campaign(
        &self,
        request: Request<pb::CancelCampaignRequest>,
    ) -> Result<Response<pb::CampaignState>, Status> {
        let id = request.into_inner().id;
        let campaigns = self.campaigns.clone();
        let found = {
            let id = id.clone();
            self.blocking(move || campaigns.cancel(&id)).await?
        };
        found
            .map(|s| Response::new(state(&s)))
            .ok_or_else(|| not_found(&id))
    }

    type SensitivityStream = AnalysisStream;

    async fn sensitivity(
        &self,
        request: Request<pb::SensitivityRequest>,
    ) -> Result<Response<Self::SensitivityStream>, Status> {
        let request = request.into_inner();
        let campaign = request
            .campaign
            .ok_or_else(|| Status::invalid_argument("campaign: missing"))?;
        let methods = match request.method.as_str() {
            "" | "both" => Methods::Both,
            "morris" => Methods::Morris,
            "sobol" => Methods::Sobol,
            other => {
                return Err(Status::invalid_argument(format!(
                    "method: `{other}` is not \"morris\", \"sobol\" or empty (both)"
                )))
            }
        };
        let settings = Settings {
            methods,
            samples: match request.samples {
                0 => DEFAULT_SAMPLES,
                n => n as usize,
            },
            seed: match request.seed {
                0 => 1,
                n => n,
            },
        };
        settings.check().map_err(status)?;
        let text = self.campaign_file(&campaign).await?;
        let campaigns = self.campaigns.clone();
        let receiver = self
            .blocking(move || campaigns.sensitivity(&text, settings))
            .await?;
        Ok(Response::new(follow_analysis(receiver)))
    }

    type ProfileStream = AnalysisStream;

    async fn profile(
        &self,
        request: Request<pb::ProfileRequest>,
    ) -> Result<Response<Self::ProfileStream>, Status> {
        let request = request.into_inner();
        let settings = crate::profile::Settings {
            parameters: request.parameters,
            max_steps: match request.max_steps {
                0 => crate::profile::walk::DEFAULT_MAX_STEPS,
                n => n as usize,
            },
        };
        let id = request.id;
        let campaigns = self.campaigns.clone();
        let watched = {
            let id = id.clone();
            self.blocking(move || campaigns.profile(&id, settings))
                .await?
        };
        let receiver = watched.ok_or_else(|| not_found(&id))?;
        Ok(Response::new(follow_analysis(receiver)))
    }

    type WatchAnalysisStream = AnalysisStream;

    async fn watch_analysis(
        &self,
        request: Request<pb::WatchAnalysisRequest>,
    ) -> Result<Response<Self::WatchAnalysisStream>, Status> {
        let id = request.into_inner().id;
        let receiver = self.campaigns.watch_analysis(&id).ok_or_else(|| {
            Status::not_found(format!("id: no analysis `{id}` on this coordinator"))
        })?;
        Ok(Response::new(follow_analysis(receiver)))
    }
}
