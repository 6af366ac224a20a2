//! Effects written as formulas: extra physics a campaign (or a program) defines for a model
//! that lacks it, such as a cogging torque `a * sin(k * armJoint.phi + c)` on the arm.
//!
//! A [`UserEffect`] names a place the model declares ([`crate::Model::places`]): a
//! generalized torque on a joint (added to the equations of motion at every right-hand
//! side) or an output (transformed after the simulation: `y + formula`). Its formula reads
//! the state by the output names ([`crate::Model::state_names`]) at a torque, or the
//! outputs by name and the output's own value as `y` at an output; the inputs by name (0
//! when undriven), `time`, and its own parameters. Each parameter becomes a parameter of
//! the model named `<effect>.<parameter>` (an effect slot after the model's own, so
//! diagnosis can hold it at 0 and offer it as a candidate).
//!
//! [`attach`] checks the definitions against the model (every mistake named by its field,
//! `effects[0].formula`), compiles each formula once and gives the model with the effects:
//! the same name and version, its parameters extended. Models with the same definitions
//! are made once per process.

mod formula;
mod model;

pub use formula::{calls, Compiled, FormulaError, FUNCTIONS};
pub use model::WithUserEffects;

use crate::content_hash::ContentHasher;
use crate::model::{Model, PlaceKind};
use std::collections::HashMap;
use std::sync::{Mutex, OnceLock};

/// One parameter of a user-defined effect.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct UserParameter {
    pub name: String,
    /// Its value when the campaign does not set it.
    pub nominal: f64,
    pub min: f64,
    pub max: f64,
}

/// An effect defined by a formula, as a campaign writes it or a program builds it.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct UserEffect {
    /// e.g. `cogging.arm`; its parameters are `cogging.arm.<name>`.
    pub name: String,
    pub kind: PlaceKind,
    /// The place of that kind: a joint (`armJoint`) or an output (`T_out`).
    pub place: String,
    pub formula: String,
    pub parameters: Vec<UserParameter>,
}

impl UserEffect {
    /// The model parameter name of its parameter `p`.
    pub fn parameter_name(&self, p: &UserParameter) -> String {
        format!("{}.{}", self.name, p.name)
    }
}

/// A refused definition: the field (`effects[1].parameters[0].nominal`) and why.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct EffectError {
    pub field: String,
    pub message: String,
}

fn refuse<T>(field: impl Into<String>, message: impl Into<String>) -> Result<T, EffectError> {
    Err(EffectError {
        field: field.into(),
        message: message.into(),
    })
}

/// The place of effect `i` from the two fields that may name it, exactly one of which must.
pub fn place_of(
    i: usize,
    torque: Option<&str>,
    output: Option<&str>,
) -> Result<(PlaceKind, String), EffectError> {
    match (torque, output) {
        (Some(t), None) => Ok((PlaceKind::Torque, t.to_string())),
        (None, Some(o)) => Ok((PlaceKind::Output, o.to_string())),
        (Some(_), Some(_)) => refuse(
            format!("effects[{i}].output"),
            "give `torque` or `output`, not both",
        ),
        (None, None) => refuse(
            format!("effects[{i}]"),
            "say where the effect acts: `torque = \"<joint>\"` or `output = \"<output>\"` \
             (`calib models <model>` lists the places)",
        ),
    }
}

/// Writes the definitions into a content hash: what simulates differently hashes apart.
pub fn hash_into(h: &mut ContentHasher, effects: &[UserEffect]) {
    if effects.is_empty() {
        return;
    }
    h.text("user effects").count(effects.len());
    for e in effects {
        h.text(&e.name)
            .text(e.kind.word())
            .text(&e.place)
            .text(&e.formula)
            .count(e.parameters.len());
        for p in &e.parameters {
            h.text(&p.name).values(&[p.nominal, p.min, p.max]);
        }
        // `sign(0)` was +1 before it was 0: a formula calling `sign` is another objective
        // now, so no value computed under the old rule is replayed from a store.
        if calls(&e.formula, "sign") {
            h.text("sign(0) = 0");
        }
    }
}

