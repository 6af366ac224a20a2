//! One worker as the dispatcher sees it: prost types stop here.

use super::error::WorkerError;
use calib_engine::evaluator::Outputs;
use calib_engine::objective::{Evaluation, Objective};
use calib_model::inputs::Interpolation;
use calib_model::scoring;
use calib_proto::v1 as proto;
use calib_proto::v1::simulator_client::SimulatorClient;
use calib_security::{ClientSecurity, SecureChannel};
use calib_worker::service::limits::MAX_MESSAGE_BYTES;
use std::sync::Arc;
use std::time::Duration;
use tonic_health::pb::health_client::HealthClient;

/// What a probe learns about a worker.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct WorkerStatus {
    pub slots: usize,
    /// Points queued beyond the slots before a request is refused.
    pub queue_bound: usize,
}

/// An objective of one experiment in the form workers take it, built once per objective.
pub struct WireObjective {
    /// Everything but the points and the measurement.
    pub template: proto::EvaluateRequest,
    /// The entries of a point this experiment's free parameters take (the others belong
    /// to other experiments).
    pub uses: Vec<usize>,
    pub measurement: proto::Measurement,
    pub outputs: usize,
    /// The archive of an FMU model, uploaded to a worker that lacks it.
    pub fmu: Option<Arc<Vec<u8>>>,
}

/// The content hash and archive of `model` when it is an FMU.
fn fmu_of(model: &str) -> (Vec<u8>, Option<Arc<Vec<u8>>>) {
    match calib_model::fmu::archive_of(model) {
        Some((hash, archive)) => (hash.to_vec(), Some(archive)),
        None => (Vec::new(), None),
    }
}

/// Driving signals as the wire carries them.
pub fn wire_inputs(objective: &Objective) -> Vec<proto::InputSeries> {
    objective
        .named_inputs()
        .into_iter()
        .map(|s| proto::InputSeries {
            input: s.name,
            times: s.times.to_vec(),
            values: s.values.to_vec(),
            interpolation: match s.interpolation {
                Interpolation::Linear => proto::Interpolation::Linear,
                Interpolation::Hold => proto::Interpolation::Hold,
            }
            .into(),
        })
        .collect()
}

/// The user-defined effects of the objective's model, sent as text with every request.
fn wire_effects(objective: &Objective) -> Vec<proto::UserEffect> {
    let effects = objective.model.user_effects();
    effects.iter().map(calib_worker::wire::to_proto).collect()
}

impl WireObjective {
    pub fn new(objective: &Objective) -> Self {
        let info = objective.model.info();
        let (fmu_hash, fmu) = fmu_of(&info.name);
        let parameters = objective
            .base
            .iter()
            .enumerate()
            .map(|(i, &value)| proto::ParameterValue {
                name: info.name_at(i).to_string(),
                value,
            })
            .collect();
        let template = proto::EvaluateRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            model: info.name.clone(),
            parameters,
            free_parameters: objective
                .free
                .iter()
                .flatten()
                .map(|&i| info.name_at(i).to_string())
                .collect(),
            outputs: objective
                .outputs
                .iter()
                .zip(&objective.weights)
                .map(|(&o, &weight)| proto::ComparedOutput {
                    output: info.outputs[o].name.clone(),
                    weight,
                })
                .collect(),
            measurement_hash: scoring::measurement_hash(
                &objective.grid,
                &objective.measured,
                &objective.named_inputs(),
            )
            .to_vec(),
            measurement: None,
            points: Vec::new(),
            solver: Some(wire_solver(&objective.solver)),
            fmu_hash,
            residuals: objective.returns_residuals(),
            effects: wire_effects(objective),
        };
        let measurement = proto::Measurement {
            times: objective.grid.clone(),
            columns: objective
                .measured
                .iter()
                .map(|values| proto::Column {
                    values: values.clone(),
                })
                .collect(),
            inputs: wire_inputs(objective),
        };
        Self {
            template,
            uses: (0..objective.free.len())
                .filter(|&k| objective.free[k].is_some())
                .collect(),
            measurement,
            outputs: objective.outputs.len(),
            fmu,
        }
    }

    /// Numbers of the record it carries to workers.
    pub fn record_values(&self) -> usize {
        let m = &self.measurement;
        let columns: usize = m.columns.iter().map(|c| c.values.len()).sum();
        let inputs: usize = m
            .inputs
            .iter()
            .map(|i| i.times.len() + i.values.len())
            .sum();
        m.times.len() + columns + inputs
    }

    /// Most points one `Evaluate` request may carry: the worker's bound, and with residuals
    /// as many as one answer holds.
    pub fn points_per_request(&self) -> usize {
        let most = calib_model::limits::MAX_POINTS;
        if !self.template.residuals {
            return most;
        }
        let each = self.measurement.times.len() * self.outputs;
        (calib_model::limits::MAX_ANSWER_VALUES / each.max(1)).clamp(1, most)
    }

    /// The values of `point` this experiment's free parameters take.
    pub fn project(&self, point: Vec<f64>) -> Vec<f64> {
        if self.uses.len() == point.len() {
            return point;
        }
        self.uses.iter().map(|&k| point[k]).collect()
    }
}

