//! `furuta`: a Furuta (rotary inverted) pendulum in free swing, with stick–slip bearings.
//!
//! The model of the Lund University rig used by the seed (`Furuta.mo`, a Modelica MultiBody
//! model shipped with the JModelica.org examples), written as ordinary differential equations.
//!
//! State `[φ, θ, φ̇, θ̇]`: arm angle about the vertical axis and pendulum angle about the arm
//! axis, `θ = 0` with the pendulum upright (it falls and settles at π). With `s = sin θ`,
//! `c = cos θ`, arm length `L1` (arm joint to pendulum joint), arm inertia `J` about the
//! vertical axis, pendulum mass `m`, joint-to-centre-of-mass distance `l` and the pendulum's
//! principal inertias about its centre of mass `Ixx` (swing axis), `Iyy` (long axis), `Izz`:
//!
//! ```text
//! A(θ) = J + m·L1² + m·l²·s² + Iyy·c² + Izz·s²      A'(θ) = 2·(m·l² + Izz − Iyy)·s·c
//! B = Ixx + m·l²                                    C = m·L1·l
//! [ A     −C·c ] [φ̈]   [ τ1 − A'·θ̇·φ̇ − C·s·θ̇²  ]
//! [ −C·c   B   ] [θ̈] = [ τ2 + ½·A'·φ̇² + m·g·l·s ]
//! ```
//!
//! The mass matrix is that of the kinetic energy
//! `T = ½·A·φ̇² − C·c·φ̇·θ̇ + ½·B·θ̇²` and the potential is `V = m·g·l·c`, so with no torques
//! `E = T + V` is conserved (a test checks it).
//!
//! ## Bearing friction: Coulomb with stick–slip
//!
//! As Modelica's `BearingFriction` with a constant friction table and `peak = 1`, each joint is
//! in one of three modes: sliding forward (`τ = −F`), sliding backward (`τ = +F`) or stuck.
//! A stuck joint has zero speed and zero acceleration; its friction torque is whatever holds
//! it, found by solving the 2×2 system with that joint's acceleration fixed at 0. Events,
//! located on the dense output of the integrator, switch the modes:
//! - a sliding joint whose speed crosses zero stops there; it stays stuck if the holding
//!   torque is within `F`, otherwise it slides on in the direction the net torque drives it;
//! - a stuck joint breaks away when its holding torque exceeds `F`.
//!
//! No smoothing is involved: a joint whose driving torque stays below its friction does not
//! creep (a test checks it).
//!
//! ## Effects (absent at 0)
//!
//! Per joint (`arm`: q = φ, `pendulum`: q = θ), each subtracted from that joint's torque:
//! `viscous_friction.<joint>` d·ω, `quadratic_drag.<joint>` c·ω·|ω|, `stiffness.<joint>`
//! k·q, `torque_bias.<joint>` t0. Viscous friction and drag vanish while a joint is stuck;
//! stiffness and bias act as driving torques the friction must hold.

use crate::inputs::InputSignal;
use crate::model::{
    check_request, EffectSpec, InputSpec, Model, ModelInfo, OutputSpec, ParameterSpec, PlaceKind,
    PlaceSpec, SimulationError, Trajectory,
};
use crate::ode::{integrate, HybridSystem};
use crate::user_effects::Force;
use crate::Run;
use std::f64::consts::PI;

/// Indices of the full parameter vector (base parameters, then effects).
mod idx {
    pub const ARM_FRICTION: usize = 0;
    pub const PENDULUM_FRICTION: usize = 1;
    pub const ARM_LENGTH: usize = 2;
    pub const ARM_INERTIA: usize = 3;
    pub const PEND_MASS: usize = 4;
    pub const PEND_COM: usize = 5;
    pub const PEND_IXX: usize = 6;
    pub const PEND_IYY: usize = 7;
    pub const PEND_IZZ: usize = 8;
    pub const G: usize = 9;
    pub const PHI0: usize = 10;
    pub const THETA0: usize = 11;
    pub const DPHI0: usize = 12;
    pub const DTHETA0: usize = 13;
    pub const BASE: usize = 14;
    // Effects, arm then pendulum for each kind.
    pub const VISCOUS: usize = BASE;
    pub const QUADRATIC: usize = BASE + 2;
    pub const STIFFNESS: usize = BASE + 4;
    pub const BIAS: usize = BASE + 6;
}

