//! The contract every hosted model implements.
//!
//! A model declares its parameters (name, unit, default, bounds), its outputs and its
//! effects, and simulates onto a time grid. Effects are extra physics with a parameter
//! whose value 0 means "absent": they are listed separately so that diagnosis can find
//! them, but they are passed to [`Model::simulate`] like any other parameter, after the
//! base parameters, in the order of [`ModelInfo::effects`]. An effect may also *be* a base
//! parameter (the furuta's Coulomb frictions are base parameters and, when a campaign holds
//! them at 0, candidate effects): it then names that parameter and has no slot of its own.
//!
//! The optimisers, the objective and the dispatcher only ever see this trait, so new
//! models slot in without touching them.

use crate::inputs::Inputs;
use crate::user_effects::Forces;
use serde::Serialize;

/// A scalar the model takes as input.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ParameterSpec {
    pub name: String,
    pub unit: String,
    pub default: f64,
    /// Physically admissible range; campaigns may narrow it but not widen it.
    pub min: f64,
    pub max: f64,
    pub description: String,
}

/// A signal the model produces on the time grid.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct OutputSpec {
    pub name: String,
    pub unit: String,
    pub description: String,
}

/// A signal the model can be driven by (see [`crate::inputs`]).
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct InputSpec {
    /// Name as campaigns map it, e.g. `armTorque`.
    pub name: String,
    pub unit: String,
    /// What it is and what it is when no signal drives it.
    pub description: String,
}

/// Extra physics the base model lacks, switched on by a parameter that is 0 when absent.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct EffectSpec {
    /// Name as campaigns and diagnosis reports use it, e.g. `viscous_friction.arm`.
    pub name: String,
    pub unit: String,
    /// Admissible range of the effect's parameter; 0 (absent) lies inside it.
    pub min: f64,
    pub max: f64,
    pub description: String,
    /// The base parameter this effect is, if it has no slot of its own.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameter: Option<String>,
}

/// What a user-defined effect acts on (see [`crate::user_effects`]).
#[derive(Debug, Clone, Copy, Serialize, PartialEq, Eq, Hash)]
#[serde(rename_all = "lowercase")]
pub enum PlaceKind {
    /// A generalized torque on a joint, added to the equations of motion.
    Torque,
    /// An output, transformed after the simulation: `y + formula`.
    Output,
}

impl PlaceKind {
    /// The word a campaign writes: `torque = "armJoint"`, `output = "T_out"`.
    pub fn word(self) -> &'static str {
        match self {
            PlaceKind::Torque => "torque",
            PlaceKind::Output => "output",
        }
    }
}

/// A place of a model where a user-defined effect may act.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct PlaceSpec {
    pub kind: PlaceKind,
    pub name: String,
    pub description: String,
}

/// Everything a client needs to know to drive a model.
#[derive(Debug, Clone, Serialize, PartialEq)]
pub struct ModelInfo {
    pub name: String,
    /// Bumped whenever a change alters simulated values: invalidates cached evaluations.
    pub version: u32,
    pub description: String,
    pub parameters: Vec<ParameterSpec>,
    pub outputs: Vec<OutputSpec>,
    pub effects: Vec<EffectSpec>,
    /// Signals that may drive the model; each keeps the model's own value when undriven.
    pub inputs: Vec<InputSpec>,
}

impl ModelInfo {
    /// Effects with a slot of their own in the full parameter vector, in slot order.
    pub fn slot_effects(&self) -> impl Iterator<Item = &EffectSpec> {
        self.effects.iter().filter(|e| e.parameter.is_none())
    }

    /// Index of a base parameter or effect in the full parameter vector.
    pub fn parameter_index(&self, name: &str) -> Option<usize> {
        if let Some(i) = self.parameters.iter().position(|p| p.name == name) {
            return Some(i);
        }
        if let Some(alias) = self
            .effects
            .iter()
            .find(|e| e.name == name)
            .and_then(|e| e.parameter.as_deref())
        {
            return self.parameters.iter().position(|p| p.name == alias);
        }
        self.slot_effects()
            .position(|e| e.name == name)
            .map(|i| self.parameters.len() + i)
    }

    /// The effect called `name`, if the model has one.
    pub fn effect(&self, name: &str) -> Option<&EffectSpec> {
        self.effects.iter().find(|e| e.name == name)
    }

    pub fn input_index(&self, name: &str) -> Option<usize> {
        self.inputs.iter().position(|i| i.name == name)
    }

    pub fn output_index(&self, name: &str) -> Option<usize> {
        self.outputs.iter().position(|o| o.name == name)
    }

    /// Length of the full parameter vector: base parameters, then effects.
    pub fn full_len(&self) -> usize {
        self.parameters.len() + self.slot_effects().count()
    }

