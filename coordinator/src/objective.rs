//! The calibration objective: weighted least squares over the time window.
//!
//! `f(p) = Σ_i k_i Σ_t (y_i(p, t) − w_i(t))²` with `y_i` the model output read at the
//! measurement times `t` inside the window and `w_i` the measured column mapped to it.
//! `k_i` is the campaign's weight (`weight`, or `1/σ_i²` from `sigma`), divided by the
//! variance of `w_i` over the window for outputs with `scale = "variance"`. The scaling is
//! folded into [`Objective::weights`] here, once, so the worker's scoring (local or remote)
//! and every consumer of the weights (diagnosis, reports) see the same `k_i`.
//! A simulation that fails (diverged, step limit) is not an error here: it evaluates to a
//! large finite penalty, so optimisers move away from it and never stop on it.

use crate::campaign::{Campaign, CampaignError, OutputScale};
use crate::measurement::Measurement;
use calib_worker::content_hash::ContentHasher;
use calib_worker::inputs::{InputSignal, Inputs};
use calib_worker::limits::MAX_TIMES;
use calib_worker::scoring::{self, Target};
use calib_worker::{Model, SimulationError, SolverOptions};

pub use calib_worker::scoring::{Evaluation, FAILURE_PENALTY};

/// Everything needed to score a parameter vector: the model, the fixed parameters, the
/// measured series on the window's grid and the weights.
#[derive(Clone)]
pub struct Objective {
    pub model: &'static dyn Model,
    /// Full parameter vector with the free entries at their nominal values.
    pub base: Vec<f64>,
    /// Positions of the free parameters in the full vector.
    pub free: Vec<usize>,
    /// Measurement times inside the window.
    pub grid: Vec<f64>,
    /// Model output indices, in campaign order.
    pub outputs: Vec<usize>,
    pub weights: Vec<f64>,
    /// Measured series on `grid`, one per output.
    pub measured: Vec<Vec<f64>>,
    pub solver: SolverOptions,
    /// Measured signals driving the model's inputs, over the simulated span.
    pub inputs: Inputs,
    measurement_hash: [u8; 32],
    fingerprint: [u8; 32],
}

impl Objective {
    /// Build the objective of `campaign` on `measurement` (which must hold every mapped column).
    pub fn new(campaign: &Campaign, measurement: &Measurement) -> Result<Self, CampaignError> {
        let (start, stop) = campaign.window;
        let time = &measurement.time;
        let field_error = |field: &str, message: String| CampaignError {
            file: campaign.source.clone().unwrap_or_default(),
            line: None,
            field: field.into(),
            message,
        };
        let window_error = |message: String| field_error("window", message);
        let (first, last) = (time[0], time[time.len() - 1]);
        let slack = 1e-9 * last.abs().max(1.0);
        if start < first - slack || stop > last + slack {
            let field = if stop > last + slack {
                "window.stop"
            } else {
                "window.start"
            };
            return Err(field_error(
                field,
                format!(
                    "[{start}, {stop}] s lies outside the data of {} (time runs from {first} \
                     to {last} s)",
                    measurement.source.display()
                ),
            ));
        }
        let rows: Vec<usize> = (0..time.len())
            .filter(|&i| time[i] >= start - slack && time[i] <= stop + slack)
            .collect();
        if rows.len() < 2 {
            return Err(window_error(format!(
                "[{start}, {stop}] s holds {} samples of {}: too few to fit",
                rows.len(),
                measurement.source.display()
            )));
        }
        if rows.len() > MAX_TIMES {
            return Err(window_error(format!(
                "[{start}, {stop}] s holds {} samples, more than the {MAX_TIMES} one \
                 simulation may return; narrow the window",
                rows.len()
            )));
        }
        if time[rows[0]] < 0.0 {
            return Err(window_error(
                "the model starts at t = 0: the window must not reach negative times".into(),
            ));
        }
        let grid: Vec<f64> = rows.iter().map(|&i| time[i]).collect();
        let measured: Vec<Vec<f64>> = campaign
            .outputs
            .iter()
            .map(|o| {
                let column = measurement
                    .column(&o.measured)
                    .expect("the measurement was loaded with every mapped column");
                rows.iter().map(|&i| column[i]).collect()
            })
            .collect();
        let mut weights = Vec::with_capacity(measured.len());
        for (i, (o, w)) in campaign.outputs.iter().zip(&measured).enumerate() {
            weights.push(match o.scale {
                OutputScale::None => o.weight,
                OutputScale::Variance => {
                    let var = variance(w);
                    if !(var > 0.0 && (o.weight / var).is_finite()) {
                        return Err(CampaignError {
                            file: campaign.source.clone().unwrap_or_default(),
                            line: None,
                            field: format!("outputs[{i}] ({})", o.model),
                            message: format!(
                                "scale = \"variance\": column `{}` of {} has variance {var:e} \
                                 over the window [{start}, {stop}] s, nothing to scale by",
                                o.measured,
                                measurement.source.display()
                            ),
                        });
                    }
                    o.weight / var
                }
            });
        }
        let inputs = driving_inputs(campaign, measurement, campaign.solver.start_time, stop)?;
        let mut objective = Self {
            model: campaign.model,
            base: campaign.base.clone(),
            free: campaign.free.iter().map(|p| p.index).collect(),
            grid,
            outputs: campaign.outputs.iter().map(|o| o.model_index).collect(),
            weights,
            measured,
            solver: campaign.solver,
            inputs,
            measurement_hash: measurement.content_hash(),
            fingerprint: [0; 32],
        };
        objective.fingerprint = objective.compute_fingerprint();
        Ok(objective)
    }

