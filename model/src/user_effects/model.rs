//! A model with user-defined effects: its parameters extended by theirs, their torques
//! passed into the equations of motion, their output transformations applied after.

use super::formula::{Compiled, MAX_LENGTH};
use super::{refuse, EffectError, Force, Forces, UserEffect};
use crate::inputs::Inputs;
use crate::model::{
    check_request, EffectSpec, Model, ModelInfo, PlaceKind, PlaceSpec, SimulationError,
    SolverOptions, Trajectory,
};
use crate::validate::hint;
use crate::Run;
use std::sync::Arc;

/// One definition, compiled.
struct Definition {
    formula: Compiled,
    /// The effect's name and formula, shared by the forces of every simulation.
    name: Arc<str>,
    text: Arc<str>,
    /// Its first parameter's position among the user parameters.
    first: usize,
    count: usize,
    /// The output it transforms (output places).
    output: Option<usize>,
}

/// A model with user-defined effects (see [`super`]).
pub struct WithUserEffects {
    base: &'static dyn Model,
    info: ModelInfo,
    base_len: usize,
    definitions: Vec<UserEffect>,
    compiled: Vec<Definition>,
}

/// A name made of letters, digits and `_` (and dots between such parts when `dotted`).
fn well_formed(name: &str, dotted: bool) -> bool {
    let part = |p: &str| {
        p.chars()
            .next()
            .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
            && p.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
    };
    if dotted {
        name.split('.').all(part)
    } else {
        part(name)
    }
}

/// The names a formula at `place` may read, in the order [`Force::value`] and
/// [`WithUserEffects`] give them: the state (torque) or `y` and the outputs (output), the
/// inputs, `time`, then the effect's parameters.
fn variables(model: &dyn Model, kind: PlaceKind, effect: &UserEffect) -> Vec<String> {
    let info = model.info();
    let mut names: Vec<String> = match kind {
        PlaceKind::Torque => model.state_names(),
        PlaceKind::Output => std::iter::once("y".to_string())
            .chain(info.outputs.iter().map(|o| o.name.clone()))
            .collect(),
    };
    names.extend(info.inputs.iter().map(|i| i.name.clone()));
    names.push("time".into());
    names.extend(effect.parameters.iter().map(|p| p.name.clone()));
    names
}

/// Check the parameters of effect `i` (`known`: its formula's variables, the parameters
/// last) and add them to `info` as effect slots.
fn add_parameters(
    info: &mut ModelInfo,
    i: usize,
    e: &UserEffect,
    known: &[String],
) -> Result<(), EffectError> {
    let reserved = known.len() - e.parameters.len();
    for (j, p) in e.parameters.iter().enumerate() {
        let at = |what: &str| format!("effects[{i}].parameters[{j}].{what}");
        if !well_formed(&p.name, false) {
            return refuse(
                at("name"),
                format!("`{}` is not a name: letters, digits and `_`", p.name),
            );
        }
        if known[..reserved].contains(&p.name) {
            return refuse(
                at("name"),
                format!("`{}` is already a variable of the formula", p.name),
            );
        }
        if e.parameters[..j].iter().any(|q| q.name == p.name) {
            return refuse(at("name"), format!("`{}` is listed twice", p.name));
        }
        if !(p.min.is_finite() && p.max.is_finite() && p.min <= p.max) {
            return refuse(
                at("max"),
                format!("bounds [{}, {}] are not a finite range", p.min, p.max),
            );
        }
        if !(p.nominal >= p.min && p.nominal <= p.max) {
            return refuse(
                at("nominal"),
                format!(
                    "nominal {} is outside its bounds [{}, {}]",
                    p.nominal, p.min, p.max
                ),
            );
        }
        let full = e.parameter_name(p);
        if info.parameter_index(&full).is_some() || info.effect(&full).is_some() {
            return refuse(
                at("name"),
                format!("`{full}` is already a parameter or effect of the model"),
            );
        }
        info.effects.push(EffectSpec {
            name: full,
            unit: String::new(),
            min: p.min,
            max: p.max,
            description: format!(
                "parameter `{}` of the effect `{}` on the {} {}: {}",
                p.name,
                e.name,
                e.kind.word(),
                e.place,
                e.formula
            ),
            parameter: None,
        });
    }
    Ok(())
}