    /// Defaults for every base parameter, 0 (absent) for every effect.
    pub fn default_vector(&self) -> Vec<f64> {
        self.parameters
            .iter()
            .map(|p| p.default)
            .chain(self.slot_effects().map(|_| 0.0))
            .collect()
    }

    /// Name of the entry at `index` of the full parameter vector.
    pub fn name_at(&self, index: usize) -> &str {
        if index < self.parameters.len() {
            &self.parameters[index].name
        } else {
            &self.slot_effect(index).name
        }
    }

    /// Admissible bounds of the entry at `index` of the full parameter vector.
    pub fn bounds_at(&self, index: usize) -> (f64, f64) {
        if index < self.parameters.len() {
            let p = &self.parameters[index];
            (p.min, p.max)
        } else {
            let e = self.slot_effect(index);
            (e.min, e.max)
        }
    }

    fn slot_effect(&self, index: usize) -> &EffectSpec {
        self.slot_effects()
            .nth(index - self.parameters.len())
            .expect("index within the full parameter vector")
    }
}

/// Accuracy settings of a simulation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SolverOptions {
    pub rtol: f64,
    pub atol: f64,
    /// Upper bound on accepted plus rejected steps before the run is abandoned.
    pub max_steps: usize,
    /// Where the simulation starts [s]: an FMU is initialised there (outputs asked for
    /// before it hold the initial values). Hosted models start at 0.
    pub start_time: f64,
    /// The most a Co-Simulation FMU advances in one `doStep` [s], never past an output time;
    /// `None`: one `doStep` from each output time to the next.
    pub communication_step: Option<f64>,
}

impl Default for SolverOptions {
    /// The calibration tolerance: tight enough that the solver's error is far below
    /// sensor noise, loose enough to keep one `furuta` simulation well under a millisecond.
    fn default() -> Self {
        Self {
            rtol: 1e-8,
            atol: 1e-10,
            max_steps: 200_000,
            start_time: 0.0,
            communication_step: None,
        }
    }
}

/// Outputs sampled on the requested grid: `values[output][sample]`.
#[derive(Debug, Clone, PartialEq)]
pub struct Trajectory {
    pub time: Vec<f64>,
    pub values: Vec<Vec<f64>>,
    /// Solver statistics, for benchmarks and diagnostics.
    pub stats: SolverStats,
}

#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SolverStats {
    pub accepted_steps: usize,
    pub rejected_steps: usize,
    pub rhs_evaluations: usize,
    pub events: usize,
}

/// Why a simulation produced no trajectory. A typed result, never a panic: the
/// objective turns it into a large finite penalty.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimulationError {
    #[error("step limit of {limit} steps reached at t = {time} s")]
    StepLimit { limit: usize, time: f64 },
    #[error("step size underflow at t = {time} s")]
    StepTooSmall { time: f64 },
    /// Events accumulate at one time (a Zeno point) and the model has no mode that holds it.
    #[error(
        "events chatter at t = {time} s: {events} events within {span:e} s, the last \
         `{event}`, and the model has no mode that stops the switching"
    )]
    Chattering {
        time: f64,
        event: String,
        events: usize,
        span: f64,
    },
    #[error("solution diverged (non-finite state) at t = {time} s")]
    Diverged { time: f64 },
    #[error("invalid request: {0}")]
    InvalidInput(String),
    /// The model could not compute its state (no steady state, a state outside the range
    /// of its property data): the reason names the quantity and its value.
    #[error("simulation failed at t = {time} s: {reason}")]
    Failed { time: f64, reason: String },
}

/// [`Model::default_stop_time`] of a model that says none [s].
pub const DEFAULT_STOP_TIME: f64 = 10.0;

/// A hosted model.
///
/// Models implement the physics ([`Model::simulate`]); the registry wraps every model in
/// [`crate::effects::WithOutputEffects`], which adds the per-output effects (offset, gain,
/// delay, lag) to its description and applies them to its outputs.
pub trait Model: Send + Sync {
    fn info(&self) -> &ModelInfo;

    /// The accuracy a calibration of this model needs: tight enough that the solver's error
    /// stays far below what sensors resolve, no tighter. Campaigns may override it.
    fn default_options(&self) -> SolverOptions {
        SolverOptions::default()
    }

    /// How long a simulation of it usually runs [s]: the end of the record it is calibrated
    /// against (an FMU: its `DefaultExperiment`'s stop time). What a client starts from.
    fn default_stop_time(&self) -> f64 {
        DEFAULT_STOP_TIME
    }

