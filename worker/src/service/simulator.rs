//! The `calib.v1.Simulator` handlers: decode and check, run on the simulation pool,
//! encode. The models and the scoring do the work.

use super::cache::MeasurementCache;
use super::error::{Error, Result};
use super::fmu_cache::FmuCache;
use super::pool::{PoolLoad, SimulationPool};
use super::request::{self, driving_inputs, Evaluation, MeasuredData, Simulation};
use calib_model::fmu::{self, archive};
use calib_model::scoring::{self, Target, FAILURE_PENALTY};
use calib_model::Run;
use calib_model::{models, Model, SimulationError};
use calib_proto::v1 as proto;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use tonic::{Request, Response, Status};

pub struct SimulatorService {
    pool: SimulationPool,
    cache: MeasurementCache,
    evaluations: AtomicU64,
    /// Uploaded FMUs, on a worker that accepts them (`--allow-fmu`).
    fmus: Option<FmuCache>,
}

impl SimulatorService {
    pub fn new(pool: SimulationPool, cache: MeasurementCache) -> Self {
        Self {
            pool,
            cache,
            evaluations: AtomicU64::new(0),
            fmus: None,
        }
    }

    /// Accept FMUs, kept in `fmus` (`None`: refuse them with `PERMISSION_DENIED`).
    pub fn with_fmus(mut self, fmus: Option<FmuCache>) -> Self {
        self.fmus = fmus;
        self
    }

    /// Make the FMU a request names by `fmu_hash` known under its model name: from this
    /// process's models, or from the FMU cache. Nothing to do for a hosted model.
    fn resolve_fmu(&self, model: &str, hash: &[u8]) -> Result<()> {
        if hash.is_empty() {
            return Ok(());
        }
        let Some(cache) = &self.fmus else {
            return Err(Error::FmuRefused {
                field: "fmu_hash".into(),
            });
        };
        let hash: [u8; 32] = hash
            .try_into()
            .map_err(|_| Error::invalid("fmu_hash", format!("{} bytes, not 32", hash.len())))?;
        if fmu::hash_of(model) == Some(hash) {
            return Ok(());
        }
        let interface = fmu::interface_in_name(model).ok_or_else(|| {
            Error::invalid(
                "model",
                format!("`{model}` is not an FMU's model name (as UploadFmu answers them)"),
            )
        })?;
        let bytes = cache
            .get(&hash)
            .ok_or_else(|| Error::FmuMissing { hash: hex(&hash) })?;
        let opened = fmu::open_in(&bytes, Some(interface), &cache.unpacked(), &cache.limits())
            .map_err(|e| Error::invalid("fmu_hash", e.to_string()))?;
        drop(bytes);
        fmu::remember_archive(&hash, &cache.path(&hash));
        if opened.info().name != model {
            return Err(Error::invalid(
                "model",
                format!(
                    "the FMU {} is `{}`, not `{model}`",
                    hex(&hash),
                    opened.info().name
                ),
            ));
        }
        Ok(())
    }

    fn upload_fmu(&self, request: proto::UploadFmuRequest) -> Result<proto::UploadFmuResponse> {
        request::check_protocol(request.protocol_version)?;
        let Some(cache) = &self.fmus else {
            return Err(Error::FmuRefused {
                field: "fmu".into(),
            });
        };
        let limits = cache.limits();
        archive::check_size(request.fmu.len() as u64, &limits)
            .map_err(|e| Error::invalid("fmu", e.to_string()))?;
        let hash = fmu::content_hash(&request.fmu);
        let models = fmu::open_all_in(&request.fmu, &cache.unpacked(), &limits)
            .map_err(|e| Error::invalid("fmu", e.to_string()))?;
        cache
            .put(&hash, &request.fmu)
            .map_err(|e| Error::Internal(format!("cannot keep the FMU: {e}")))?;
        // Kept on disk from now on: the request's bytes go with the request.
        fmu::remember_archive(&hash, &cache.path(&hash));
        tracing::info!(fmu = %hex(&hash), bytes = request.fmu.len(), "fmu uploaded");
        Ok(proto::UploadFmuResponse {
            fmu_hash: hash.to_vec(),
            models: models.iter().map(|m| m.info().name.clone()).collect(),
        })
    }

