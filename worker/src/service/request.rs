//! Requests as the worker understands them, checked on arrival.
//!
//! Every `TryFrom<proto::…>` here validates a request completely before any simulation
//! starts, and names the offending field in its error, so that a client in any language
//! learns exactly what to fix.

use super::error::{Error, Result};
use calib_model::inputs::{Inputs, Interpolation, NamedSignal};
use calib_model::{limits, user_effects, validate, Model, ModelInfo, SolverOptions};
use calib_proto::v1 as proto;

/// Reject any protocol version but ours: the check of requests that simulate.
pub fn check_protocol(client: u32) -> Result<()> {
    check_protocol_among(client, &[calib_proto::PROTOCOL_VERSION])
}

/// Reject any protocol version but ours or unset (0): the check of read-only requests
/// (ListModels, Describe, Status), which a client may send before it knows the version.
pub fn check_read_protocol(client: u32) -> Result<()> {
    check_protocol_among(client, &[0, calib_proto::PROTOCOL_VERSION])
}

fn check_protocol_among(client: u32, accepted: &[u32]) -> Result<()> {
    if accepted.contains(&client) {
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
    validate::model(name).map_err(|e| Error::invalid("model", e.message))
}

/// The hosted model called `name` with the request's user-defined effects.
pub fn model_with_effects(name: &str, effects: &[proto::UserEffect]) -> Result<&'static dyn Model> {
    let model = hosted_model(name)?;
    let refused = |e: user_effects::EffectError| Error::invalid(e.field, e.message);
    let definitions = crate::wire::all_from_proto(effects).map_err(refused)?;
    user_effects::attach(model, &definitions).map_err(refused)
}

/// A refusal of [`validate`] placed at `field`, or at its element when it names one.
fn at(field: &str, e: validate::Invalid) -> Error {
    match e.index {
        Some(i) => Error::invalid(format!("{field}[{i}]"), e.message),
        None => Error::invalid(field, e.message),
    }
}

fn check_value(info: &ModelInfo, index: usize, value: f64, field: &str) -> Result<()> {
    validate::parameter_value(info, index, value).map_err(|e| at(field, e))
}