/// The formula of effect `i` compiled against its variables `known`; an unknown name gets
/// the nearest known one.
fn compile(i: usize, e: &UserEffect, known: &[String]) -> Result<Compiled, EffectError> {
    let field = format!("effects[{i}].formula");
    if e.formula.len() > MAX_LENGTH {
        return refuse(
            field,
            format!("{} characters, more than {MAX_LENGTH}", e.formula.len()),
        );
    }
    Compiled::new(&e.formula, known).map_err(|f| {
        let suggestion = f.unknown.as_deref().map_or(String::new(), |u| {
            if f.message.starts_with("unknown function") {
                let functions = super::FUNCTIONS.iter().copied().chain(["pow"]);
                return hint(
                    u,
                    functions,
                    "functions: sin cos exp abs sign sqrt tanh pow",
                );
            }
            let listed = format!(
                "a formula reads {}, `time` and its parameters",
                match e.kind {
                    PlaceKind::Torque => "the state by output names, the inputs",
                    PlaceKind::Output => "`y`, the outputs, the inputs",
                }
            );
            hint(u, known.iter().map(String::as_str), &listed)
        });
        EffectError {
            field,
            message: format!("at character {}: {}{suggestion}", f.position, f.message),
        }
    })
}

impl WithUserEffects {
    /// Check `effects` against `base` and compile them.
    pub fn new(base: &'static dyn Model, effects: Vec<UserEffect>) -> Result<Self, EffectError> {
        let mut info = base.info().clone();
        let base_len = info.full_len();
        let places = base.places();
        let mut compiled = Vec::with_capacity(effects.len());
        let mut first = 0;
        for (i, e) in effects.iter().enumerate() {
            let field = |what: &str| format!("effects[{i}].{what}");
            if !well_formed(&e.name, true) {
                return refuse(
                    field("name"),
                    format!(
                        "`{}` is not a name: letters, digits and `_`, in parts joined by dots",
                        e.name
                    ),
                );
            }
            if effects[..i].iter().any(|o| o.name == e.name) {
                return refuse(field("name"), format!("`{}` is defined twice", e.name));
            }
            if !places.iter().any(|p| p.kind == e.kind && p.name == e.place) {
                let known = places
                    .iter()
                    .filter(|p| p.kind == e.kind)
                    .map(|p| p.name.as_str());
                let listing = format!("`calib models {}` lists its places", info.name);
                return refuse(
                    field(e.kind.word()),
                    format!(
                        "model `{}` has no {} `{}`{}",
                        info.name,
                        e.kind.word(),
                        e.place,
                        hint(&e.place, known, &listing)
                    ),
                );
            }
            let known = variables(base, e.kind, e);
            add_parameters(&mut info, i, e, &known)?;
            let formula = compile(i, e, &known)?;
            compiled.push(Definition {
                formula,
                name: e.name.as_str().into(),
                text: e.formula.as_str().into(),
                first,
                count: e.parameters.len(),
                output: (e.kind == PlaceKind::Output)
                    .then(|| info.output_index(&e.place))
                    .flatten(),
            });
            first += e.parameters.len();
        }
        Ok(Self {
            base,
            info,
            base_len,
            definitions: effects,
            compiled,
        })
    }