pub const JOINTS: [&str; 2] = ["arm", "pendulum"];

pub struct Furuta {
    info: ModelInfo,
}

impl Default for Furuta {
    fn default() -> Self {
        Self::new()
    }
}

impl Furuta {
    pub fn new() -> Self {
        let p = |name: &str, unit: &str, default: f64, min: f64, max: f64, description: &str| {
            ParameterSpec {
                name: name.into(),
                unit: unit.into(),
                default,
                min,
                max,
                description: description.into(),
            }
        };
        let parameters = vec![
            p(
                "armFriction",
                "N.m",
                0.012,
                0.0,
                0.9,
                "Coulomb friction torque of the arm bearing",
            ),
            p(
                "pendulumFriction",
                "N.m",
                0.002,
                0.0,
                0.9,
                "Coulomb friction torque of the pendulum bearing",
            ),
            p(
                "arm_length",
                "m",
                0.245,
                1e-3,
                5.0,
                "arm joint to pendulum joint (L1)",
            ),
            p(
                "arm_inertia",
                "kg.m2",
                0.001,
                1e-7,
                10.0,
                "arm inertia about the vertical axis (J)",
            ),
            p("pend_mass", "kg", 0.035, 1e-5, 100.0, "pendulum mass (m)"),
            p(
                "pend_com",
                "m",
                0.2105,
                1e-4,
                5.0,
                "pendulum joint to pendulum centre of mass (l)",
            ),
            p(
                "pend_Ixx",
                "kg.m2",
                0.00384,
                0.0,
                10.0,
                "pendulum inertia about its centre of mass, swing axis",
            ),
            p(
                "pend_Iyy",
                "kg.m2",
                0.001,
                0.0,
                10.0,
                "pendulum inertia about its centre of mass, long axis",
            ),
            p(
                "pend_Izz",
                "kg.m2",
                0.001,
                0.0,
                10.0,
                "pendulum inertia about its centre of mass, third axis",
            ),
            p("g", "m/s2", 9.81, 0.0, 30.0, "gravitational acceleration"),
            p("phi0", "rad", 0.0, -100.0, 100.0, "initial arm angle"),
            p(
                "theta0",
                "rad",
                PI / 6.0,
                -100.0,
                100.0,
                "initial pendulum angle (0 = upright)",
            ),
            p("dphi0", "rad/s", 0.0, -100.0, 100.0, "initial arm speed"),
            p(
                "dtheta0",
                "rad/s",
                0.0,
                -100.0,
                100.0,
                "initial pendulum speed",
            ),
        ];
        let mut effects: Vec<EffectSpec> = JOINTS
            .iter()
            .zip(["armFriction", "pendulumFriction"])
            .map(|(joint, parameter)| EffectSpec {
                name: format!("coulomb_friction.{joint}"),
                unit: "N.m".into(),
                min: 0.0,
                max: 0.9,
                description: format!(
                    "Coulomb (stick-slip) friction on the {joint} joint: the base parameter \
                     `{parameter}`, a candidate when a campaign holds it at 0"
                ),
                parameter: Some(parameter.into()),
            })
            .collect();
        let kinds: [(&str, &str, f64, f64, &str); 4] = [
            (
                "viscous_friction",
                "N.m.s/rad",
                0.0,
                1.0,
                "viscous friction: tau -= d*w",
            ),
            (
                "quadratic_drag",
                "N.m.s2/rad2",
                0.0,
                1.0,
                "quadratic drag: tau -= c*w*|w|",
            ),
            (
                "stiffness",
                "N.m/rad",
                -10.0,
                10.0,
                "torsional stiffness: tau -= k*q",
            ),
            (
                "torque_bias",
                "N.m",
                -1.0,
                1.0,
                "constant torque: tau -= t0",
            ),
        ];
        for (kind, unit, min, max, description) in kinds {
            for joint in JOINTS {
                effects.push(EffectSpec {
                    name: format!("{kind}.{joint}"),
                    unit: unit.into(),
                    min,
                    max,
                    description: format!("{description} on the {joint} joint"),
                    parameter: None,
                });
            }
        }
        let o = |name: &str, unit: &str, description: &str| OutputSpec {
            name: name.into(),
            unit: unit.into(),
            description: description.into(),
        };
        let outputs = vec![
            o("armJoint.phi", "rad", "arm angle"),
            o("pendulumJoint.phi", "rad", "pendulum angle, 0 upright"),
            o("armJoint.w", "rad/s", "arm angular speed"),
            o("pendulumJoint.w", "rad/s", "pendulum angular speed"),
        ];
        Self {
            info: ModelInfo {
                name: "furuta".into(),
                version: 1,
                description:
                    "Furuta pendulum in free swing with stick-slip Coulomb bearing friction".into(),
                parameters,
                outputs,
                effects,
                inputs: vec![InputSpec {
                    name: "armTorque".into(),
                    unit: "N.m".into(),
                    description: "motor torque on the arm joint, positive in the direction of \
                                  armJoint.phi (0 when undriven: a free swing)"
                        .into(),
                }],
            },
        }
    }
}