    /// The same objective with every parameter fixed at `full` (the full parameter vector):
    /// nothing left free.
    pub fn fixed_at(&self, full: Vec<f64>) -> Objective {
        let mut o = self.clone();
        o.base = full;
        o.free.clear();
        o.fingerprint = o.compute_fingerprint();
        o
    }

    /// A hash of everything that changes the value of the objective at a given point: model
    /// and version, fixed parameters, which parameters are free, grid, measured data,
    /// output mapping, weights and solver settings.
    pub fn fingerprint(&self) -> [u8; 32] {
        self.fingerprint
    }

    fn compute_fingerprint(&self) -> [u8; 32] {
        let info = self.model.info();
        let mut h = ContentHasher::new(b"calib-objective-v1");
        h.bytes(info.name.as_bytes())
            .bytes(&info.version.to_le_bytes());
        let indices = |h: &mut ContentHasher, v: &[usize]| {
            h.count(v.len());
            for &x in v {
                h.count(x);
            }
        };
        let mut fixed = self.base.clone();
        for &i in &self.free {
            fixed[i] = 0.0;
        }
        h.series(&fixed);
        indices(&mut h, &self.free);
        h.series(&self.grid).bytes(&self.measurement_hash);
        indices(&mut h, &self.outputs);
        h.series(&self.weights)
            .series(&[self.solver.rtol, self.solver.atol])
            .count(self.solver.max_steps);
        // The start and the communication step, when set, change what is simulated; a
        // run without them keeps the fingerprint it always had.
        if self.solver.start_time != 0.0 || self.solver.communication_step.is_some() {
            h.text("time settings").series(&[
                self.solver.start_time,
                self.solver.communication_step.unwrap_or(0.0),
            ]);
        }
        // Inputs likewise: an undriven objective keeps its fingerprint.
        calib_worker::inputs::hash_into(&mut h, &self.named_inputs());
        h.finish()
    }

    /// The driving signals under their inputs' names, as the wire carries them.
    pub fn named_inputs(&self) -> Vec<calib_worker::inputs::NamedSignal> {
        self.inputs.named(self.model.info())
    }

    /// The full parameter vector with the free parameters set to `free_values`.
    pub fn full_parameters(&self, free_values: &[f64]) -> Vec<f64> {
        let mut full = self.base.clone();
        for (&i, v) in self.free.iter().zip(free_values) {
            full[i] = *v;
        }
        full
    }

