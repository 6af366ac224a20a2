//! Requests as the worker understands them, checked on arrival.
//!
//! Every `TryFrom<proto::…>` here validates a request completely before any simulation
//! starts, and names the offending field in its error, so that a client in any language
//! learns exactly what to fix.

use super::error::{Error, Result};
use super::limits;
use crate::{models, Model, ModelInfo, SolverOptions};
use calib_proto::v1 as proto;

/// Reject any protocol version but ours.
pub fn check_protocol(client: u32) -> Result<()> {
    if client == calib_proto::PROTOCOL_VERSION {
        Ok(())
    } else {
        Err(Error::ProtocolMismatch {
            client,
            worker: calib_proto::PROTOCOL_VERSION,
        })
    }
}

/// The hosted model called `name`.
pub fn hosted_model(name: &str) -> Result<&'static dyn Model> {
    models::find(name).ok_or_else(|| {
        let known: Vec<_> = models::all()
            .iter()
            .map(|m| m.info().name.clone())
            .collect();
        Error::invalid(
            "model",
            format!("unknown model `{name}` (hosted: {})", known.join(", ")),
        )
    })
}

/// A value for entry `index` of the model's parameter vector: finite and within its range.
fn check_value(info: &ModelInfo, index: usize, value: f64, field: &str) -> Result<()> {
    let name = info.name_at(index);
    if !value.is_finite() {
        return Err(Error::invalid(
            field,
            format!("`{name}` = {value} is not a finite number"),
        ));
    }
    let (lo, hi) = info.bounds_at(index);
    // Points mapped from a unit box may land an ulp outside the bounds they came from.
    let slack = 1e-9 * (hi - lo).abs().max(f64::MIN_POSITIVE);
    if value < lo - slack || value > hi + slack {
        return Err(Error::invalid(
            field,
            format!("`{name}` = {value} is outside its admissible range [{lo}, {hi}]"),
        ));
    }
    Ok(())
}

/// The model's defaults overridden by the named values.
fn parameter_vector(info: &ModelInfo, values: &[proto::ParameterValue]) -> Result<Vec<f64>> {
    let mut params = info.default_vector();
    let mut seen = vec![false; params.len()];
    for (i, p) in values.iter().enumerate() {
        let index = info.parameter_index(&p.name).ok_or_else(|| {
            Error::invalid(
                format!("parameters[{i}].name"),
                format!("model `{}` has no parameter `{}`", info.name, p.name),
            )
        })?;
        if std::mem::replace(&mut seen[index], true) {
            return Err(Error::invalid(
                format!("parameters[{i}].name"),
                format!("`{}` is set twice", p.name),
            ));
        }
        check_value(info, index, p.value, &format!("parameters[{i}].value"))?;
        params[index] = p.value;
    }
    Ok(params)
}

/// Output times: non-empty, finite, ≥ 0, non-decreasing, bounded in number and extent.
fn check_times(times: &[f64], field: &str) -> Result<()> {
    let Some(&stop) = times.last() else {
        return Err(Error::invalid(field, "empty time grid"));
    };
    if times.len() > limits::MAX_TIMES {
        return Err(Error::invalid(
            field,
            format!(
                "{} times exceed the limit of {}",
                times.len(),
                limits::MAX_TIMES
            ),
        ));
    }
    if let Some(i) = times.iter().position(|t| !t.is_finite()) {
        return Err(Error::invalid(
            format!("{field}[{i}]"),
            format!("{} is not a finite time", times[i]),
        ));
    }
    if stop < 0.0 {
        return Err(Error::invalid(
            field,
            format!("stop time {stop} s is negative"),
        ));
    }
    if stop > limits::MAX_STOP_TIME {
        return Err(Error::invalid(
            field,
            format!(
                "stop time {stop} s is beyond what calib simulates ({} s)",
                limits::MAX_STOP_TIME
            ),
        ));
    }
    if let Some(i) = times.iter().position(|t| *t < 0.0) {
        return Err(Error::invalid(
            format!("{field}[{i}]"),
            format!("{} s is negative: simulations start at 0 s", times[i]),
        ));
    }
    if let Some(i) = times.windows(2).position(|w| w[1] < w[0]) {
        return Err(Error::invalid(
            format!("{field}[{}]", i + 1),
            format!(
                "{} s comes after {} s: times must not decrease",
                times[i + 1],
                times[i]
            ),
        ));
    }
    Ok(())
}

