//! The `furuta` model of the worker as a [`JointModel`]: joints `armJoint` (φ) and
//! `pendulumJoint` (θ), the names its outputs and input carry.

use super::residual::{JointForces, JointModel};
use calib_model::models::furuta::joint_dynamics;

/// The furuta model at one full parameter vector (as simulated: base parameters, effects).
#[derive(Debug, Clone)]
pub struct FurutaJoints {
    pub params: Vec<f64>,
}

impl JointModel for FurutaJoints {
    fn joints(&self) -> Vec<String> {
        vec!["armJoint".into(), "pendulumJoint".into()]
    }

    fn state_names(&self) -> (Vec<String>, Vec<String>) {
        (
            vec!["armJoint.phi".into(), "pendulumJoint.phi".into()],
            vec!["armJoint.w".into(), "pendulumJoint.w".into()],
        )
    }

    fn input_names(&self) -> Vec<String> {
        vec!["armTorque".into()]
    }

    fn forces(&self, q: &[f64], w: &[f64], u: &[f64]) -> Result<JointForces, String> {
        let y = [q[0], q[1], w[0], w[1]];
        let d = joint_dynamics(&self.params, &y, u.first().copied().unwrap_or(0.0))
            .map_err(|e| e.to_string())?;
        Ok(JointForces {
            mass: d.mass.iter().map(|r| r.to_vec()).collect(),
            forces: d.forces.to_vec(),
            coulomb: d.coulomb.to_vec(),
        })
    }
}