    /// What points are scored against: grid, outputs, measured series, weights, solver.
    pub fn target(&self) -> Target<'_> {
        Target {
            grid: &self.grid,
            outputs: &self.outputs,
            measured: &self.measured,
            weights: &self.weights,
            solver: &self.solver,
            inputs: &self.inputs,
        }
    }

    /// Simulate at `free_values` and score against the measurement (the same computation a
    /// remote worker makes, bit for bit).
    pub fn evaluate(&self, free_values: &[f64]) -> Evaluation {
        scoring::evaluate(
            self.model,
            &self.full_parameters(free_values),
            &self.target(),
        )
    }

    /// The mapped outputs on the grid at `free_values` (one series per output).
    pub fn simulate(&self, free_values: &[f64]) -> Result<Vec<Vec<f64>>, SimulationError> {
        let params = self.full_parameters(free_values);
        self.model
            .simulate_driven(
                &params,
                &self.grid,
                &self.outputs,
                &self.solver,
                &self.inputs,
            )
            .map(|t| t.values)
    }

    /// Score simulated series (one per output, on the grid).
    pub fn score(&self, simulated: &[Vec<f64>]) -> Evaluation {
        scoring::score(simulated, &self.measured, &self.weights)
    }
}

/// The measured columns mapped to the campaign's inputs, as signals: the whole column (plots
/// may simulate past the window). A column that does not cover the fitted span
/// `[start, stop]` is refused naming file, column and times.
fn driving_inputs(
    campaign: &Campaign,
    measurement: &Measurement,
    start: f64,
    stop: f64,
) -> Result<Inputs, CampaignError> {
    let time = &measurement.time;
    let (first, last) = (time[0], time[time.len() - 1]);
    let slack = 1e-9 * stop.abs().max(1.0);
    let mut signals = Vec::with_capacity(campaign.inputs.len());
    for (i, input) in campaign.inputs.iter().enumerate() {
        let error = |message: String| CampaignError {
            file: campaign.source.clone().unwrap_or_default(),
            line: None,
            field: format!("inputs[{i}] ({})", input.model),
            message,
        };
        let column = measurement.column(&input.measured).ok_or_else(|| {
            error(format!(
                "column `{}` was not loaded from {}",
                input.measured,
                measurement.source.display()
            ))
        })?;
        if first > start + slack || last < stop - slack {
            return Err(error(format!(
                "column `{}` of {} runs from {first} to {last} s and does not cover the                  simulation from {start} to {stop} s",
                input.measured,
                measurement.source.display()
            )));
        }
        signals.push(InputSignal {
            input: input.model_index,
            times: time.as_slice().into(),
            values: column.into(),
            interpolation: input.interpolation,
        });
    }
    Ok(Inputs { signals })
}