    /// The model the effects are attached to.
    pub fn base(&self) -> &'static dyn Model {
        self.base
    }

    /// Apply the output transformations, in the order written, to `values` (every output
    /// of the base model that `values` holds, at `slot[o]`); a term that is not a number
    /// fails the simulation at its time.
    fn transform(
        &self,
        user: &[f64],
        grid: &[f64],
        inputs: &Inputs,
        values: &mut [Vec<f64>],
        slot: &[Option<usize>],
    ) -> Result<(), SimulationError> {
        let outputs = self.info.outputs.len();
        let n_inputs = self.info.inputs.len();
        for c in &self.compiled {
            let Some(target) = c.output else { continue };
            let params = &user[c.first..c.first + c.count];
            let k = slot[target].expect("the transformed output is simulated");
            for (i, &t) in grid.iter().enumerate() {
                let v = c.formula.eval_by(|name| {
                    if name == 0 {
                        values[k][i]
                    } else if name <= outputs {
                        values[slot[name - 1].expect("a read output is simulated")][i]
                    } else if name <= outputs + n_inputs {
                        inputs.signal(name - outputs - 1).map_or(0.0, |s| s.at(t))
                    } else if name == outputs + n_inputs + 1 {
                        t
                    } else {
                        params[name - outputs - n_inputs - 2]
                    }
                });
                if !v.is_finite() {
                    return Err(SimulationError::Failed {
                        time: t,
                        reason: format!(
                            "the term of effect `{}` on `{}` is {v} (formula `{}`)",
                            c.name,
                            self.info.outputs[target].name,
                            super::shortened(&c.text)
                        ),
                    });
                }
                values[k][i] += v;
            }
        }
        Ok(())
    }
}

impl Model for WithUserEffects {
    fn info(&self) -> &ModelInfo {
        &self.info
    }

    fn default_options(&self) -> SolverOptions {
        self.base.default_options()
    }

    fn tolerance_origin(&self) -> &'static str {
        self.base.tolerance_origin()
    }

    fn default_stop_time(&self) -> f64 {
        self.base.default_stop_time()
    }

    fn places(&self) -> Vec<PlaceSpec> {
        self.base.places()
    }

    fn state_names(&self) -> Vec<String> {
        self.base.state_names()
    }

    fn user_effects(&self) -> &[UserEffect] {
        &self.definitions
    }

    fn simulate(&self, run: &Run) -> Result<Trajectory, SimulationError> {
        run.refuse_forces(self.info())?;
        let Run {
            params,
            grid,
            outputs,
            options,
            inputs,
            ..
        } = *run;
        check_request(&self.info, params, grid, outputs)?;
        let (base_params, user) = params.split_at(self.base_len);
        let states = self.base.state_names().len();
        let forces = Forces {
            terms: self
                .compiled
                .iter()
                .zip(&self.definitions)
                .filter(|(_, d)| d.kind == PlaceKind::Torque)
                .map(|(c, d)| {
                    Force::new(
                        d.place.clone(),
                        (c.name.clone(), c.text.clone()),
                        c.formula.clone(),
                        (states, self.info.inputs.len()),
                        user[c.first..c.first + c.count].to_vec(),
                    )
                })
                .collect(),
        };
        // The outputs asked for, then those the transformations read or change.
        let mut wanted: Vec<usize> = outputs.to_vec();
        let n = self.info.outputs.len();
        for c in self.compiled.iter().filter(|c| c.output.is_some()) {
            let read = c.formula.reads().iter().filter(|&&k| k >= 1 && k <= n);
            for o in c.output.into_iter().chain(read.map(|k| k - 1)) {
                if !wanted.contains(&o) {
                    wanted.push(o);
                }
            }
        }
        let mut trajectory = self.base.simulate(
            &Run::new(base_params, grid, &wanted, options)
                .driven(inputs)
                .forced(&forces),
        )?;
        if wanted.len() > outputs.len() || self.compiled.iter().any(|c| c.output.is_some()) {
            let mut slot = vec![None; n];
            for (k, &o) in wanted.iter().enumerate() {
                slot[o].get_or_insert(k);
            }
            self.transform(user, grid, inputs, &mut trajectory.values, &slot)?;
            // Requested outputs listed twice read the same transformed series.
            let values = outputs
                .iter()
                .map(|&o| trajectory.values[slot[o].expect("requested")].clone())
                .collect();
            trajectory.values = values;
        }
        Ok(trajectory)
    }
}