    pub fn load(&self) -> PoolLoad {
        self.pool.load()
    }

    async fn simulate(&self, request: proto::SimulateRequest) -> Result<proto::SimulateResponse> {
        self.resolve_fmu(&request.model, &request.fmu_hash)?;
        let Simulation {
            model,
            params,
            times,
            outputs,
            solver,
            inputs,
        } = Simulation::try_from(request)?;
        let admission = self.pool.admit(1)?;
        let times = Arc::new(times);
        let grid = times.clone();
        let wanted = outputs.clone();
        let outcome = self
            .pool
            .run(&admission, 1, move |_| {
                model.simulate(&Run::new(&params, &grid, &wanted, &solver).driven(&inputs))
            })
            .await?
            .pop()
            .expect("one simulation");
        let info = model.info();
        let times = Arc::unwrap_or_clone(times);
        Ok(match outcome {
            Ok(trajectory) => proto::SimulateResponse {
                times,
                series: outputs
                    .iter()
                    .zip(trajectory.values)
                    .map(|(&o, values)| proto::Series {
                        output: info.outputs[o].name.clone(),
                        values,
                    })
                    .collect(),
                failure: None,
                statistics: Some(proto::SolverStatistics {
                    accepted_steps: trajectory.stats.accepted_steps as u64,
                    rejected_steps: trajectory.stats.rejected_steps as u64,
                    rhs_evaluations: trajectory.stats.rhs_evaluations as u64,
                    events: trajectory.stats.events as u64,
                }),
            },
            Err(e) => proto::SimulateResponse {
                times,
                series: Vec::new(),
                failure: Some(failure(&e)),
                statistics: None,
            },
        })
    }

    async fn evaluate(&self, request: proto::EvaluateRequest) -> Result<proto::EvaluateResponse> {
        self.resolve_fmu(&request.model, &request.fmu_hash)?;
        let mut evaluation = Evaluation::try_from(request)?;
        let measured = self.measurement(&mut evaluation)?;
        let stop = measured.times[measured.times.len() - 1];
        let inputs = Arc::new(driving_inputs(
            evaluation.model,
            &measured.inputs,
            evaluation.solver.start_time,
            stop,
            "measurement.inputs",
        )?);
        let count = evaluation.points.len();
        if evaluation.residuals {
            let each = measured.times.len() * evaluation.outputs.len();
            super::request::answer_fits("points", count, each)?;
        }
        let admission = self.pool.admit(count)?;
        let evaluation = Arc::new(evaluation);
        let outcomes = {
            let evaluation = evaluation.clone();
            self.pool
                .run(&admission, count, move |i| {
                    let target = Target {
                        grid: &measured.times,
                        outputs: &evaluation.outputs,
                        measured: &measured.columns,
                        weights: &evaluation.weights,
                        solver: &evaluation.solver,
                        inputs: &inputs,
                        residuals: evaluation.residuals,
                    };
                    scoring::simulate_and_score(
                        evaluation.model,
                        &evaluation.parameters(i),
                        &target,
                    )
                })
                .await?
        };
        let mut results = Vec::with_capacity(count);
        for outcome in outcomes {
            results.push(point_result(outcome, evaluation.outputs.len()));
        }
        self.evaluations.fetch_add(count as u64, Ordering::Relaxed);
        Ok(proto::EvaluateResponse {
            results,
            measurement_hash: evaluation.measurement_hash.to_vec(),
        })
    }

    /// The measurement an evaluation compares with: the one it carries (now cached), else the
    /// cached one of its hash; an error when it is not cached or its columns are not the
    /// evaluation's outputs.
    fn measurement(&self, evaluation: &mut Evaluation) -> Result<Arc<MeasuredData>> {
        let measured = match evaluation.measurement.take() {
            Some(data) => self.cache.insert(evaluation.measurement_hash, data),
            None => self
                .cache
                .get(&evaluation.measurement_hash)
                .ok_or_else(|| Error::MeasurementMissing {
                    hash: hex(&evaluation.measurement_hash),
                })?,
        };
        if measured.columns.len() != evaluation.outputs.len() {
            return Err(Error::invalid(
                "outputs",
                format!(
                    "{} outputs compared with a measurement of {} columns",
                    evaluation.outputs.len(),
                    measured.columns.len()
                ),
            ));
        }
        Ok(measured)
    }

