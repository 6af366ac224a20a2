//! A campaign message made the campaign file SubmitCampaign starts, with the uploaded
//! datasets and FMU it names; and the problems found before (ValidateCampaign's answer,
//! SubmitCampaign's and Sensitivity's refusals).

use super::problem::Problem;
use super::validation::{
    check_against_dataset, dataset_problems, form_problems, mapped_campaign, mapped_experiment,
};
use super::{defined_effects, spec, CalibrationApi};
use crate::hosting::datasets::DatasetInfo;
use calib_engine::campaign::{CampaignSpec, MAX_EXPERIMENTS};
use calib_model::fmu;
use calib_proto::v1 as pb;
use tonic::Status;

impl CalibrationApi {
    /// The dataset `id` a campaign names at `field` ("dataset_id"), or the problem it is.
    async fn named_dataset(
        &self,
        id: &str,
        field: &str,
    ) -> Result<Result<DatasetInfo, Problem>, Status> {
        if id.is_empty() {
            return Ok(Err(Problem::new(
                field,
                "missing: upload a measurement first",
            )));
        }
        let found = {
            let campaigns = self.campaigns.clone();
            let id = id.to_string();
            self.blocking(move || campaigns.datasets().get(&id)).await
        };
        Ok(match found {
            Ok(Some(dataset)) => Ok(dataset),
            Ok(None) => Err(Problem {
                code: tonic::Code::NotFound,
                ..Problem::new(
                    field,
                    "no dataset with this id on this server: upload the measurement again",
                )
            }),
            Err(s) if s.code() == tonic::Code::InvalidArgument => {
                Err(Problem::new(field, s.message()))
            }
            Err(s) => return Err(s),
        })
    }

    /// Every problem of campaign `c` found before its campaign file is written: the form's
    /// own ([`form_problems`]), then its datasets' (each named, each holding the columns
    /// and the windows mapped onto it).
    pub(super) async fn early_problems(&self, c: &pb::Campaign) -> Result<Vec<Problem>, Status> {
        let mut problems = form_problems(c);
        if c.experiments.is_empty() {
            match self.named_dataset(&c.dataset_id, "dataset_id").await? {
                Err(problem) => problems.push(problem),
                Ok(dataset) => problems.extend(dataset_problems(&mapped_campaign(c), &dataset)),
            }
        } else {
            for (k, e) in c.experiments.iter().enumerate() {
                let field = format!("experiments[{k}].dataset_id");
                match self.named_dataset(&e.dataset_id, &field).await? {
                    Err(problem) => problems.push(problem),
                    Ok(dataset) => {
                        problems.extend(dataset_problems(&mapped_experiment(c, k), &dataset))
                    }
                }
            }
        }
        Ok(problems)
    }

    /// Every problem that makes SubmitCampaign refuse campaign `c`, each at its field, in
    /// SubmitCampaign's order: the form's and the datasets' ([`Self::early_problems`]);
    /// when there are none, the first the campaign's loader finds in the campaign file
    /// SubmitCampaign would start (the model, its parameters and outputs, the solver, the
    /// window against the data). Nothing is started. An error only when the server fails.
    pub async fn validate(&self, c: &pb::Campaign) -> Result<Vec<Problem>, Status> {
        let early = self.early_problems(c).await?;
        if !early.is_empty() {
            return Ok(early);
        }
        let refused = |s: &Status| {
            matches!(
                s.code(),
                tonic::Code::InvalidArgument | tonic::Code::NotFound
            )
        };
        let spec = match self.campaign_spec(c).await {
            Ok(spec) => spec,
            Err(s) if refused(&s) => return Ok(vec![Problem::of_refusal(&s)]),
            Err(s) => return Err(s),
        };
        let campaigns = self.campaigns.clone();
        match self
            .blocking(move || campaigns.check(spec).map(|_| ()))
            .await
        {
            Ok(()) => Ok(Vec::new()),
            Err(s) if refused(&s) => {
                let mut problem = Problem::of_refusal(&s);
                problem.field = defined_effects::message_field(c, &problem.field);
                Ok(vec![problem])
            }
            Err(s) => Err(s),
        }
    }

    /// The dataset as the campaign file names it.
    fn record(&self, dataset: &DatasetInfo) -> spec::Record {
        spec::Record {
            file: self.campaigns.datasets().file(dataset),
            time_column: dataset.time_column.clone(),
        }
    }

    /// The campaign of a campaign message, its records the uploaded datasets it names:
    /// `dataset_id`, or each experiment's.
    pub(super) async fn campaign_spec(
        &self,
        campaign: &pb::Campaign,
    ) -> Result<CampaignSpec, Status> {
        let (record, experiments) = self.records(campaign).await?;
        if campaign.fmu_id.is_empty() {
            if fmu::interface_in_name(&campaign.model).is_some() {
                return Err(Status::invalid_argument(format!(
                    "campaign.fmu_id: missing; `{}` is an FMU's model: name the FMU by the \
                     id UploadFmu answered",
                    campaign.model
                )));
            }
            return spec::campaign_spec_with(campaign, record.as_ref(), &experiments, None)
                .map_err(Status::invalid_argument);
        }
        let (campaign, archive) = self.on_fmu(campaign).await?;
        spec::campaign_spec_with(&campaign, record.as_ref(), &experiments, Some(&archive))
            .map_err(Status::invalid_argument)
    }

    /// The records of a campaign message, each checked against its dataset: the one of
    /// `dataset_id`, or each experiment's.
    async fn records(
        &self,
        campaign: &pb::Campaign,
    ) -> Result<(Option<spec::Record>, Vec<spec::Record>), Status> {
        Ok(if campaign.experiments.is_empty() {
            let dataset = self
                .dataset(&campaign.dataset_id, "campaign.dataset_id")
                .await?;
            let mapped = mapped_campaign(campaign);
            check_against_dataset(&mapped, &dataset)?;
            (Some(self.record(&dataset)), Vec::new())
        } else {
            if !campaign.dataset_id.is_empty() {
                return Err(Status::invalid_argument(
                    "campaign.dataset_id: with experiments, each experiment names its dataset \
                     (experiments[k].dataset_id); leave this one empty",
                ));
            }
            if campaign.experiments.len() > MAX_EXPERIMENTS {
                return Err(Status::invalid_argument(format!(
                    "campaign.experiments: {} experiments, more than the {MAX_EXPERIMENTS} \
                     accepted",
                    campaign.experiments.len()
                )));
            }
            let mut records = Vec::with_capacity(campaign.experiments.len());
            for (k, e) in campaign.experiments.iter().enumerate() {
                let place = format!("experiments[{k}].");
                let dataset = self
                    .dataset(&e.dataset_id, &format!("campaign.{place}dataset_id"))
                    .await?;
                let mapped = mapped_experiment(campaign, k);
                check_against_dataset(&mapped, &dataset)?;
                records.push(self.record(&dataset));
            }
            (None, records)
        })
    }

    /// A campaign message on the uploaded FMU it names, its model checked to be one of the
    /// FMU's and its interface the one that model runs through; and the FMU's archive.
    async fn on_fmu(
        &self,
        campaign: &pb::Campaign,
    ) -> Result<(pb::Campaign, std::path::PathBuf), Status> {
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
        Ok((campaign, archive))
    }
}