    /// Where the tolerance of [`Model::default_options`] comes from, in words (Describe and
    /// `calib models` say it).
    fn tolerance_origin(&self) -> &'static str {
        "the model's calibration tolerance"
    }

    /// Where user-defined effects may act: by default each output (a transformation
    /// `y + formula`); a model with equations of motion adds its joints' torques.
    fn places(&self) -> Vec<PlaceSpec> {
        self.info()
            .outputs
            .iter()
            .map(|o| PlaceSpec {
                kind: PlaceKind::Output,
                name: o.name.clone(),
                description: format!("added to the output {} ({})", o.name, o.unit),
            })
            .collect()
    }

    /// The names a formula acting inside the model (on a torque) reads its state by, in
    /// the order of the state vector; empty for a model without such places.
    fn state_names(&self) -> Vec<String> {
        Vec::new()
    }

    /// The user-defined effects this model carries (see [`crate::user_effects`]); none for
    /// a model as hosted.
    fn user_effects(&self) -> &[crate::user_effects::UserEffect] {
        &[]
    }

    /// Simulate `run`: from t = 0 (an FMU: from [`SolverOptions::start_time`]) with the
    /// full parameter vector (base parameters then effects, see [`ModelInfo::full_len`]),
    /// driven by its inputs and with its forces added at their places, and return its
    /// outputs at the times of its grid. A model that takes no input refuses a signal
    /// ([`Run::refuse_inputs`]), and one with no torque place refuses forces
    /// ([`Run::refuse_forces`]).
    fn simulate(&self, run: &Run) -> Result<Trajectory, SimulationError>;
}

/// One simulation a model is asked for.
#[derive(Debug, Clone, Copy)]
pub struct Run<'a> {
    /// The full parameter vector: base parameters then effects ([`ModelInfo::full_len`]).
    pub params: &'a [f64],
    /// The times of the answer: finite, non-negative, non-decreasing.
    pub grid: &'a [f64],
    /// The outputs answered, as indices into [`ModelInfo::outputs`].
    pub outputs: &'a [usize],
    pub options: &'a SolverOptions,
    /// Signals of [`ModelInfo::inputs`]; inputs without one keep the model's own values.
    pub inputs: &'a Inputs,
    /// Terms of user-defined effects added at torque places.
    pub forces: &'a Forces,
}

impl<'a> Run<'a> {
    /// A free simulation: no input driven, no force added.
    pub fn new(
        params: &'a [f64],
        grid: &'a [f64],
        outputs: &'a [usize],
        options: &'a SolverOptions,
    ) -> Self {
        Run {
            params,
            grid,
            outputs,
            options,
            inputs: Inputs::none(),
            forces: Forces::none(),
        }
    }

    /// The same run driven by `inputs`.
    pub fn driven(self, inputs: &'a Inputs) -> Self {
        Run { inputs, ..self }
    }

    /// The same run with `forces` added.
    pub fn forced(self, forces: &'a Forces) -> Self {
        Run { forces, ..self }
    }

    /// The same run with other parameters.
    pub fn with_params(self, params: &'a [f64]) -> Self {
        Run { params, ..self }
    }

    /// Refuses the run if it drives an input: for a model that takes none.
    pub fn refuse_inputs(&self, info: &ModelInfo) -> Result<(), SimulationError> {
        match self.inputs.signals.first() {
            Some(s) => Err(SimulationError::InvalidInput(format!(
                "model `{}` takes no input (input #{} was given)",
                info.name, s.input
            ))),
            None => Ok(()),
        }
    }

    /// Refuses the run if it adds forces: for a model with no torque place.
    pub fn refuse_forces(&self, info: &ModelInfo) -> Result<(), SimulationError> {
        match self.forces.terms.first() {
            Some(f) => Err(SimulationError::InvalidInput(format!(
                "model `{}` has no torque `{}`",
                info.name, f.place
            ))),
            None => Ok(()),
        }
    }
}

/// Checks shared by every model before it simulates.
pub fn check_request(
    info: &ModelInfo,
    params: &[f64],
    grid: &[f64],
    outputs: &[usize],
) -> Result<(), SimulationError> {
    if params.len() != info.full_len() {
        return Err(SimulationError::InvalidInput(format!(
            "model `{}` takes {} parameters, got {}",
            info.name,
            info.full_len(),
            params.len()
        )));
    }
    if let Some(i) = params.iter().position(|v| !v.is_finite()) {
        return Err(SimulationError::InvalidInput(format!(
            "parameter `{}` is not finite",
            info.name_at(i)
        )));
    }
    if grid.is_empty() {
        return Err(SimulationError::InvalidInput("empty time grid".into()));
    }
    if grid.iter().any(|t| !t.is_finite() || *t < 0.0) || grid.windows(2).any(|w| w[1] < w[0]) {
        return Err(SimulationError::InvalidInput(
            "time grid must be finite, non-negative and non-decreasing".into(),
        ));
    }
    if let Some(o) = outputs.iter().find(|o| **o >= info.outputs.len()) {
        return Err(SimulationError::InvalidInput(format!(
            "model `{}` has no output #{o}",
            info.name
        )));
    }
    Ok(())
}
