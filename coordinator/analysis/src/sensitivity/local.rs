//! Sensitivity at the fit: whether a parameter that hardly matters over the bounds matters
//! where the calibration ended.
//!
//! The global indices ([`super::analyse`]) average over the whole box, where one output's
//! errors far from any fit can drown everything else, and where a joint that sticks over
//! most of the box hides every parameter that acts on it moving. Near the best point the
//! picture can differ: the parameters the box-wide variance was made of are pinned, and one
//! that looked negligible may be what the remaining fit hangs on.
//!
//! At the point of a calibration's result, each output's sensitivity to each parameter is
//! taken by central differences of [`UNIT_STEP`] on the parameter's search scale mapped to
//! the unit box (as the global analysis samples it), so that parameters on different scales
//! compare. The **local index** of parameter `i` on output `o` is its share of that output's
//! squared sensitivities, `‖∂y_o/∂u_i‖² / Σ_j ‖∂y_o/∂u_j‖²`; on the objective the same with
//! every output weighted as the objective weights it, `Σ_o k_o ‖∂y_o/∂u_i‖²` (the diagonal of
//! the Gauss–Newton approximation of the objective's curvature, as a share of its trace).
//! A parameter is called fixable only when its global index and its local index are both
//! below [`super::INFLUENTIAL_TOTAL`] on the objective and on every output.

use super::{Sensitivity, INFLUENTIAL_TOTAL};
use crate::residuals::jacobian::series_weights;
use calib_engine::calibration::load_measurement;
use calib_engine::campaign::Campaign;
use calib_engine::error::{Error, Result};
use calib_engine::evaluator::Simulator;
use calib_engine::objective::Objective;
use calib_engine::optim::space::UnitBox;
use calib_engine::outcome::CalibrationOutcome;
use calib_engine::store::Store;

/// Central-difference step on the unit box of the scaled bounds.
pub const UNIT_STEP: f64 = 1e-3;

/// The local sensitivities at a calibration's best point.
#[derive(Debug, Clone, PartialEq)]
pub struct AtFit {
    /// Where the point comes from: a result file, or the store's result of the campaign.
    pub source: String,
    /// The free parameters' values there, in campaign order.
    pub point: Vec<f64>,
    /// The objective the result reports there.
    pub objective: f64,
    /// Per quantity (the objective, then each output, as [`Sensitivity::quantities`]), per
    /// parameter: the local index.
    pub indices: Vec<Vec<f64>>,
    /// Trajectories simulated for the differences.
    pub simulated: usize,
}

/// The best point of `outcome` for `campaign`'s free parameters, by name: an error naming
/// `source` and the parameter when one is missing from the result or outside the bounds.
pub fn best_point(
    campaign: &Campaign,
    outcome: &CalibrationOutcome,
    source: &str,
) -> Result<Vec<f64>> {
    campaign
        .free
        .iter()
        .map(|p| {
            let v = *outcome.best.parameters.get(&p.name).ok_or_else(|| {
                Error::InvalidRequest(format!(
                    "{source}: best.parameters has no `{}`, a free parameter of campaign `{}`",
                    p.name, campaign.name
                ))
            })?;
            if !(p.min..=p.max).contains(&v) {
                return Err(Error::InvalidRequest(format!(
                    "{source}: best.parameters.{} = {v} lies outside its bounds [{}, {}] in \
                     campaign `{}`",
                    p.name, p.min, p.max, campaign.name
                )));
            }
            Ok(v)
        })
        .collect()
}

/// The result the store holds for `campaign` on its current data (what `calib calibrate`
/// with the same store recorded), if it finished.
pub fn stored_result(campaign: &Campaign, store: &dyn Store) -> Result<Option<CalibrationOutcome>> {
    let measurement = load_measurement(campaign)?;
    let id = campaign.identity(&measurement.content_hash());
    Ok(store.campaign(&id)?.and_then(|record| record.result))
}

/// Read a `result.json`.
pub fn read_result(path: &std::path::Path) -> Result<CalibrationOutcome> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::InvalidRequest(format!("{}: cannot be read: {e}", path.display())))?;
    serde_json::from_str(&text).map_err(|e| {
        Error::InvalidRequest(format!("{}: not a calibration result: {e}", path.display()))
    })
}