impl Model for Furuta {
    fn info(&self) -> &ModelInfo {
        &self.info
    }

    /// The 40 s free swing of the rig's records.
    fn default_stop_time(&self) -> f64 {
        40.0
    }

    /// A torque on each joint (`armJoint`, `pendulumJoint`), and each output.
    fn places(&self) -> Vec<PlaceSpec> {
        let torques = ["armJoint", "pendulumJoint"].map(|joint| PlaceSpec {
            kind: PlaceKind::Torque,
            name: joint.into(),
            description: format!(
                "generalized torque on the {joint} [N.m], positive in the direction of \
                 {joint}.phi; a driving torque the bearing friction must hold while stuck"
            ),
        });
        let outputs = self.info.outputs.iter().map(|o| PlaceSpec {
            kind: PlaceKind::Output,
            name: o.name.clone(),
            description: format!("added to the output {} ({})", o.name, o.unit),
        });
        torques.into_iter().chain(outputs).collect()
    }

    /// The state `[φ, θ, φ̇, θ̇]` is the outputs in their order.
    fn state_names(&self) -> Vec<String> {
        self.info.outputs.iter().map(|o| o.name.clone()).collect()
    }

    fn simulate(&self, run: &Run) -> Result<Trajectory, SimulationError> {
        let Run {
            params,
            grid,
            outputs,
            options,
            inputs,
            forces,
        } = *run;
        check_request(&self.info, params, grid, outputs)?;
        inputs
            .check(&self.info, 0.0, grid[grid.len() - 1])
            .map_err(SimulationError::InvalidInput)?;
        let mut system = FurutaSystem::new(params)?;
        system.motor = inputs.signal(0).cloned();
        for f in &forces.terms {
            let joint = match f.place.as_str() {
                "armJoint" => 0,
                "pendulumJoint" => 1,
                other => {
                    return Err(SimulationError::InvalidInput(format!(
                        "model `furuta` has no torque `{other}`"
                    )))
                }
            };
            system.forces.push((joint, f.clone()));
        }
        let y0 = [
            params[idx::PHI0],
            params[idx::THETA0],
            params[idx::DPHI0],
            params[idx::DTHETA0],
        ];
        system.settle_modes(0.0, &y0);
        let mut values = vec![vec![0.0; grid.len()]; outputs.len()];
        let stats = integrate(&mut system, &y0, grid, options, |i, y| {
            for (series, &o) in values.iter_mut().zip(outputs) {
                series[i] = y[o];
            }
        })
        .map_err(|e| system.blame(e))?;
        Ok(Trajectory {
            time: grid.to_vec(),
            values,
            stats,
        })
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Mode {
    Forward,
    Backward,
    Stuck,
}

/// The equations of motion with the current bearing modes.
pub(crate) struct FurutaSystem {
    friction: [f64; 2],
    viscous: [f64; 2],
    quadratic: [f64; 2],
    stiffness: [f64; 2],
    bias: [f64; 2],
    /// J + m·L1² + Iyy, the θ-independent part of A.
    a0: f64,
    /// m·l² + Izz − Iyy: A = a0 + a1·s².
    a1: f64,
    b: f64,
    c: f64,
    mgl: f64,
    modes: [Mode; 2],
    /// The arm's motor torque, when a signal drives it.
    motor: Option<InputSignal>,
    /// Torques of user-defined effects, each on a joint.
    forces: Vec<(usize, Force)>,
    /// The first torque of `forces` found not to be a number, at any stage a step tried:
    /// its index, time and value. When the integration fails, it is the cause named.
    fault: std::cell::Cell<Option<(usize, f64, f64)>>,
}

/// Accelerations and bearing friction torques in one mode configuration.
struct Dynamics {
    acc: [f64; 2],
    friction: [f64; 2],
}

impl FurutaSystem {
    fn new(p: &[f64]) -> Result<Self, SimulationError> {
        let (l1, j, m, l) = (
            p[idx::ARM_LENGTH],
            p[idx::ARM_INERTIA],
            p[idx::PEND_MASS],
            p[idx::PEND_COM],
        );
        let (ixx, iyy, izz) = (p[idx::PEND_IXX], p[idx::PEND_IYY], p[idx::PEND_IZZ]);
        let pair = |i: usize| [p[i], p[i + 1]];
        let system = Self {
            friction: [p[idx::ARM_FRICTION], p[idx::PENDULUM_FRICTION]],
            viscous: pair(idx::VISCOUS),
            quadratic: pair(idx::QUADRATIC),
            stiffness: pair(idx::STIFFNESS),
            bias: pair(idx::BIAS),
            a0: j + m * l1 * l1 + iyy,
            a1: m * l * l + izz - iyy,
            b: ixx + m * l * l,
            c: m * l1 * l,
            mgl: m * p[idx::G] * l,
            modes: [Mode::Forward; 2],
            motor: None,
            forces: Vec::new(),
            fault: std::cell::Cell::new(None),
        };
        if system.friction.iter().any(|f| *f < 0.0) {
            return Err(SimulationError::InvalidInput(
                "Coulomb friction must be non-negative".into(),
            ));
        }
        // The mass matrix must stay positive definite for every θ: A·B > C² at its minimum.
        let a_min = system.a0 + system.a1.min(0.0);
        if !(a_min > 0.0 && system.b > 0.0 && a_min * system.b > system.c * system.c) {
            return Err(SimulationError::InvalidInput(
                "inertia parameters give a singular mass matrix".into(),
            ));
        }
        Ok(system)
    }

    /// `e`, or the torque of a user's effect that stopped being a number first (the step
    /// size collapses on a torque that is NaN at every stage tried).
    fn blame(&self, e: SimulationError) -> SimulationError {
        match self.fault.get() {
            Some((k, t, v)) => self.forces[k].1.not_finite(t, v),
            None => e,
        }
    }

    /// Right-hand side of the equations of motion at time `t` without bearing friction,
    /// and the mass matrix entries `(A, C·c)`.
    fn free_forces(&self, t: f64, y: &[f64]) -> ([f64; 2], f64, f64) {
        let (s, c) = y[1].sin_cos();
        let (w1, w2) = (y[2], y[3]);
        let a = self.a0 + self.a1 * s * s;
        let da = 2.0 * self.a1 * s * c;
        let mut r = [
            -da * w2 * w1 - self.c * s * w2 * w2,
            0.5 * da * w1 * w1 + self.mgl * s,
        ];
        for (joint, rj) in r.iter_mut().enumerate() {
            let (q, w) = (y[joint], y[joint + 2]);
            *rj -= self.viscous[joint] * w
                + self.quadratic[joint] * w * w.abs()
                + self.stiffness[joint] * q
                + self.bias[joint];
        }
        if let Some(motor) = &self.motor {
            r[0] += motor.at(t);
        }
        for (k, (joint, force)) in self.forces.iter().enumerate() {
            let motor = |_: usize| self.motor.as_ref().map_or(0.0, |m| m.at(t));
            let v = force.value(t, y, motor);
            if !v.is_finite() && self.fault.get().is_none() {
                self.fault.set(Some((k, t, v)));
            }
            r[*joint] += v;
        }
        (r, a, self.c * c)
    }

    /// Accelerations and friction torques at time `t` with the joints in `modes`.
    fn dynamics(&self, t: f64, y: &[f64], modes: [Mode; 2]) -> Dynamics {
        let (r, a, cc) = self.free_forces(t, y);
        let sliding = |joint: usize| match modes[joint] {
            Mode::Forward => -self.friction[joint],
            Mode::Backward => self.friction[joint],
            Mode::Stuck => 0.0,
        };
        match modes {
            [Mode::Stuck, Mode::Stuck] => Dynamics {
                acc: [0.0, 0.0],
                friction: [-r[0], -r[1]],
            },
            [Mode::Stuck, _] => {
                let f2 = sliding(1);
                let a2 = (r[1] + f2) / self.b;
                Dynamics {
                    acc: [0.0, a2],
                    friction: [-cc * a2 - r[0], f2],
                }
            }
            [_, Mode::Stuck] => {
                let f1 = sliding(0);
                let a1 = (r[0] + f1) / a;
                Dynamics {
                    acc: [a1, 0.0],
                    friction: [f1, -cc * a1 - r[1]],
                }
            }
            _ => {
                let f = [sliding(0), sliding(1)];
                let (r1, r2) = (r[0] + f[0], r[1] + f[1]);
                let det = a * self.b - cc * cc;
                Dynamics {
                    acc: [(self.b * r1 + cc * r2) / det, (cc * r1 + a * r2) / det],
                    friction: f,
                }
            }
        }
    }

    /// Bring the modes in line with the state: joints at rest stick if their friction can
    /// hold them and slide the way they are driven otherwise; moving joints slide.
    fn settle_modes(&mut self, t: f64, y: &[f64]) {
        for joint in 0..2 {
            let w = y[joint + 2];
            if w != 0.0 || self.friction[joint] == 0.0 {
                self.modes[joint] = if w >= 0.0 {
                    Mode::Forward
                } else {
                    Mode::Backward
                };
            } else {
                self.modes[joint] = Mode::Stuck;
            }
        }
        // Release stuck joints that cannot be held, one at a time (releasing one changes what
        // holds the other), until the configuration is consistent.
        for _ in 0..3 {
            let d = self.dynamics(t, y, self.modes);
            let overloaded = (0..2)
                .filter(|&j| self.modes[j] == Mode::Stuck)
                .map(|j| (j, d.friction[j].abs() - self.friction[j]))
                .filter(|(_, excess)| *excess > 0.0)
                .max_by(|a, b| a.1.total_cmp(&b.1));
            let Some((joint, _)) = overloaded else {
                return;
            };
            self.modes[joint] = if d.friction[joint] > 0.0 {
                Mode::Backward
            } else {
                Mode::Forward
            };
        }
    }
}

impl HybridSystem for FurutaSystem {
    fn dim(&self) -> usize {
        4
    }

    fn rhs(&self, t: f64, y: &[f64], dy: &mut [f64]) {
        let d = self.dynamics(t, y, self.modes);
        dy[0] = y[2];
        dy[1] = y[3];
        dy[2] = d.acc[0];
        dy[3] = d.acc[1];
    }

    fn event_count(&self) -> usize {
        2
    }

    fn events(&self, t: f64, y: &[f64], g: &mut [f64]) {
        let mut holding = None;
        for joint in 0..2 {
            g[joint] = match self.modes[joint] {
                _ if self.friction[joint] == 0.0 => 1.0,
                Mode::Forward => y[joint + 2],
                Mode::Backward => -y[joint + 2],
                Mode::Stuck => {
                    let d = holding.get_or_insert_with(|| self.dynamics(t, y, self.modes));
                    self.friction[joint] - d.friction[joint].abs()
                }
            };
        }
    }

    fn event_name(&self, event: usize) -> String {
        format!("{} bearing stick-slip", JOINTS[event])
    }

    /// A user's torque that is not a number at a step kept ends the simulation there,
    /// naming it: a stuck joint would otherwise hold it silently (its acceleration is 0
    /// whatever the torque).
    fn check_step(&self, t: f64, y: &[f64]) -> Result<(), SimulationError> {
        let motor = |_: usize| self.motor.as_ref().map_or(0.0, |m| m.at(t));
        for (_, force) in &self.forces {
            let v = force.value(t, y, motor);
            if !v.is_finite() {
                return Err(force.not_finite(t, v));
            }
        }
        Ok(())
    }

    // No `on_chattering`: each joint has its sticking mode already, entered at every stop it
    // can hold, so switching that still accumulates has no mode to settle in and ends the
    // simulation with a typed error.

    fn on_event(&mut self, t: f64, y: &mut [f64], event: usize) {
        if self.modes[event] != Mode::Stuck {
            // The joint came to rest.
            y[event + 2] = 0.0;
        }
        for joint in 0..2 {
            if self.modes[joint] == Mode::Stuck {
                y[joint + 2] = 0.0;
            }
        }
        self.settle_modes(t, y);
    }
}

/// The equations of motion at one state, for inverse dynamics (discovering a missing torque
/// from a measured trajectory): `M(θ)·q̈ = forces + friction + τ_missing`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointDynamics {
    /// The mass matrix `[[A, −C·c], [−C·c, B]]` at the state's pendulum angle.
    pub mass: [[f64; 2]; 2],
    /// Every generalized force on `[φ, θ]` but the Coulomb bearing frictions: Coriolis,
    /// centrifugal and gravity terms, the effects of `params`, and `arm_torque` on the arm.
    pub forces: [f64; 2],
    /// The Coulomb friction levels `F` of the two joints (`−F·sign(ω)` while sliding).
    pub coulomb: [f64; 2],
}

/// [`JointDynamics`] of the model with the full parameter vector `params` (as simulated) at
/// state `y = [φ, θ, φ̇, θ̇]` with motor torque `arm_torque` [N m].
pub fn joint_dynamics(
    params: &[f64],
    y: &[f64; 4],
    arm_torque: f64,
) -> Result<JointDynamics, SimulationError> {
    if params.len() < idx::BIAS + 2 {
        return Err(SimulationError::InvalidInput(format!(
            "furuta: {} parameters given, at least {} expected",
            params.len(),
            idx::BIAS + 2
        )));
    }
    let system = FurutaSystem::new(params)?;
    let (mut forces, a, cc) = system.free_forces(0.0, y);
    forces[0] += arm_torque;
    Ok(JointDynamics {
        mass: [[a, -cc], [-cc, system.b]],
        forces,
        coulomb: system.friction,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::inputs::Inputs;
    use crate::SolverOptions;

    fn defaults() -> Vec<f64> {
        Furuta::new().info().default_vector()
    }

    fn grid(stop: f64, step: f64) -> Vec<f64> {
        let n = (stop / step).round() as usize;
        (0..=n).map(|i| i as f64 * step).collect()
    }

    fn energy(s: &FurutaSystem, y: &[f64]) -> f64 {
        let (sn, c) = y[1].sin_cos();
        let a = s.a0 + s.a1 * sn * sn;
        0.5 * a * y[2] * y[2] - s.c * c * y[2] * y[3] + 0.5 * s.b * y[3] * y[3] + s.mgl * c
    }

    #[test]
    fn frictionless_swing_conserves_energy() {
        let mut p = defaults();
        p[idx::ARM_FRICTION] = 0.0;
        p[idx::PENDULUM_FRICTION] = 0.0;
        p[idx::DPHI0] = 1.0; // excite both joints
        let model = Furuta::new();
        let t = grid(40.0, 0.01);
        let traj = model
            .simulate(&Run::new(&p, &t, &[0, 1, 2, 3], &SolverOptions::default()))
            .unwrap();
        let system = FurutaSystem::new(&p).unwrap();
        let e0 = energy(&system, &[p[10], p[11], p[12], p[13]]);
        let worst = (0..t.len())
            .map(|i| {
                let y: Vec<f64> = traj.values.iter().map(|v| v[i]).collect();
                ((energy(&system, &y) - e0) / e0).abs()
            })
            .fold(0.0, f64::max);
        assert!(worst < 1e-6, "relative energy drift {worst:e}");
    }

    #[test]
    fn tight_tolerance_matches_calibration_tolerance() {
        let model = Furuta::new();
        let p = defaults();
        let t = grid(40.0, 0.01);
        let calib = SolverOptions::default();
        let tight = SolverOptions {
            rtol: 1e-12,
            atol: 1e-14,
            max_steps: 10_000_000,
            ..SolverOptions::default()
        };
        let a = model.simulate(&Run::new(&p, &t, &[0, 1], &calib)).unwrap();
        let b = model.simulate(&Run::new(&p, &t, &[0, 1], &tight)).unwrap();
        let worst = a
            .values
            .iter()
            .flatten()
            .zip(b.values.iter().flatten())
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f64::max);
        // Angles are O(1) rad: the global error must stay within the calibration tolerance's
        // reach, far below the 2 mrad sensor noise.
        assert!(worst < 1e-5, "max deviation {worst:e} rad");
    }

    #[test]
    fn a_joint_driven_below_its_friction_does_not_creep() {
        // Pendulum hanging at rest, arm pushed by a constant bias below its Coulomb friction.
        let mut p = defaults();
        p[idx::THETA0] = PI;
        p[idx::ARM_FRICTION] = 0.012;
        p[idx::BIAS] = 0.011; // torque −0.011 N·m on the arm
        let model = Furuta::new();
        let t = grid(40.0, 0.1);
        let traj = model
            .simulate(&Run::new(&p, &t, &[0, 2], &SolverOptions::default()))
            .unwrap();
        assert!(traj.values[0].iter().all(|phi| *phi == 0.0));
        assert!(traj.values[1].iter().all(|w| *w == 0.0));
        // Just above the friction it must move.
        p[idx::BIAS] = 0.013;
        let traj = model
            .simulate(&Run::new(&p, &t, &[0], &SolverOptions::default()))
            .unwrap();
        assert!(traj.values[0].last().unwrap() < &-0.1);
    }

    #[test]
    fn swing_settles_hanging_down_and_sticks() {
        let model = Furuta::new();
        let p = defaults();
        let t = grid(120.0, 0.5);
        let traj = model
            .simulate(&Run::new(&p, &t, &[1, 3, 2], &SolverOptions::default()))
            .unwrap();
        let theta_end = *traj.values[0].last().unwrap();
        assert!((theta_end - PI).abs() < 0.1, "θ(end) = {theta_end}");
        // Coulomb friction stops the motion in finite time: exactly zero speed at the end.
        assert_eq!(*traj.values[1].last().unwrap(), 0.0);
        assert_eq!(*traj.values[2].last().unwrap(), 0.0);
    }

    fn constant(input: usize, value: f64, stop: f64) -> Inputs {
        Inputs {
            signals: vec![InputSignal {
                input,
                times: vec![0.0, stop].into(),
                values: vec![value, value].into(),
                interpolation: crate::inputs::Interpolation::Linear,
            }],
        }
    }

    #[test]
    fn a_constant_arm_torque_is_a_negative_torque_bias() {
        // The motor torque drives the arm as the bias effect would, with the opposite
        // sign: the same sum, so the same bits.
        let model = Furuta::new();
        let t = grid(10.0, 0.01);
        let options = SolverOptions::default();
        let driven = model
            .simulate(
                &Run::new(&defaults(), &t, &[0, 1], &options).driven(&constant(0, 0.02, 10.0)),
            )
            .unwrap();
        let mut biased = defaults();
        biased[idx::BIAS] = -0.02;
        let reference = model
            .simulate(&Run::new(&biased, &t, &[0, 1], &options))
            .unwrap();
        assert_eq!(driven.values, reference.values);
        assert!(
            driven.values[0].last().unwrap() > &1.0,
            "the arm was driven"
        );
    }

    #[test]
    fn an_input_must_cover_the_simulation() {
        let model = Furuta::new();
        let t = grid(10.0, 0.1);
        let r = model.simulate(
            &Run::new(&defaults(), &t, &[0], &SolverOptions::default())
                .driven(&constant(0, 0.02, 5.0)),
        );
        let Err(SimulationError::InvalidInput(message)) = r else {
            panic!("{r:?}");
        };
        assert!(
            message.contains("armTorque") && message.contains("cover"),
            "{message}"
        );
    }

    #[test]
    fn bad_parameters_are_typed_errors() {
        let model = Furuta::new();
        let mut p = defaults();
        p[idx::PEND_IXX] = -1.0;
        p[idx::PEND_MASS] = 1.0;
        let r = model.simulate(&Run::new(&p, &[1.0], &[0], &SolverOptions::default()));
        assert!(matches!(r, Err(SimulationError::InvalidInput(_))), "{r:?}");
        let mut p = defaults();
        p[0] = f64::NAN;
        let r = model.simulate(&Run::new(&p, &[1.0], &[0], &SolverOptions::default()));
        assert!(matches!(r, Err(SimulationError::InvalidInput(_))));
    }

    #[test]
    fn joint_dynamics_inverts_the_equations_of_motion() {
        // Both joints sliding: M·q̈ from the simulated right-hand side is the sum of the
        // forces and the sliding frictions.
        let mut p = defaults();
        p[idx::VISCOUS] = 0.003;
        let y = [0.4, 2.5, 1.2, -0.7];
        let mut system = FurutaSystem::new(&p).unwrap();
        system.motor = Some(constant(0, 0.02, 1.0).signals[0].clone());
        system.settle_modes(0.5, &y);
        let mut dy = [0.0; 4];
        system.rhs(0.5, &y, &mut dy);
        let d = joint_dynamics(&p, &y, 0.02).unwrap();
        for j in 0..2 {
            let lhs = d.mass[j][0] * dy[2] + d.mass[j][1] * dy[3];
            let rhs = d.forces[j] - d.coulomb[j] * y[j + 2].signum();
            assert!((lhs - rhs).abs() < 1e-14, "joint {j}: {lhs} != {rhs}");
        }
        assert!(joint_dynamics(&p[..10], &y, 0.0).is_err());
    }
}