/// Population variance of a series.
fn variance(w: &[f64]) -> f64 {
    let n = w.len() as f64;
    let mean = w.iter().sum::<f64>() / n;
    w.iter().map(|v| (v - mean) * (v - mean)).sum::<f64>() / n
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::{Path, PathBuf};

    fn campaign(output_lines: &str) -> Campaign {
        let text = format!(
            r#"
[model]
name = "furuta"
[measurement]
file = "m.csv"
time_column = "t"
[[outputs]]
model = "armJoint.phi"
measured = "phi"
{output_lines}
[[outputs]]
model = "pendulumJoint.phi"
measured = "theta"
[[parameters]]
name = "armFriction"
min = 0.0
max = 0.9
[window]
start = 1.0
stop = 3.0
"#
        );
        Campaign::parse(&text, Path::new("/c/c.toml")).unwrap()
    }

    fn measurement(phi: Vec<f64>) -> Measurement {
        Measurement {
            source: PathBuf::from("/c/m.csv"),
            time: vec![0.0, 1.0, 2.0, 3.0, 4.0],
            columns: vec![
                ("phi".into(), phi),
                ("theta".into(), vec![0.0, 1.0, 2.0, 3.0, 4.0]),
            ],
        }
    }

    #[test]
    fn variance_scaling_is_folded_into_the_weights() {
        // Window rows 1..=3: phi 2, 4, 9 (mean 5, variance (9 + 1 + 16)/3).
        let m = measurement(vec![100.0, 2.0, 4.0, 9.0, -50.0]);
        let o = Objective::new(&campaign("weight = 3.0\nscale = \"variance\""), &m).unwrap();
        assert!(
            (o.weights[0] - 3.0 / (26.0 / 3.0)).abs() < 1e-15,
            "{:?}",
            o.weights
        );
        assert_eq!(o.weights[1], 1.0);
        let plain = Objective::new(&campaign("sigma = 0.25"), &m).unwrap();
        assert_eq!(plain.weights, vec![16.0, 1.0]);
        assert_ne!(o.fingerprint(), plain.fingerprint());
        // The score uses exactly these weights.
        let e = o.score(&[vec![3.0, 4.0, 9.0], vec![1.0, 2.0, 3.0]]);
        assert_eq!(e.objective, o.weights[0] * 1.0);
    }

    #[test]
    fn stored_keys_are_pinned() {
        // Evaluations, campaigns and datasets are stored under these hashes: a change
        // here orphans every existing store, so it must come with a new tag.
        let m = measurement(vec![100.0, 2.0, 4.0, 9.0, -50.0]);
        let c = campaign("weight = 3.0");
        let o = Objective::new(&c, &m).unwrap();
        let key = crate::store::evaluation_key(&o, &[0.25]);
        let identity = c.identity(&m.content_hash());
        let hex = crate::store::hex;
        assert_eq!(
            hex(&m.content_hash()),
            "e26cd9006ea76b9362f5dbbfbe2a88204c7519f99e32b332b641ac51a3893a92"
        );
        assert_eq!(
            hex(&o.fingerprint()),
            "7cc56ea080b1ffff64b4107299beaf036cec5639b19ad620f95a2856e543448a"
        );
        assert_eq!(
            hex(&key),
            "7efd2c123002a3798fded9b4f11ccfb9152407e84dcf6d579dd73f347b40686b"
        );
        assert_eq!(
            hex(&identity),
            "2c9b2ae261a0decfe9b0918be827b43efcfc5d8eddf4f581d25a92c19073576f"
        );
        assert_eq!(
            hex(&calib_worker::scoring::measurement_hash(
                &o.grid,
                &o.measured,
                &[]
            )),
            "1295954f5261deafcbefb6c8019cd73c9867b9b806a12b4fbfcb4281e56fe992"
        );
    }

    #[test]
    fn an_input_column_must_cover_the_window() {
        let with_input = |stop: f64| {
            let c = campaign("");
            let spec = c.spec.replace(
                "[window]",
                "[[inputs]]\nmodel = \"armTorque\"\nmeasured = \"u\"\n[window]",
            );
            let spec = spec.replace("stop = 3.0", &format!("stop = {stop}"));
            Campaign::parse(&spec, Path::new("/c/c.toml")).unwrap()
        };
        let mut m = measurement(vec![100.0, 2.0, 4.0, 9.0, -50.0]);
        m.columns.push(("u".into(), vec![0.0, 0.1, 0.2, 0.3, 0.4]));
        let o = Objective::new(&with_input(3.0), &m).unwrap();
        assert_eq!(o.inputs.signals[0].values.len(), 5);
        assert_ne!(
            o.fingerprint(),
            Objective::new(&campaign(""), &m).unwrap().fingerprint()
        );
        m.time = vec![0.5, 1.0, 2.0, 3.0, 4.0];
        let Err(e) = Objective::new(&with_input(3.0), &m) else {
            panic!("an input that starts after the simulation was accepted");
        };
        assert_eq!(e.field, "inputs[0] (armTorque)");
        assert!(
            e.message.contains("column `u`") && e.message.contains("from 0.5 to 4 s"),
            "{e}"
        );
    }

    #[test]
    fn a_constant_signal_cannot_be_variance_scaled() {
        let m = measurement(vec![0.0, 2.0, 2.0, 2.0, 5.0]);
        let Err(e) = Objective::new(&campaign("scale = \"variance\""), &m) else {
            panic!("a constant column was scaled");
        };
        assert_eq!(e.field, "outputs[0] (armJoint.phi)");
        assert!(e.message.contains("column `phi`"), "{e}");
    }
}