    fn status(&self) -> proto::StatusResponse {
        let load = self.pool.load();
        let (measurements, bytes) = self.cache.usage();
        proto::StatusResponse {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            release: env!("CARGO_PKG_VERSION").into(),
            slots: load.slots as u32,
            queue_bound: load.queue_bound as u32,
            running: load.running as u32,
            queued: load.queued as u32,
            simulations: load.completed,
            evaluations: self.evaluations.load(Ordering::Relaxed),
            cached_measurements: measurements as u32,
            cached_bytes: bytes as u64,
        }
    }
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// One point's result as the protocol reports it: its score, or the failure penalty with NaN
/// errors for each of its `outputs` when the simulation failed.
fn point_result(
    outcome: std::result::Result<scoring::Evaluation, SimulationError>,
    outputs: usize,
) -> proto::PointResult {
    match outcome {
        Ok(e) => proto::PointResult {
            objective: e.objective,
            sse: e.sse,
            residuals: e.residuals,
            failure: e.failure.map(|message| proto::SimulationFailure {
                kind: proto::simulation_failure::Kind::NonFiniteOutput.into(),
                message,
                time: f64::NAN,
            }),
        },
        Err(e) => proto::PointResult {
            objective: FAILURE_PENALTY,
            sse: vec![f64::NAN; outputs],
            failure: Some(failure(&e)),
            residuals: Vec::new(),
        },
    }
}

/// A failed simulation as the protocol reports it.
fn failure(e: &SimulationError) -> proto::SimulationFailure {
    use proto::simulation_failure::Kind;
    let (kind, time) = match e {
        SimulationError::StepLimit { time, .. } => (Kind::StepLimit, *time),
        SimulationError::StepTooSmall { time } => (Kind::StepTooSmall, *time),
        SimulationError::Diverged { time } => (Kind::Diverged, *time),
        SimulationError::Chattering { time, .. } => (Kind::Unspecified, *time),
        SimulationError::InvalidInput(_) => (Kind::Unspecified, f64::NAN),
        SimulationError::Failed { time, .. } => (Kind::Unspecified, *time),
    };
    proto::SimulationFailure {
        kind: kind.into(),
        message: e.to_string(),
        time,
    }
}

pub fn describe(model: &dyn Model) -> proto::ModelDescription {
    let info = model.info();
    let solver = model.default_options();
    proto::ModelDescription {
        default_solver: Some(proto::SolverOptions {
            rtol: Some(solver.rtol),
            atol: Some(solver.atol),
            max_steps: Some(solver.max_steps as u64),
            start_time: Some(solver.start_time),
            communication_step: solver.communication_step,
        }),
        tolerance_origin: model.tolerance_origin().to_string(),
        default_stop_time: model.default_stop_time(),
        places: model
            .places()
            .into_iter()
            .map(|p| proto::PlaceDescription {
                kind: p.kind.word().into(),
                name: p.name,
                description: p.description,
            })
            .collect(),
        inputs: info
            .inputs
            .iter()
            .map(|i| proto::InputDescription {
                name: i.name.clone(),
                unit: i.unit.clone(),
                description: i.description.clone(),
            })
            .collect(),
        name: info.name.clone(),
        version: info.version,
        description: info.description.clone(),
        parameters: info
            .parameters
            .iter()
            .map(|p| proto::ParameterDescription {
                name: p.name.clone(),
                unit: p.unit.clone(),
                default_value: p.default,
                min: p.min,
                max: p.max,
                description: p.description.clone(),
                alias_of: String::new(),
            })
            .collect(),
        outputs: info
            .outputs
            .iter()
            .map(|o| proto::OutputDescription {
                name: o.name.clone(),
                unit: o.unit.clone(),
                description: o.description.clone(),
            })
            .collect(),
        effects: info
            .effects
            .iter()
            .map(|e| {
                // An effect that is a base parameter: its value is that parameter's.
                let aliased = e
                    .parameter
                    .as_deref()
                    .and_then(|name| info.parameters.iter().find(|p| p.name == name));
                let (min, max) = aliased.map_or((e.min, e.max), |p| (p.min, p.max));
                proto::ParameterDescription {
                    name: e.name.clone(),
                    unit: e.unit.clone(),
                    default_value: aliased.map_or(0.0, |p| p.default),
                    min,
                    max,
                    description: e.description.clone(),
                    alias_of: aliased.map_or_else(String::new, |p| p.name.clone()),
                }
            })
            .collect(),
    }
}

#[tonic::async_trait]
impl proto::simulator_server::Simulator for SimulatorService {
    async fn list_models(
        &self,
        request: Request<proto::ListModelsRequest>,
    ) -> Result<Response<proto::ListModelsResponse>, Status> {
        request::check_read_protocol(request.get_ref().protocol_version)?;
        let models = models::all().iter().map(|m| describe(m.as_ref())).collect();
        Ok(Response::new(proto::ListModelsResponse { models }))
    }

