//! The `calib.v1.Calibration` gRPC service: campaigns for clients in any language. A thin
//! layer: messages are checked and converted here, the work is [`crate::campaigns`]'.

pub mod defined_effects;
pub mod discovery;
pub mod result;
pub mod spec;

use crate::campaign::MAX_EXPERIMENTS;
use crate::campaigns::analyses::AnalysisSnapshot;
use crate::campaigns::datasets::DatasetInfo;
use crate::campaigns::diagnoses::DiagnosisSnapshot;
use crate::campaigns::fmus::FmuInfo;
use crate::campaigns::{Campaigns, Phase, Snapshot, Watched};
use crate::error::Error;
use crate::limits::{MAX_DATASET_BYTES, MAX_FMU_BYTES, MAX_IDEMPOTENCY_KEY_BYTES};
use crate::report;
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
        let guessed = time_column.trim().is_empty();
        if guessed {
            time_column.clear();
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
            time_column: info.time_column,
            time_column_guessed: guessed,
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

    /// The uploaded dataset `id`, named by the message's `field`; NOT_FOUND when absent.
    async fn dataset(&self, id: &str, field: &str) -> Result<DatasetInfo, Status> {
        if id.is_empty() {
            return Err(Status::invalid_argument(format!(
                "{field}: missing; upload the data with UploadDataset first"
            )));
        }
        let found = {
            let campaigns = self.campaigns.clone();
            let id = id.to_string();
            self.blocking(move || campaigns.datasets().get(&id)).await?
        };
        found.ok_or_else(|| {
            Status::not_found(format!(
                "{field}: no dataset `{id}` on this coordinator; upload it with UploadDataset"
            ))
        })
    }

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
    async fn early_problems(&self, c: &pb::Campaign) -> Result<Vec<Problem>, Status> {
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
        let text = match self.campaign_file(c).await {
            Ok(text) => text,
            Err(s) if refused(&s) => return Ok(vec![Problem::of_refusal(&s)]),
            Err(s) => return Err(s),
        };
        let campaigns = self.campaigns.clone();
        match self
            .blocking(move || campaigns.check(&text).map(|_| ()))
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

    /// The campaign file of a campaign message, its records the uploaded datasets it names:
    /// `dataset_id`, or each experiment's.
    async fn campaign_file(&self, campaign: &pb::Campaign) -> Result<String, Status> {
        let (record, experiments) = if campaign.experiments.is_empty() {
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
        };
        if campaign.fmu_id.is_empty() {
            if fmu::interface_in_name(&campaign.model).is_some() {
                return Err(Status::invalid_argument(format!(
                    "campaign.fmu_id: missing; `{}` is an FMU's model: name the FMU by the \
                     id UploadFmu answered",
                    campaign.model
                )));
            }
            return spec::campaign_file_with(campaign, record.as_ref(), &experiments, None)
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
        spec::campaign_file_with(&campaign, record.as_ref(), &experiments, Some(&archive))
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

/// What a campaign of one record maps onto its dataset.
fn mapped_campaign(campaign: &pb::Campaign) -> Mapped<'_> {
    let mut windows = Vec::new();
    // A window of 0 to 0 is no window: the campaign's check names it missing.
    if campaign.window_start != 0.0 || campaign.window_stop != 0.0 {
        windows.push((
            "window_start".to_string(),
            "window_stop".to_string(),
            campaign.window_start,
            campaign.window_stop,
        ));
    }
    for (j, w) in campaign.windows.iter().enumerate() {
        windows.push((
            format!("windows[{j}].start"),
            format!("windows[{j}].stop"),
            w.start,
            w.stop,
        ));
    }
    Mapped {
        place: String::new(),
        outputs: &campaign.outputs,
        inputs: &campaign.inputs,
        windows,
    }
}

/// What experiment `k` of a campaign maps onto its dataset.
fn mapped_experiment(campaign: &pb::Campaign, k: usize) -> Mapped<'_> {
    let e = &campaign.experiments[k];
    let place = format!("experiments[{k}].");
    Mapped {
        place: place.clone(),
        outputs: own_or(&e.outputs, &campaign.outputs),
        inputs: own_or(&e.inputs, &campaign.inputs),
        windows: e
            .windows
            .iter()
            .enumerate()
            .map(|(j, w)| {
                (
                    format!("{place}windows[{j}].start"),
                    format!("{place}windows[{j}].stop"),
                    w.start,
                    w.stop,
                )
            })
            .collect(),
    }
}

/// An experiment's own list, or the campaign's when it has none.
fn own_or<'a, T>(own: &'a [T], campaign: &'a [T]) -> &'a [T] {
    if own.is_empty() {
        campaign
    } else {
        own
    }
}

/// What a campaign (or one of its experiments) maps onto a dataset: `place` prefixes the
/// fields named (e.g. "experiments[1]."); each window is its start's and stop's fields and
/// values.
struct Mapped<'a> {
    place: String,
    outputs: &'a [pb::Output],
    inputs: &'a [pb::Input],
    windows: Vec<(String, String, f64, f64)>,
}

/// What is wrong with a campaign, and where: a field of the Campaign message, written as a
/// path from it ("outputs[1].measured", "window_stop"; "" for the whole campaign).
#[derive(Debug, Clone, PartialEq)]
pub struct Problem {
    pub field: String,
    pub message: String,
    /// How SubmitCampaign refuses it: INVALID_ARGUMENT, or NOT_FOUND for an unknown dataset.
    pub code: tonic::Code,
}

impl Problem {
    fn new(field: impl Into<String>, message: impl Into<String>) -> Self {
        Self {
            field: field.into(),
            message: message.into(),
            code: tonic::Code::InvalidArgument,
        }
    }

    /// SubmitCampaign's refusal: the field named from the request, as every refusal does.
    fn status(&self) -> Status {
        let field = if self.field.is_empty() {
            "campaign".to_string()
        } else {
            format!("campaign.{}", self.field)
        };
        Status::new(self.code, format!("{field}: {}", self.message))
    }

    fn message(&self) -> pb::CampaignProblem {
        pb::CampaignProblem {
            field: self.field.clone(),
            message: self.message.clone(),
        }
    }

    /// The problem a refusal of the campaign's loader states: its message is "campaign.<field>:
    /// <what>" (a parameter named in the field, "parameters[0] (armFriction)", is its index
    /// alone), "data: <what>" for the dataset's file, else about the whole campaign.
    fn of_refusal(status: &Status) -> Self {
        let text = status.message();
        let (field, message) = if let Some(rest) = text.strip_prefix("campaign.") {
            match rest.split_once(": ") {
                Some((field, message)) => (field.to_string(), message.to_string()),
                None => (String::new(), rest.to_string()),
            }
        } else if let Some(rest) = text.strip_prefix("data: ") {
            ("dataset_id".to_string(), rest.to_string())
        } else {
            (String::new(), text.to_string())
        };
        let field = match field.as_str() {
            // The window as a whole: its stop, where the form's window ends.
            "window_start, campaign.window_stop" => "window_stop".to_string(),
            other => without_names(other),
        };
        Self {
            field,
            message: plain_words(&message),
            code: status.code(),
        }
    }
}

/// `field` without the names the loader adds after an index ("parameters[0] (armFriction)"
/// is "parameters[0]").
fn without_names(field: &str) -> String {
    let mut out = String::with_capacity(field.len());
    let mut rest = field;
    while let Some(at) = rest.find(" (") {
        out.push_str(&rest[..at]);
        rest = match rest[at..].find(')') {
            Some(end) => &rest[at + end + 1..],
            None => "",
        };
    }
    out.push_str(rest);
    out
}

/// A loader's message in the words of someone filling in a form rather than a campaign file.
fn plain_words(message: &str) -> String {
    [
        (
            "[[parameters]] or [[effects]] entry",
            "parameter to calibrate",
        ),
        ("[[parameters]] entry", "parameter to calibrate"),
        ("[[outputs]] entry", "output to compare"),
        ("[model.parameters]", "the model's fixed values"),
        ("[window]", "a window"),
    ]
    .iter()
    .fold(without_stored_names(message), |m, (toml, words)| {
        m.replace(toml, words)
    })
}

/// `message` with each uploaded file named as the coordinator stores it ("dataset
/// <64 hex digits>.csv") called "the measurement": the user never saw that name.
fn without_stored_names(message: &str) -> String {
    let mut out = String::with_capacity(message.len());
    let mut rest = message;
    while let Some(at) = rest.find("dataset ") {
        let after = &rest[at + "dataset ".len()..];
        let hex = after.bytes().take_while(u8::is_ascii_hexdigit).count();
        let extension = [".csv", ".txt", ".mat"]
            .iter()
            .find(|e| hex == 64 && after[hex..].starts_with(**e));
        match extension {
            Some(e) => {
                out.push_str(&rest[..at]);
                out.push_str("the measurement");
                rest = &after[hex + e.len()..];
            }
            None => {
                out.push_str(&rest[..at + "dataset ".len()]);
                rest = after;
            }
        }
    }
    out.push_str(rest);
    out
}

/// What the form of a campaign states wrong on its own, before any dataset or model is
/// looked at: every such problem, each at its field.
fn form_problems(c: &pb::Campaign) -> Vec<Problem> {
    let mut problems = Vec::new();
    if !c.experiments.is_empty() && !c.dataset_id.is_empty() {
        problems.push(Problem::new(
            "dataset_id",
            "with experiments, each experiment names its dataset; leave this one empty",
        ));
    }
    if let Some(search) = &c.search {
        if search.methods.is_empty() {
            problems.push(Problem::new("search.methods", "choose at least one method"));
        }
    }
    let no_outputs = "choose at least one output to compare with the measurement";
    if c.experiments.is_empty() {
        if c.outputs.is_empty() {
            problems.push(Problem::new("outputs", no_outputs));
        }
    } else if c.outputs.is_empty() {
        for (k, e) in c.experiments.iter().enumerate() {
            if e.outputs.is_empty() {
                problems.push(Problem::new(
                    format!("experiments[{k}].outputs"),
                    no_outputs,
                ));
            }
        }
    }
    let outputs = c
        .outputs
        .iter()
        .enumerate()
        .map(|(i, o)| (String::new(), i, o));
    let own = c.experiments.iter().enumerate().flat_map(|(k, e)| {
        e.outputs
            .iter()
            .enumerate()
            .map(move |(i, o)| (format!("experiments[{k}]."), i, o))
    });
    for (place, i, o) in outputs.chain(own) {
        if o.measured.is_empty() {
            problems.push(Problem::new(
                format!("{place}outputs[{i}].measured"),
                "choose the measured column this output is compared with",
            ));
        }
    }
    let shared_free = !c.parameters.is_empty() || !c.effects.is_empty();
    let own_free = c.experiments.iter().any(|e| !e.parameters.is_empty());
    if !shared_free && !own_free {
        problems.push(Problem::new(
            "parameters",
            "choose at least one parameter to calibrate",
        ));
    }
    let lists = [
        (String::from("parameters"), &c.parameters),
        (String::from("effects"), &c.effects),
    ];
    let own = c
        .experiments
        .iter()
        .enumerate()
        .map(|(k, e)| (format!("experiments[{k}].parameters"), &e.parameters));
    for (list, parameters) in lists.into_iter().chain(own) {
        for (i, p) in parameters.iter().enumerate() {
            problems.extend(bound_problems(&format!("{list}[{i}]"), p));
        }
    }
    if c.experiments.is_empty() {
        let (start, stop) = (c.window_start, c.window_stop);
        if c.windows.is_empty() && start == 0.0 && stop == 0.0 {
            problems.push(Problem::new(
                "window_stop",
                "give the window of the data to fit: its start and its stop",
            ));
        } else if !c.windows.is_empty() && (start != 0.0 || stop != 0.0) {
            problems.push(Problem::new(
                "windows",
                "give one window or several windows, not both",
            ));
        } else if c.windows.is_empty() {
            problems.extend(window_problems("window_start", "window_stop", start, stop));
        }
        for (j, w) in c.windows.iter().enumerate() {
            problems.extend(window_problems(
                &format!("windows[{j}].start"),
                &format!("windows[{j}].stop"),
                w.start,
                w.stop,
            ));
        }
    } else {
        for (k, e) in c.experiments.iter().enumerate() {
            if e.windows.is_empty() {
                problems.push(Problem::new(
                    format!("experiments[{k}].windows"),
                    "give the window of the data to fit: its start and its stop",
                ));
            }
            for (j, w) in e.windows.iter().enumerate() {
                problems.extend(window_problems(
                    &format!("experiments[{k}].windows[{j}].start"),
                    &format!("experiments[{k}].windows[{j}].stop"),
                    w.start,
                    w.stop,
                ));
            }
        }
    }
    problems
}

/// A free parameter's bounds, start value and scale, at `field` ("parameters[0]").
fn bound_problems(field: &str, p: &pb::Parameter) -> Vec<Problem> {
    let mut problems = Vec::new();
    if !p.min.is_finite() {
        problems.push(Problem::new(format!("{field}.min"), "give a lower bound"));
    }
    if !p.max.is_finite() {
        problems.push(Problem::new(format!("{field}.max"), "give an upper bound"));
    }
    if !problems.is_empty() {
        return problems;
    }
    if p.min >= p.max {
        problems.push(Problem::new(
            format!("{field}.max"),
            format!(
                "the upper bound {} must be above the lower bound {}",
                p.max, p.min
            ),
        ));
        return problems;
    }
    if p.scale == "log10" && p.min <= 0.0 {
        problems.push(Problem::new(
            format!("{field}.min"),
            format!(
                "a log10 scale needs a lower bound above 0 (it is {}); use the lin scale to \
                 search from 0",
                p.min
            ),
        ));
    }
    if let Some(nominal) = p.nominal {
        if !nominal.is_finite() || nominal < p.min || nominal > p.max {
            problems.push(Problem::new(
                format!("{field}.nominal"),
                format!(
                    "the start value {nominal} lies outside the bounds [{}, {}]",
                    p.min, p.max
                ),
            ));
        }
    }
    problems
}

/// A window's start and stop on their own: finite, from 0 s, the stop after the start.
fn window_problems(start_field: &str, stop_field: &str, start: f64, stop: f64) -> Vec<Problem> {
    if !start.is_finite() || start < 0.0 {
        return vec![Problem::new(
            start_field,
            format!("the window starts at {start} s; it must start at 0 s or later"),
        )];
    }
    if !stop.is_finite() || stop <= start {
        return vec![Problem::new(
            stop_field,
            format!("the window must end after it starts ({start} s); it ends at {stop} s"),
        )];
    }
    Vec::new()
}

/// The fields mapped onto a dataset checked against it, before anything is parsed or run:
/// every mapped column is one of the dataset's, the windows lie inside its data. Every
/// problem found.
fn dataset_problems(mapped: &Mapped, dataset: &DatasetInfo) -> Vec<Problem> {
    let mut problems = Vec::new();
    let columns = mapped
        .outputs
        .iter()
        .enumerate()
        .map(|(i, o)| (format!("outputs[{i}]"), &o.measured))
        .chain(
            mapped
                .inputs
                .iter()
                .enumerate()
                .map(|(i, input)| (format!("inputs[{i}]"), &input.measured)),
        );
    for (field, measured) in columns {
        // An empty choice is the form's problem, named there.
        if measured.is_empty() || dataset.columns.contains(measured) {
            continue;
        }
        let mut listed: Vec<String> = dataset
            .columns
            .iter()
            .take(LISTED_COLUMNS)
            .map(|c| format!("{c:?}"))
            .collect();
        if dataset.columns.len() > LISTED_COLUMNS {
            listed.push(format!("… ({} in all)", dataset.columns.len()));
        }
        problems.push(Problem::new(
            format!("{}{field}.measured", mapped.place),
            format!(
                "dataset {} has no column {measured:?}; its columns are: {}",
                dataset.file_name,
                listed.join(", ")
            ),
        ));
    }
    let (first, last) = (dataset.start_time, dataset.stop_time);
    let slack = 1e-9 * last.abs().max(1.0);
    let outside = |field: &str, value: f64| {
        Problem::new(
            field,
            format!(
                "{value} s lies outside the data of dataset {} (time runs from {first} to {last} \
                 s)",
                dataset.file_name
            ),
        )
    };
    for (start_field, stop_field, start, stop) in &mapped.windows {
        // A window wrong on its own is the form's problem, named there.
        if !window_problems(start_field, stop_field, *start, *stop).is_empty() {
            continue;
        }
        if *stop > last + slack {
            problems.push(outside(stop_field, *stop));
        }
        if *start < first - slack {
            problems.push(outside(start_field, *start));
        }
    }
    problems
}

/// [`dataset_problems`]' first, as the refusal of a request.
fn check_against_dataset(mapped: &Mapped, dataset: &DatasetInfo) -> Result<(), Status> {
    match dataset_problems(mapped, dataset).first() {
        Some(problem) => Err(problem.status()),
        None => Ok(()),
    }
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
            if other.starts_with("experiments[") {
                // An experiment's `window` is its message's `windows`, its `fixed.x` the
                // map's entry.
                let (head, tail) = other.split_once(").").unwrap_or((other, ""));
                let tail = match tail {
                    "window" | "window.start" | "window.stop" => "windows".to_string(),
                    t => match t.strip_prefix("fixed.") {
                        Some(name) => format!("fixed[{name:?}]"),
                        None => t.to_string(),
                    },
                };
                return if tail.is_empty() {
                    format!("campaign.{other}")
                } else {
                    format!("campaign.{head}).{tail}")
                };
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
    let (runs, best_parameters) = match &s.result {
        Some(outcome) => (
            result::run_messages(outcome),
            outcome
                .best
                .parameters
                .iter()
                .map(|(k, v)| (k.to_string(), *v))
                .collect(),
        ),
        None => {
            let rows = report::runs::rows_so_far(&s.runs, &s.free);
            let best = report::runs::best_parameters(&rows).into_iter().collect();
            (rows.into_iter().map(result::row_message).collect(), best)
        }
    };
    let at_best = runs.iter().filter(|r| r.at_best).count() as u64;
    let rounds = match &s.result {
        Some(outcome) => outcome.rounds,
        None => {
            let each: Vec<usize> = runs.iter().map(|r| r.rounds as usize).collect();
            crate::optim::multistart::plan_rounds(&each) as u64
        }
    };
    pb::CampaignState {
        rounds,
        campaign: s
            .message
            .clone()
            .and_then(|m| serde_json::from_value(m).ok()),
        history: s
            .history
            .points()
            .iter()
            .map(|p| pb::ProgressPoint {
                evaluations: p.evaluations,
                run_best: p
                    .run_best
                    .iter()
                    .map(|v| v.unwrap_or(f64::INFINITY))
                    .collect(),
            })
            .collect(),
        runs_at_best: Some(pb::RunsAtBest {
            count: at_best,
            of: runs.len() as u64,
            tolerance: crate::evidence::BEST_TOLERANCE,
        }),
        runs,
        simulated: s.result.as_ref().map(|o| o.simulated).unwrap_or_default(),
        from_store: s
            .result
            .as_ref()
            .map(|o| o.from_store())
            .unwrap_or_default(),
        best_parameters,
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
            .map(|o| o.to_json_text())
            .unwrap_or_default(),
        result: s.result.as_ref().map(result::result_message),
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
        found_outside_the_library: s.found.as_deref().map(discovery::found_message),
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
        // Refused for what ValidateCampaign reports, the same checks on the same code.
        if let Some(problem) = self.early_problems(&campaign).await?.first() {
            return Err(problem.status());
        }
        let text = self.campaign_file(&campaign).await?;
        let campaigns = self.campaigns.clone();
        let key = Some(request.idempotency_key).filter(|k| !k.is_empty());
        let message = serde_json::to_value(&campaign).ok();
        let (id, started) = self
            .blocking(move || campaigns.submit_message(&text, key.as_deref(), message))
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