/// The local indices of `campaign`'s free parameters at `point` (see the module
/// documentation), `objective` the value reported there.
pub fn at_fit<S: Simulator>(
    campaign: &Campaign,
    simulator: &S,
    point: &[f64],
    objective_value: f64,
    source: String,
) -> Result<AtFit> {
    let measurement = load_measurement(campaign)?;
    let objective = Objective::new(campaign, &measurement)?;
    let space = UnitBox::new(&campaign.free);
    let centre = space.to_unit(point);
    let mut points = Vec::with_capacity(2 * centre.len());
    let mut widths = Vec::with_capacity(centre.len());
    for i in 0..centre.len() {
        let up = (centre[i] + UNIT_STEP).min(1.0);
        let down = (centre[i] - UNIT_STEP).max(0.0);
        for u in [up, down] {
            let mut unit = centre.clone();
            unit[i] = u;
            let mut physical = space.to_physical(&unit);
            // Only parameter i moves: the others keep their values exactly.
            for (j, v) in physical.iter_mut().enumerate() {
                if j != i {
                    *v = point[j];
                }
            }
            points.push(physical);
        }
        widths.push(up - down);
    }
    let simulated = simulator.simulate(&objective, &points)?;
    let weights = series_weights(&objective);
    // squared[s][i]: ‖∂y_s/∂u_i‖², series s weighted as the objective weighs it.
    let mut squared = vec![vec![0.0; centre.len()]; weights.len()];
    for (i, pair) in simulated.chunks(2).enumerate() {
        let series = |k: usize| {
            pair[k].as_ref().map_err(|e| {
                Error::Optimiser(format!(
                    "the simulation at the fit with {} moved failed: {e}",
                    campaign.free[i].name
                ))
            })
        };
        let (up, down) = (series(0)?, series(1)?);
        for (s, (a, b)) in up.iter().zip(down).enumerate() {
            let d: f64 = a
                .iter()
                .zip(b)
                .map(|(x, y)| ((x - y) / widths[i]).powi(2))
                .sum();
            squared[s][i] = weights[s] * d;
        }
    }
    let share = |row: &[f64]| -> Vec<f64> {
        let total: f64 = row.iter().sum();
        row.iter()
            .map(|v| if total > 0.0 { v / total } else { 0.0 })
            .collect()
    };
    let on_objective: Vec<f64> = (0..centre.len())
        .map(|i| squared.iter().map(|row| row[i]).sum())
        .collect();
    let mut indices = vec![share(&on_objective)];
    indices.extend(squared.iter().map(|row| share(row)));
    Ok(AtFit {
        source,
        point: point.to_vec(),
        objective: objective_value,
        indices,
        simulated: points.len(),
    })
}

impl Sensitivity {
    /// Whether parameter `i` matters at the fit: its local index on the objective or on an
    /// output at least [`INFLUENTIAL_TOTAL`]. False without local sensitivities.
    pub fn influential_at_fit(&self, i: usize) -> bool {
        self.at_fit
            .as_ref()
            .is_some_and(|a| a.indices.iter().any(|q| q[i] >= INFLUENTIAL_TOTAL))
    }

    /// The quantity (0: the objective, else an output) that keeps parameter `i` in at the
    /// fit although it is negligible over the bounds: the one where its local index is
    /// largest. `None` when it matters over the bounds or nowhere.
    pub fn kept_at_fit(&self, i: usize) -> Option<usize> {
        if self.influential(i) || !self.influential_at_fit(i) {
            return None;
        }
        let a = self.at_fit.as_ref()?;
        (0..a.indices.len()).max_by(|&p, &q| a.indices[p][i].total_cmp(&a.indices[q][i]))
    }

    /// The sentences of the parameters kept in at the fit.
    pub(super) fn kept_at_fit_sentences(&self) -> String {
        let Some(a) = &self.at_fit else {
            return String::new();
        };
        let mut out = String::new();
        for i in 0..self.parameters.len() {
            if let Some(q) = self.kept_at_fit(i) {
                let what = if q == 0 {
                    "the objective".to_string()
                } else {
                    self.quantities[q].name.clone()
                };
                out.push_str(&format!(
                    " {name} is kept for {what} at the fit: its local index there is \
                     {local:.3} at the best point of {source}, although negligible over \
                     the bounds; holding it fixed would lose the fit there.",
                    name = self.parameters[i],
                    local = a.indices[q][i],
                    source = a.source,
                ));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use calib_engine::evaluator::LocalEvaluator;
    use std::path::Path;

    fn example(name: &str) -> Campaign {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
        Campaign::load(&dir.join(name)).unwrap()
    }

    #[test]
    fn local_indices_are_shares_and_a_parameter_no_output_sees_has_none() {
        let campaign = example("hx_all.toml");
        let point: Vec<f64> = campaign.free.iter().map(|p| p.nominal).collect();
        let a = at_fit(&campaign, &LocalEvaluator, &point, 1.0, "nominal".into()).unwrap();
        assert_eq!(a.indices.len(), 3, "the objective and two outputs");
        assert_eq!(a.simulated, 2 * campaign.free.len());
        for q in &a.indices {
            let sum: f64 = q.iter().sum();
            assert!((sum - 1.0).abs() < 1e-9, "{q:?}");
        }
        // The outputs never see the air-side pressure drop.
        let airdp = campaign
            .free
            .iter()
            .position(|p| p.name == "CF_Airdp")
            .unwrap();
        assert!(a.indices.iter().all(|q| q[airdp] == 0.0), "{:?}", a.indices);
    }

    #[test]
    fn a_result_without_a_free_parameter_or_outside_the_bounds_is_refused_by_name() {
        let campaign = example("hx_all.toml");
        let mut outcome = CalibrationOutcome::default();
        let err = best_point(&campaign, &outcome, "r.json")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("r.json: best.parameters has no `CF_RefHT`"),
            "{err}"
        );
        for p in &campaign.free {
            outcome.best.parameters.insert(p.name.clone(), p.nominal);
        }
        assert_eq!(best_point(&campaign, &outcome, "r.json").unwrap().len(), 8);
        outcome.best.parameters.insert("dp0".into(), 1e6);
        let err = best_point(&campaign, &outcome, "r.json")
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("best.parameters.dp0 = 1000000 lies outside"),
            "{err}"
        );
    }
}
