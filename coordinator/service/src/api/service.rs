//! The `Calibration` trait answered: each RPC unpacks its request, hands the work to the
//! campaigns, and packs the answer. The checks and conversions are the sibling modules'.

use super::follow::{follow, follow_analysis, AnalysisStream, DiagnosisStream, StateStream};
use super::messages::{diagnosis_state, fmu_message, state};
use super::problem::Problem;
use super::refusals::{not_found, status};
use super::uploads::{dataset_chunks, fmu_chunks};
use super::{defined_effects, CalibrationApi, MAX_PAGE};
use crate::hosting::Watched;
use calib_analysis::sensitivity::{Methods, Settings, DEFAULT_SAMPLES};
use calib_engine::limits::MAX_IDEMPOTENCY_KEY_BYTES;
use calib_proto::v1 as pb;
use calib_proto::v1::calibration_server::Calibration;
use tonic::{Request, Response, Status, Streaming};

#[tonic::async_trait]
impl Calibration for CalibrationApi {
    async fn upload_dataset(
        &self,
        request: Request<Streaming<pb::DatasetChunk>>,
    ) -> Result<Response<pb::Dataset>, Status> {
        let (file_name, time_column, bytes) = dataset_chunks(request.into_inner()).await?;
        self.upload(file_name, time_column, bytes)
            .await
            .map(Response::new)
    }

    async fn upload_fmu(
        &self,
        request: Request<Streaming<pb::FmuChunk>>,
    ) -> Result<Response<pb::Fmu>, Status> {
        let (file_name, bytes) = fmu_chunks(request.into_inner()).await?;
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
        // Refused for what ValidateCampaign reports, the same checks on the same code.
        if let Some(problem) = self.early_problems(&campaign).await?.first() {
            return Err(problem.status());
        }
        let spec = self.campaign_spec(&campaign).await?;
        let campaigns = self.campaigns.clone();
        let key = Some(request.idempotency_key).filter(|k| !k.is_empty());
        let message = serde_json::to_value(&campaign).ok();
        let (id, started) = self
            .blocking(move || campaigns.submit_message(spec, key.as_deref(), message))
            .await
            .map_err(|s| defined_effects::refusal_in_message_fields(&campaign, s))?;
        Ok(Response::new(pb::SubmitCampaignResponse { id, started }))
    }

    async fn validate_campaign(
        &self,
        request: Request<pb::ValidateCampaignRequest>,
    ) -> Result<Response<pb::ValidateCampaignResponse>, Status> {
        let campaign = request
            .into_inner()
            .campaign
            .ok_or_else(|| Status::invalid_argument("campaign: missing"))?;
        let problems = self.validate(&campaign).await?;
        Ok(Response::new(pb::ValidateCampaignResponse {
            problems: problems.iter().map(Problem::message).collect(),
        }))
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
        let pb::DiagnoseRequest { id, discover } = request.into_inner();
        let campaigns = self.campaigns.clone();
        let watched = {
            let id = id.clone();
            self.blocking(move || campaigns.diagnose(&id, discover))
                .await?
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
        // Lists are for choosing: each campaign's progress history is GetCampaign's.
        let page: Vec<pb::CampaignState> = all
            .iter()
            .skip(from)
            .take(size)
            .map(|s| pb::CampaignState {
                history: Vec::new(),
                ..state(s)
            })
            .collect();
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
        // What SubmitCampaign would refuse, but the search, which an analysis does not use.
        let early = self.early_problems(&campaign).await?;
        if let Some(problem) = early.iter().find(|p| !p.field.starts_with("search")) {
            return Err(problem.status());
        }
        let spec = self.campaign_spec(&campaign).await?;
        let campaigns = self.campaigns.clone();
        let receiver = self
            .blocking(move || campaigns.sensitivity(spec, settings))
            .await?;
        Ok(Response::new(follow_analysis(receiver)))
    }

    type ProfileStream = AnalysisStream;

    async fn profile(
        &self,
        request: Request<pb::ProfileRequest>,
    ) -> Result<Response<Self::ProfileStream>, Status> {
        let request = request.into_inner();
        let settings = calib_analysis::profile::Settings {
            parameters: request.parameters,
            max_steps: match request.max_steps {
                0 => calib_analysis::profile::walk::DEFAULT_MAX_STEPS,
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