fn output_index(info: &ModelInfo, name: &str, field: &str) -> Result<usize> {
    info.output_index(name).ok_or_else(|| {
        Error::invalid(
            field,
            format!("model `{}` has no output `{name}`", info.name),
        )
    })
}

fn solver_options(options: Option<proto::SolverOptions>) -> Result<SolverOptions> {
    let Some(o) = options else {
        return Ok(SolverOptions::default());
    };
    if !(o.rtol > 0.0 && o.rtol < 1.0) {
        return Err(Error::invalid(
            "solver.rtol",
            format!("{} is not in (0, 1)", o.rtol),
        ));
    }
    if !(o.atol > 0.0 && o.atol.is_finite()) {
        return Err(Error::invalid(
            "solver.atol",
            format!("{} is not a positive finite number", o.atol),
        ));
    }
    if o.max_steps == 0 || o.max_steps > limits::MAX_STEPS {
        return Err(Error::invalid(
            "solver.max_steps",
            format!("{} is not between 1 and {}", o.max_steps, limits::MAX_STEPS),
        ));
    }
    Ok(SolverOptions {
        rtol: o.rtol,
        atol: o.atol,
        max_steps: o.max_steps as usize,
    })
}

/// One simulation, checked.
pub struct Simulation {
    pub model: &'static dyn Model,
    pub params: Vec<f64>,
    pub times: Vec<f64>,
    pub outputs: Vec<usize>,
    pub solver: SolverOptions,
}

impl TryFrom<proto::SimulateRequest> for Simulation {
    type Error = Error;

    fn try_from(r: proto::SimulateRequest) -> Result<Self> {
        check_protocol(r.protocol_version)?;
        let model = hosted_model(&r.model)?;
        let info = model.info();
        let params = parameter_vector(info, &r.parameters)?;
        check_times(&r.times, "times")?;
        let outputs = if r.outputs.is_empty() {
            (0..info.outputs.len()).collect()
        } else {
            r.outputs
                .iter()
                .enumerate()
                .map(|(i, name)| output_index(info, name, &format!("outputs[{i}]")))
                .collect::<Result<_>>()?
        };
        Ok(Self {
            model,
            params,
            times: r.times,
            outputs,
            solver: solver_options(r.solver)?,
        })
    }
}

/// Measured series on their grid, as shipped by a client.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredData {
    pub times: Vec<f64>,
    pub columns: Vec<Vec<f64>>,
}

impl MeasuredData {
    /// Memory the data occupies [bytes], for the cache's bound.
    pub fn bytes(&self) -> usize {
        8 * (self.times.len() + self.columns.iter().map(Vec::len).sum::<usize>())
    }

    pub fn hash(&self) -> [u8; 32] {
        crate::scoring::measurement_hash(&self.times, &self.columns)
    }
}

impl TryFrom<proto::Measurement> for MeasuredData {
    type Error = Error;

    fn try_from(m: proto::Measurement) -> Result<Self> {
        check_times(&m.times, "measurement.times")?;
        let columns: Vec<Vec<f64>> = m.columns.into_iter().map(|c| c.values).collect();
        for (i, column) in columns.iter().enumerate() {
            let field = format!("measurement.columns[{i}]");
            if column.len() != m.times.len() {
                return Err(Error::invalid(
                    field,
                    format!("{} values for {} times", column.len(), m.times.len()),
                ));
            }
            if let Some(j) = column.iter().position(|v| !v.is_finite()) {
                return Err(Error::invalid(
                    format!("{field}.values[{j}]"),
                    format!("{} is not a finite number", column[j]),
                ));
            }
        }
        Ok(Self {
            times: m.times,
            columns,
        })
    }
}