    async fn describe(
        &self,
        request: Request<proto::DescribeRequest>,
    ) -> Result<Response<proto::DescribeResponse>, Status> {
        let request = request.into_inner();
        request::check_read_protocol(request.protocol_version)?;
        let model = request::hosted_model(&request.model)?;
        Ok(Response::new(proto::DescribeResponse {
            model: Some(describe(model)),
        }))
    }

    async fn simulate(
        &self,
        request: Request<proto::SimulateRequest>,
    ) -> Result<Response<proto::SimulateResponse>, Status> {
        Ok(Response::new(self.simulate(request.into_inner()).await?))
    }

    async fn evaluate(
        &self,
        request: Request<proto::EvaluateRequest>,
    ) -> Result<Response<proto::EvaluateResponse>, Status> {
        Ok(Response::new(self.evaluate(request.into_inner()).await?))
    }

    async fn status(
        &self,
        request: Request<proto::StatusRequest>,
    ) -> Result<Response<proto::StatusResponse>, Status> {
        request::check_read_protocol(request.get_ref().protocol_version)?;
        Ok(Response::new(self.status()))
    }

    async fn upload_fmu(
        &self,
        request: Request<proto::UploadFmuRequest>,
    ) -> Result<Response<proto::UploadFmuResponse>, Status> {
        Ok(Response::new(self.upload_fmu(request.into_inner())?))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use calib_model::limits::{MAX_MESSAGE_BYTES, MAX_POINTS, MAX_TIMES};
    use prost::Message;

    /// The answer to a Simulate request of the longest grid and every output of `model`.
    fn largest_simulate_response(model: &dyn Model) -> proto::SimulateResponse {
        let times: Vec<f64> = (0..MAX_TIMES).map(|i| i as f64 * 1.1).collect();
        proto::SimulateResponse {
            series: model
                .info()
                .outputs
                .iter()
                .map(|o| proto::Series {
                    output: o.name.clone(),
                    values: times.iter().map(|t| t.sin()).collect(),
                })
                .collect(),
            times,
            failure: None,
            statistics: Some(proto::SolverStatistics {
                accepted_steps: u64::MAX,
                rejected_steps: u64::MAX,
                rhs_evaluations: u64::MAX,
                events: u64::MAX,
            }),
        }
    }

    #[test]
    fn the_largest_answers_fit_in_a_message_as_the_proto_says() {
        let mut largest = 0;
        for model in models::all() {
            let outputs = model.info().outputs.len();
            let len = largest_simulate_response(model.as_ref()).encoded_len();
            // 8 bytes per time and per time and output, plus a few bytes of framing.
            assert!(len >= 8 * MAX_TIMES * (1 + outputs), "{len}");
            assert!(len < 8 * MAX_TIMES * (1 + outputs) + 1024, "{len}");
            largest = largest.max(len);
            let evaluate = proto::EvaluateResponse {
                results: vec![
                    proto::PointResult {
                        objective: 1.5,
                        sse: vec![0.25; outputs],
                        failure: None,
                        residuals: Vec::new(),
                    };
                    MAX_POINTS
                ],
                measurement_hash: vec![0xff; 32],
            };
            let len = evaluate.encoded_len();
            assert!(len <= MAX_POINTS * (14 + 8 * outputs) + 34, "{len}");
            assert!(len < 1 << 20, "{len}");
        }
        assert!(largest < MAX_MESSAGE_BYTES);
        assert!((43_000_000..45_000_000).contains(&largest), "{largest}");
    }
}