/// The terms user-defined effects add inside a model, each at a torque place.
#[derive(Debug, Clone, Default)]
pub struct Forces {
    pub terms: Vec<Force>,
}

impl Forces {
    /// No term added.
    pub fn none() -> &'static Forces {
        static NONE: Forces = Forces { terms: Vec::new() };
        &NONE
    }
}

/// One term: a compiled formula with its parameters' values of this simulation.
#[derive(Debug, Clone)]
pub struct Force {
    /// The torque place it acts on.
    pub place: String,
    /// The effect's name and its formula as written, for messages.
    effect: std::sync::Arc<str>,
    text: std::sync::Arc<str>,
    formula: Compiled,
    /// How many state entries and inputs come before `time` among the formula's names.
    states: usize,
    inputs: usize,
    parameters: Vec<f64>,
}

impl Force {
    /// The term `formula` of effect `named` (its name and text) at `place`, reading
    /// `counts` (states, inputs) before `time` and then `parameters`.
    pub(crate) fn new(
        place: String,
        named: (std::sync::Arc<str>, std::sync::Arc<str>),
        formula: Compiled,
        counts: (usize, usize),
        parameters: Vec<f64>,
    ) -> Self {
        Self {
            place,
            effect: named.0,
            text: named.1,
            formula,
            states: counts.0,
            inputs: counts.1,
            parameters,
        }
    }

    /// A failed simulation at `t`: this term's value `value` is not a number.
    pub fn not_finite(&self, t: f64, value: f64) -> crate::model::SimulationError {
        crate::model::SimulationError::Failed {
            time: t,
            reason: format!(
                "the torque of effect `{}` on `{}` is {value} (formula `{}`)",
                self.effect,
                self.place,
                shortened(&self.text)
            ),
        }
    }

    /// Its value at time `t` and state `y`, with input `k` worth `input(k)`.
    #[inline]
    pub fn value(&self, t: f64, y: &[f64], input: impl Fn(usize) -> f64) -> f64 {
        let (s, i) = (self.states, self.inputs);
        self.formula.eval_by(|k| {
            if k < s {
                y[k]
            } else if k < s + i {
                input(k - s)
            } else if k == s + i {
                t
            } else {
                self.parameters[k - s - i - 1]
            }
        })
    }
}

/// A formula as messages show it: whole up to 200 characters, else its start.
pub(crate) fn shortened(text: &str) -> String {
    match text.char_indices().nth(200) {
        Some((end, _)) => format!("{}…", &text[..end]),
        None => text.to_string(),
    }
}

/// `model` with `effects`, checked and compiled; `model` itself when there are none.
/// Made once per process for each model and set of definitions.
pub fn attach(
    model: &'static dyn Model,
    effects: &[UserEffect],
) -> Result<&'static dyn Model, EffectError> {
    if effects.is_empty() {
        return Ok(model);
    }
    type Registry = Mutex<HashMap<[u8; 32], &'static dyn Model>>;
    static MADE: OnceLock<Registry> = OnceLock::new();
    let info = model.info();
    let mut h = ContentHasher::new(b"calib-user-effects-v1\0");
    h.text(&info.name).count(info.version as usize);
    hash_into(&mut h, effects);
    let key = h.finish();
    let made = MADE.get_or_init(Default::default);
    if let Some(m) = made.lock().expect("registry lock").get(&key) {
        return Ok(*m);
    }
    let with = WithUserEffects::new(model, effects.to_vec())?;
    // Kept for the life of the process, as opened FMUs are: a handful per campaign.
    let with: &'static dyn Model = Box::leak(Box::new(with));
    Ok(*made
        .lock()
        .expect("registry lock")
        .entry(key)
        .or_insert(with))
}

#[cfg(test)]
mod tests;