/// A batch of points to score, checked.
pub struct Evaluation {
    pub model: &'static dyn Model,
    /// Full parameter vector the points' free values are written into.
    pub base: Vec<f64>,
    pub free: Vec<usize>,
    pub outputs: Vec<usize>,
    pub weights: Vec<f64>,
    pub measurement_hash: [u8; 32],
    /// The measurement, when the client sent it along (checked against the hash).
    pub measurement: Option<MeasuredData>,
    pub points: Vec<Vec<f64>>,
    pub solver: SolverOptions,
}

impl Evaluation {
    /// The full parameter vector of point `i`.
    pub fn parameters(&self, i: usize) -> Vec<f64> {
        let mut full = self.base.clone();
        for (&index, v) in self.free.iter().zip(&self.points[i]) {
            full[index] = *v;
        }
        full
    }
}

impl TryFrom<proto::EvaluateRequest> for Evaluation {
    type Error = Error;

    fn try_from(r: proto::EvaluateRequest) -> Result<Self> {
        check_protocol(r.protocol_version)?;
        let model = hosted_model(&r.model)?;
        let info = model.info();
        let base = parameter_vector(info, &r.parameters)?;
        let mut free = Vec::with_capacity(r.free_parameters.len());
        for (i, name) in r.free_parameters.iter().enumerate() {
            let field = format!("free_parameters[{i}]");
            let index = info.parameter_index(name).ok_or_else(|| {
                Error::invalid(
                    &field,
                    format!("model `{}` has no parameter `{name}`", info.name),
                )
            })?;
            if free.contains(&index) {
                return Err(Error::invalid(field, format!("`{name}` is listed twice")));
            }
            free.push(index);
        }
        if r.outputs.is_empty() {
            return Err(Error::invalid("outputs", "no output to compare"));
        }
        let mut outputs = Vec::with_capacity(r.outputs.len());
        let mut weights = Vec::with_capacity(r.outputs.len());
        for (i, o) in r.outputs.iter().enumerate() {
            outputs.push(output_index(
                info,
                &o.output,
                &format!("outputs[{i}].output"),
            )?);
            if !(o.weight >= 0.0 && o.weight.is_finite()) {
                return Err(Error::invalid(
                    format!("outputs[{i}].weight"),
                    format!("{} is not a finite non-negative number", o.weight),
                ));
            }
            weights.push(o.weight);
        }
        let measurement_hash: [u8; 32] =
            r.measurement_hash.as_slice().try_into().map_err(|_| {
                Error::invalid(
                    "measurement_hash",
                    format!("{} bytes, expected 32 (BLAKE3)", r.measurement_hash.len()),
                )
            })?;
        let measurement = r.measurement.map(MeasuredData::try_from).transpose()?;
        if let Some(m) = &measurement {
            if m.columns.len() != outputs.len() {
                return Err(Error::invalid(
                    "measurement.columns",
                    format!("{} columns for {} outputs", m.columns.len(), outputs.len()),
                ));
            }
            if m.hash() != measurement_hash {
                return Err(Error::invalid(
                    "measurement",
                    "its content hash differs from measurement_hash",
                ));
            }
        }
        if r.points.is_empty() {
            return Err(Error::invalid("points", "no point to evaluate"));
        }
        if r.points.len() > limits::MAX_POINTS {
            return Err(Error::invalid(
                "points",
                format!(
                    "{} points exceed the limit of {}",
                    r.points.len(),
                    limits::MAX_POINTS
                ),
            ));
        }
        let mut points = Vec::with_capacity(r.points.len());
        for (i, p) in r.points.into_iter().enumerate() {
            if p.values.len() != free.len() {
                return Err(Error::invalid(
                    format!("points[{i}].values"),
                    format!(
                        "{} values for {} free parameters",
                        p.values.len(),
                        free.len()
                    ),
                ));
            }
            for (j, (&index, &v)) in free.iter().zip(&p.values).enumerate() {
                check_value(info, index, v, &format!("points[{i}].values[{j}]"))?;
            }
            points.push(p.values);
        }
        Ok(Self {
            model,
            base,
            free,
            outputs,
            weights,
            measurement_hash,
            measurement,
            points,
            solver: solver_options(r.solver)?,
        })
    }
}