/// The objective's solver options as a request carries them: every field set.
fn wire_solver(solver: &calib_model::SolverOptions) -> proto::SolverOptions {
    proto::SolverOptions {
        rtol: Some(solver.rtol),
        atol: Some(solver.atol),
        max_steps: Some(solver.max_steps as u64),
        start_time: Some(solver.start_time),
        communication_step: solver.communication_step,
    }
}

/// A simulation of an objective's mapped outputs on its grid, in the form workers take it:
/// each point becomes one `Simulate` request with every parameter set by name, so that the
/// worker simulates exactly what [`Objective::simulate`] would, bit for bit.
pub struct WireSimulation {
    /// Everything but the parameters.
    pub template: proto::SimulateRequest,
    /// The archive of an FMU model, uploaded to a worker that lacks it.
    fmu: Option<Arc<Vec<u8>>>,
    /// Name of each entry of the full parameter vector.
    names: Vec<String>,
    /// The full parameter vector and where the free entries go, as in the objective.
    base: Vec<f64>,
    free: Vec<Option<usize>>,
}

impl WireSimulation {
    pub fn new(objective: &Objective) -> Self {
        let info = objective.model.info();
        let (fmu_hash, fmu) = fmu_of(&info.name);
        let template = proto::SimulateRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            model: info.name.clone(),
            parameters: Vec::new(),
            times: objective.grid.clone(),
            outputs: objective
                .outputs
                .iter()
                .map(|&o| info.outputs[o].name.clone())
                .collect(),
            solver: Some(wire_solver(&objective.solver)),
            fmu_hash,
            inputs: wire_inputs(objective),
            effects: wire_effects(objective),
        };
        Self {
            template,
            fmu,
            names: (0..objective.base.len())
                .map(|i| info.name_at(i).to_string())
                .collect(),
            base: objective.base.clone(),
            free: objective.free.clone(),
        }
    }

    /// The request for the free parameters at `point`.
    fn request(&self, point: &[f64]) -> proto::SimulateRequest {
        let mut full = self.base.clone();
        for (i, &value) in self.free.iter().zip(point) {
            if let Some(i) = i {
                full[*i] = value;
            }
        }
        let mut request = self.template.clone();
        request.parameters = self
            .names
            .iter()
            .zip(full)
            .map(|(name, value)| proto::ParameterValue {
                name: name.clone(),
                value,
            })
            .collect();
        request
    }
}

#[derive(Clone)]
pub struct WorkerClient {
    url: String,
    simulator: SimulatorClient<SecureChannel>,
    health: HealthClient<SecureChannel>,
}

impl WorkerClient {
    /// A client for the worker at `url`, dialed with `security` (an `https://` worker is
    /// verified as `server_name`, by default the URL's host); connects on first use and
    /// reconnects as needed.
    pub fn new(
        url: &str,
        security: &ClientSecurity,
        server_name: Option<&str>,
    ) -> Result<Self, String> {
        let channel = security
            .endpoint(url, server_name)
            .map_err(|e| format!("`{url}` is not a worker URL: {e}"))?
            .connect_timeout(Duration::from_secs(3))
            .tcp_nodelay(true)
            .http2_keep_alive_interval(Duration::from_secs(10))
            .keep_alive_timeout(Duration::from_secs(10))
            .keep_alive_while_idle(true)
            .connect_lazy();
        let channel = security.authorize(channel);
        Ok(Self {
            url: url.to_string(),
            simulator: SimulatorClient::new(channel.clone())
                .max_decoding_message_size(MAX_MESSAGE_BYTES)
                .max_encoding_message_size(MAX_MESSAGE_BYTES),
            health: HealthClient::new(channel),
        })
    }

    pub fn url(&self) -> &str {
        &self.url
    }