/// The model's defaults overridden by the named values.
fn parameter_vector(info: &ModelInfo, values: &[proto::ParameterValue]) -> Result<Vec<f64>> {
    let mut params = info.default_vector();
    let mut seen = vec![false; params.len()];
    for (i, p) in values.iter().enumerate() {
        let index = validate::parameter(info, &p.name)
            .map_err(|e| at(&format!("parameters[{i}].name"), e))?;
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

fn check_times(times: &[f64], field: &str) -> Result<()> {
    validate::output_grid(times).map_err(|e| at(field, e))
}

fn output_index(info: &ModelInfo, name: &str, field: &str) -> Result<usize> {
    validate::output(info, name).map_err(|e| at(field, e))
}

/// The request's solver options field by field, the model's own calibration tolerances for
/// every field it leaves unset.
fn solver_options(
    model: &dyn Model,
    options: Option<proto::SolverOptions>,
) -> Result<SolverOptions> {
    let overrides = options.map_or_else(Default::default, |o| validate::SolverOverrides {
        rtol: o.rtol,
        atol: o.atol,
        max_steps: o.max_steps,
        start_time: o.start_time,
        communication_step: o.communication_step,
    });
    validate::solver_options(model, overrides)
        .map_err(|(option, e)| at(&format!("solver.{option}"), e))
}

/// Input signals as a request names them, each checked on its own (`field` is where the
/// list sits in the request): as many values as times, finite, times non-decreasing.
fn named_signals(series: Vec<proto::InputSeries>, field: &str) -> Result<Vec<NamedSignal>> {
    let mut named = Vec::with_capacity(series.len());
    for (k, s) in series.into_iter().enumerate() {
        let at = |what: &str| format!("{field}[{k}].{what}");
        let interpolation = match proto::Interpolation::try_from(s.interpolation) {
            Ok(proto::Interpolation::Linear) => Interpolation::Linear,
            Ok(proto::Interpolation::Hold) => Interpolation::Hold,
            Err(_) => {
                return Err(Error::invalid(
                    at("interpolation"),
                    format!("{} is not an Interpolation", s.interpolation),
                ))
            }
        };
        if s.times.is_empty() {
            return Err(Error::invalid(at("times"), "no sample"));
        }
        if s.values.len() != s.times.len() {
            return Err(Error::invalid(
                at("values"),
                format!("{} values for {} times", s.values.len(), s.times.len()),
            ));
        }
        if let Some(j) = s.times.iter().position(|t| !t.is_finite()) {
            return Err(Error::invalid(
                format!("{}[{j}]", at("times")),
                format!("{} is not a finite number", s.times[j]),
            ));
        }
        if let Some(j) = s.times.windows(2).position(|w| w[1] < w[0]) {
            return Err(Error::invalid(
                format!("{}[{}]", at("times"), j + 1),
                format!("{} s comes before {} s", s.times[j + 1], s.times[j]),
            ));
        }
        if let Some(j) = s.values.iter().position(|v| !v.is_finite()) {
            return Err(Error::invalid(
                format!("{}[{j}]", at("values")),
                format!("{} is not a finite number", s.values[j]),
            ));
        }
        if named.iter().any(|n: &NamedSignal| n.name == s.input) {
            return Err(Error::invalid(
                at("input"),
                format!("`{}` is driven twice", s.input),
            ));
        }
        named.push(NamedSignal {
            name: s.input,
            times: s.times.into(),
            values: s.values.into(),
            interpolation,
        });
    }
    Ok(named)
}

/// Named signals resolved against `model` and checked to cover the simulation from
/// `start` to `stop` (`field` is where they sit in the request).
pub fn driving_inputs(
    model: &dyn Model,
    named: &[NamedSignal],
    start: f64,
    stop: f64,
    field: &str,
) -> Result<Inputs> {
    let info = model.info();
    let inputs = Inputs::resolve(info, named)
        .map_err(|(k, message)| Error::invalid(format!("{field}[{k}].input"), message))?;
    inputs.check(info, start, stop).map_err(|message| {
        let k = inputs
            .signals
            .iter()
            .position(|s| message.contains(&format!("`{}`", info.inputs[s.input].name)))
            .unwrap_or(0);
        Error::invalid(format!("{field}[{k}]"), message)
    })?;
    Ok(inputs)
}

/// One simulation, checked.
pub struct Simulation {
    pub model: &'static dyn Model,
    pub params: Vec<f64>,
    pub times: Vec<f64>,
    pub outputs: Vec<usize>,
    pub solver: SolverOptions,
    pub inputs: Inputs,
}

impl TryFrom<proto::SimulateRequest> for Simulation {
    type Error = Error;

    fn try_from(r: proto::SimulateRequest) -> Result<Self> {
        check_protocol(r.protocol_version)?;
        let model = model_with_effects(&r.model, &r.effects)?;
        let info = model.info();
        let params = parameter_vector(info, &r.parameters)?;
        check_times(&r.times, "times")?;
        let outputs: Vec<usize> = if r.outputs.is_empty() {
            (0..info.outputs.len()).collect()
        } else {
            r.outputs
                .iter()
                .enumerate()
                .map(|(i, name)| output_index(info, name, &format!("outputs[{i}]")))
                .collect::<Result<_>>()?
        };
        answer_fits("outputs", r.times.len(), 1 + outputs.len())?;
        let solver = solver_options(model, r.solver)?;
        let named = named_signals(r.inputs, "inputs")?;
        let stop = r.times[r.times.len() - 1];
        let inputs = driving_inputs(model, &named, solver.start_time, stop, "inputs")?;
        Ok(Self {
            model,
            params,
            times: r.times,
            outputs,
            solver,
            inputs,
        })
    }
}

/// Refuses a request whose answer would carry `count` × `each` numbers, more than
/// [`limits::MAX_ANSWER_VALUES`]: `field` is what to ask less of.
pub fn answer_fits(field: &str, count: usize, each: usize) -> Result<()> {
    let total = count.saturating_mul(each);
    if total <= limits::MAX_ANSWER_VALUES {
        return Ok(());
    }
    let most = limits::MAX_ANSWER_VALUES / each.max(1);
    Err(Error::invalid(
        field,
        format!(
            "the answer would carry {count} × {each} = {total} numbers, more than the {} one \
             answer holds ({} MiB); ask for at most {most} at once",
            limits::MAX_ANSWER_VALUES,
            (limits::MAX_ANSWER_VALUES * 8) >> 20
        ),
    ))
}

/// Measured series on their grid, as shipped by a client.
#[derive(Debug, Clone, PartialEq)]
pub struct MeasuredData {
    pub times: Vec<f64>,
    pub columns: Vec<Vec<f64>>,
    /// Signals driving the model while it is simulated for this measurement.
    pub inputs: Vec<NamedSignal>,
}

impl MeasuredData {
    /// Memory the data occupies [bytes], for the cache's bound.
    pub fn bytes(&self) -> usize {
        let inputs: usize = self.inputs.iter().map(|s| 2 * s.times.len()).sum();
        8 * (self.times.len() + self.columns.iter().map(Vec::len).sum::<usize>() + inputs)
    }

    pub fn hash(&self) -> [u8; 32] {
        calib_model::scoring::measurement_hash(&self.times, &self.columns, &self.inputs)
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
            inputs: named_signals(m.inputs, "measurement.inputs")?,
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
    /// Whether each point's weighted residuals are returned.
    pub residuals: bool,
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

/// The indices of the free parameters, each named once.
fn free_indices(info: &ModelInfo, names: &[String]) -> Result<Vec<usize>> {
    let mut free = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        let field = format!("free_parameters[{i}]");
        let index = validate::parameter(info, name).map_err(|e| at(&field, e))?;
        if free.contains(&index) {
            return Err(Error::invalid(field, format!("`{name}` is listed twice")));
        }
        free.push(index);
    }
    Ok(free)
}

/// The points to evaluate: at least one, at most the limit, each a value in range for every
/// free parameter.
fn checked_points(
    info: &ModelInfo,
    free: &[usize],
    points: Vec<proto::Point>,
) -> Result<Vec<Vec<f64>>> {
    if points.is_empty() {
        return Err(Error::invalid("points", "no point to evaluate"));
    }
    if points.len() > limits::MAX_POINTS {
        return Err(Error::invalid(
            "points",
            format!(
                "{} points exceed the limit of {}",
                points.len(),
                limits::MAX_POINTS
            ),
        ));
    }
    let mut checked = Vec::with_capacity(points.len());
    for (i, p) in points.into_iter().enumerate() {
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
        checked.push(p.values);
    }
    Ok(checked)
}

impl TryFrom<proto::EvaluateRequest> for Evaluation {
    type Error = Error;

    fn try_from(r: proto::EvaluateRequest) -> Result<Self> {
        check_protocol(r.protocol_version)?;
        let model = model_with_effects(&r.model, &r.effects)?;
        let info = model.info();
        let base = parameter_vector(info, &r.parameters)?;
        let free = free_indices(info, &r.free_parameters)?;
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
        let measurement = r.measurement.map(MeasuredData::try_from).transpose()?;
        // Without a hash, a request carrying the measurement lets the worker name it (the
        // answer gives the name for later requests): clients need not compute it.
        let named_here = r.measurement_hash.is_empty() && measurement.is_some();
        let measurement_hash: [u8; 32] = match &measurement {
            Some(m) if named_here => m.hash(),
            _ => r.measurement_hash.as_slice().try_into().map_err(|_| {
                Error::invalid(
                    "measurement_hash",
                    format!("{} bytes, expected 32 (BLAKE3)", r.measurement_hash.len()),
                )
            })?,
        };
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
        let points = checked_points(info, &free, r.points)?;
        Ok(Self {
            model,
            base,
            free,
            outputs,
            weights,
            measurement_hash,
            measurement,
            points,
            solver: solver_options(model, r.solver)?,
            residuals: r.residuals,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn simulate_request(
        model: &str,
        solver: Option<proto::SolverOptions>,
    ) -> proto::SimulateRequest {
        proto::SimulateRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
            model: model.into(),
            parameters: vec![],
            times: vec![0.0, 1.0],
            outputs: vec![],
            solver,
            fmu_hash: Vec::new(),
            inputs: vec![],
            effects: vec![],
        }
    }

    #[test]
    fn an_answer_is_refused_beyond_the_numbers_one_message_holds() {
        assert!(answer_fits("outputs", 500_000, 11).is_ok());
        assert!(answer_fits("points", 3668, 2001).is_ok());
        let e = answer_fits("points", 3669, 2001).unwrap_err().to_string();
        assert!(
            e.starts_with("points: the answer would carry 3669 × 2001 = 7341669 numbers")
                && e.ends_with("ask for at most 3668 at once"),
            "{e}"
        );
        assert!(
            answer_fits("outputs", usize::MAX, 3).is_err(),
            "no overflow"
        );
    }

    #[test]
    fn a_request_without_solver_options_gets_the_models_own_tolerances() {
        let hx = Simulation::try_from(simulate_request("hx_lowfi", None)).unwrap();
        assert_eq!(hx.solver.rtol, 1e-6);
        assert_eq!(hx.solver, hx.model.default_options());
        let furuta = Simulation::try_from(simulate_request("furuta", None)).unwrap();
        assert_eq!(furuta.solver.rtol, 1e-8);
        let given = proto::SolverOptions {
            rtol: Some(1e-4),
            atol: Some(1e-6),
            max_steps: Some(10),
            ..Default::default()
        };
        let s = Simulation::try_from(simulate_request("hx_lowfi", Some(given))).unwrap();
        assert_eq!(
            (s.solver.rtol, s.solver.atol, s.solver.max_steps),
            (1e-4, 1e-6, 10)
        );
    }

    #[test]
    fn each_solver_option_left_unset_is_the_models_own() {
        let only_rtol = proto::SolverOptions {
            rtol: Some(1e-5),
            ..Default::default()
        };
        for model in ["furuta", "hx_lowfi"] {
            let s = Simulation::try_from(simulate_request(model, Some(only_rtol))).unwrap();
            let own = s.model.default_options();
            assert_eq!(
                (s.solver.rtol, s.solver.atol, s.solver.max_steps),
                (1e-5, own.atol, own.max_steps)
            );
        }
        let only_atol_zero = proto::SolverOptions {
            atol: Some(0.0),
            ..Default::default()
        };
        let e = Simulation::try_from(simulate_request("furuta", Some(only_atol_zero)))
            .err()
            .unwrap();
        assert!(e.to_string().starts_with("solver.atol: "), "{e}");
    }

    #[test]
    fn refusals_name_the_field_and_suggest_the_nearest_name() {
        let mut r = simulate_request("furuta", None);
        r.parameters.push(proto::ParameterValue {
            name: "armFrict".into(),
            value: 0.1,
        });
        let e = Simulation::try_from(r).err().unwrap();
        assert_eq!(
            e.to_string(),
            "parameters[0].name: model `furuta` has no parameter `armFrict`; did you mean \
             `armFriction`?"
        );
        let mut r = simulate_request("furuta", None);
        r.times = vec![0.0, 2.0, 1.0];
        let e = Simulation::try_from(r).err().unwrap();
        assert!(e.to_string().starts_with("times[2]: "), "{e}");
        let r = simulate_request(
            "furuta",
            Some(proto::SolverOptions {
                rtol: Some(1e-8),
                atol: Some(1e-10),
                max_steps: Some(20_000_000),
                ..Default::default()
            }),
        );
        let e = Simulation::try_from(r).err().unwrap();
        assert!(e.to_string().starts_with("solver.max_steps: "), "{e}");
    }

    fn user_effect(formula: &str) -> proto::UserEffect {
        proto::UserEffect {
            name: "damping.arm".into(),
            torque: "armJoint".into(),
            output: String::new(),
            formula: formula.into(),
            parameters: vec![proto::UserEffectParameter {
                name: "b".into(),
                nominal: 0.0,
                min: 0.0,
                max: 1.0,
            }],
        }
    }

    #[test]
    fn user_effects_travel_as_text_and_are_checked_on_arrival() {
        let mut r = simulate_request("furuta", None);
        r.effects.push(user_effect("-b * armJoint.w"));
        r.parameters.push(proto::ParameterValue {
            name: "damping.arm.b".into(),
            value: 0.01,
        });
        let s = Simulation::try_from(r).unwrap();
        let b = s.model.info().parameter_index("damping.arm.b").unwrap();
        assert_eq!(s.params[b], 0.01);
        assert_eq!(s.model.user_effects()[0].formula, "-b * armJoint.w");

        let mut r = simulate_request("furuta", None);
        r.effects.push(user_effect("-b * armJoint.v"));
        let e = Simulation::try_from(r).err().unwrap();
        assert_eq!(
            e.to_string(),
            "effects[0].formula: at character 6: unknown name `armJoint.v`; did you mean \
             `armJoint.w`?"
        );
        let mut r = simulate_request("furuta", None);
        let mut both = user_effect("b");
        both.output = "armJoint.phi".into();
        r.effects.push(both);
        let e = Simulation::try_from(r).err().unwrap();
        assert!(e.to_string().starts_with("effects[0].output: "), "{e}");
    }
}