    /// Health check, then the worker's capacity.
    pub async fn probe(&self, deadline: Duration) -> Result<WorkerStatus, WorkerError> {
        use tonic_health::pb::health_check_response::ServingStatus;
        let mut request = tonic::Request::new(tonic_health::pb::HealthCheckRequest {
            service: "calib.v1.Simulator".into(),
        });
        request.set_timeout(deadline);
        let health = self.health.clone().check(request).await?.into_inner();
        if health.status != ServingStatus::Serving as i32 {
            return Err(WorkerError::Unavailable("not serving".into()));
        }
        let mut request = tonic::Request::new(proto::StatusRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
        });
        request.set_timeout(deadline);
        let status = self.simulator.clone().status(request).await?.into_inner();
        if status.protocol_version != calib_proto::PROTOCOL_VERSION {
            return Err(WorkerError::Incompatible(format!(
                "worker speaks protocol {}, this coordinator {}",
                status.protocol_version,
                calib_proto::PROTOCOL_VERSION
            )));
        }
        Ok(WorkerStatus {
            slots: (status.slots as usize).max(1),
            queue_bound: status.queue_bound as usize,
        })
    }

    /// Score `points` of `objective`; the measurement is sent along only when the worker
    /// answers that it lacks it.
    pub async fn evaluate(
        &self,
        objective: &WireObjective,
        points: Vec<Vec<f64>>,
        deadline: Duration,
    ) -> Result<Vec<Evaluation>, WorkerError> {
        let count = points.len();
        let mut message = objective.template.clone();
        message.points = points
            .into_iter()
            .map(|values| proto::Point {
                values: objective.project(values),
            })
            .collect();
        // At most one FMU upload and one measurement upload, in whichever order they are
        // asked for.
        let mut tries = 0;
        let answer = loop {
            tries += 1;
            match self.call(message.clone(), deadline).await {
                Err(WorkerError::MeasurementMissing) if message.measurement.is_none() => {
                    tracing::debug!(worker = %self.url, "uploading the measurement");
                    message.measurement = Some(objective.measurement.clone());
                }
                Err(WorkerError::FmuMissing) if tries <= 2 => {
                    self.upload_fmu(objective.fmu.as_deref(), deadline).await?;
                }
                other => break other?,
            }
        };
        if answer.results.len() != count {
            return Err(WorkerError::Malformed(format!(
                "{} results for {count} points",
                answer.results.len()
            )));
        }
        Ok(answer
            .results
            .into_iter()
            .map(|r| match r.failure {
                Some(failure) => Evaluation::failed(objective.outputs, failure.message),
                None => Evaluation {
                    objective: r.objective,
                    sse: r.sse,
                    failure: None,
                    residuals: r.residuals,
                },
            })
            .collect())
    }

    /// The mapped outputs of `simulation` at `point`; a failed simulation is an `Err` of
    /// the outputs, not of the call.
    pub async fn simulate(
        &self,
        simulation: &WireSimulation,
        point: &[f64],
        deadline: Duration,
    ) -> Result<Outputs, WorkerError> {
        let call = || {
            let mut request = tonic::Request::new(simulation.request(point));
            request.set_timeout(deadline);
            let mut simulator = self.simulator.clone();
            async move { simulator.simulate(request).await }
        };
        let answer = match call().await.map_err(WorkerError::from) {
            Err(WorkerError::FmuMissing) => {
                self.upload_fmu(simulation.fmu.as_deref(), deadline).await?;
                call().await?
            }
            other => other?,
        }
        .into_inner();
        if let Some(failure) = answer.failure {
            return Ok(Err(failure.message));
        }
        let (outputs, times) = (
            simulation.template.outputs.len(),
            simulation.template.times.len(),
        );
        if answer.series.len() != outputs || answer.series.iter().any(|s| s.values.len() != times) {
            return Err(WorkerError::Malformed(format!(
                "{} series for {outputs} outputs of {times} times",
                answer.series.len()
            )));
        }
        Ok(Ok(answer.series.into_iter().map(|s| s.values).collect()))
    }

    /// Send an FMU to the worker (which asked for it).
    async fn upload_fmu(
        &self,
        fmu: Option<&Vec<u8>>,
        deadline: Duration,
    ) -> Result<(), WorkerError> {
        let Some(fmu) = fmu else {
            return Err(WorkerError::Malformed(
                "the worker asks for an FMU the request does not name".into(),
            ));
        };
        tracing::debug!(worker = %self.url, bytes = fmu.len(), "uploading the FMU");
        let mut request = tonic::Request::new(proto::UploadFmuRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            fmu: fmu.clone(),
        });
        request.set_timeout(deadline);
        self.simulator.clone().upload_fmu(request).await?;
        Ok(())
    }

    async fn call(
        &self,
        message: proto::EvaluateRequest,
        deadline: Duration,
    ) -> Result<proto::EvaluateResponse, WorkerError> {
        let mut request = tonic::Request::new(message);
        request.set_timeout(deadline);
        Ok(self.simulator.clone().evaluate(request).await?.into_inner())
    }
}
