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

use crate::campaign::{Campaign, CampaignError, Experiment, OutputScale};
use crate::measurement::Measurement;
use calib_model::content_hash::ContentHasher;
use calib_model::inputs::{InputSignal, Inputs};
use calib_model::limits::{MAX_RECORD_VALUES, MAX_TIMES};
use calib_model::scoring::{self, Target};
use calib_model::Run;
use calib_model::{Model, SimulationError, SolverOptions};

pub use calib_model::scoring::{Evaluation, FAILURE_PENALTY};

/// Everything needed to score a parameter vector: the model, the fixed parameters, the
/// measured series on the window's grid and the weights. A campaign that fits several
/// experiments is one objective per experiment, the first holding the others in
/// [`Objective::more`]: the value is the sum over all, the series those of each in turn.
#[derive(Clone)]
pub struct Objective {
    pub model: &'static dyn Model,
    /// The experiment's name (empty for a campaign with one record).
    pub name: String,
    /// Full parameter vector with the free entries at their nominal values.
    pub base: Vec<f64>,
    /// Positions of the free parameters in the full vector; `None` for a parameter that
    /// belongs to another experiment (its value does not reach this one).
    pub free: Vec<Option<usize>>,
    /// Measurement times inside the window(s).
    pub grid: Vec<f64>,
    /// Model output indices, in campaign order.
    pub outputs: Vec<usize>,
    pub weights: Vec<f64>,
    /// Measured series on `grid`, one per output.
    pub measured: Vec<Vec<f64>>,
    pub solver: SolverOptions,
    /// Measured signals driving the model's inputs, over the simulated span.
    pub inputs: Inputs,
    /// The further experiments, each an objective of its own over the same free
    /// parameters (their own `more` empty).
    pub more: Vec<Objective>,
    /// Whether evaluations return the weighted residuals beside the objective (see
    /// [`Objective::with_residuals`]).
    residuals: bool,
    measurement_hash: [u8; 32],
    fingerprint: [u8; 32],
}

impl Objective {
    /// Build the objective of `campaign` on `measurement` (which must hold every mapped
    /// column of the first experiment); the records of further experiments are read from
    /// their files.
    pub fn new(campaign: &Campaign, measurement: &Measurement) -> Result<Self, CampaignError> {
        let experiments = campaign.experiments();
        let mut first = Self::part(campaign, &experiments[0], measurement, "")?;
        for (k, experiment) in experiments.iter().enumerate().skip(1) {
            let place = format!("experiments[{k}] ({})", experiment.name);
            let measurement = load_experiment(campaign, experiment, &place)?;
            first.more.push(Self::part(
                campaign,
                experiment,
                &measurement,
                &format!("{place}."),
            )?);
        }
        if !first.more.is_empty() {
            first.fingerprint = first.compute_fingerprint();
        }
        Ok(first)
    }

    /// The objective of one experiment; `place` prefixes the fields errors name.
    fn part(
        campaign: &Campaign,
        experiment: &Experiment,
        measurement: &Measurement,
        place: &str,
    ) -> Result<Self, CampaignError> {
        let (_, stop) = experiment.window;
        let time = &measurement.time;
        let rows = window_rows(campaign, experiment, measurement, place)?;
        let grid: Vec<f64> = rows.iter().map(|&i| time[i]).collect();
        let measured: Vec<Vec<f64>> = experiment
            .outputs
            .iter()
            .map(|o| {
                let column = measurement
                    .column(&o.measured)
                    .expect("the measurement was loaded with every mapped column");
                rows.iter().map(|&i| column[i]).collect()
            })
            .collect();
        let weights = output_weights(campaign, experiment, measurement, &measured, place)?;
        // The inputs must cover what is simulated: plots run to the experiment's stop time.
        let inputs = driving_inputs(
            campaign,
            experiment,
            measurement,
            campaign.solver.start_time,
            stop.max(experiment.stop_time),
            place,
        )?;
        record_fits(campaign, place, &grid, measured.len(), &inputs)?;
        let mut objective = Self {
            model: campaign.model,
            name: experiment.name.clone(),
            base: experiment.base.clone(),
            free: campaign
                .free
                .iter()
                .map(|p| p.applies_to(&experiment.name).then_some(p.index))
                .collect(),
            grid,
            outputs: experiment.outputs.iter().map(|o| o.model_index).collect(),
            weights,
            measured,
            solver: campaign.solver,
            inputs,
            more: Vec::new(),
            residuals: false,
            measurement_hash: measurement.content_hash(),
            fingerprint: [0; 32],
        };
        objective.fingerprint = objective.compute_fingerprint();
        Ok(objective)
    }

    /// The same objective with every parameter fixed at `full` (the full parameter vector
    /// of the first experiment; the others keep their own fixed values): nothing left free.
    pub fn fixed_at(&self, full: Vec<f64>) -> Objective {
        let mut o = self.clone();
        let free = std::mem::take(&mut o.free);
        for part in &mut o.more {
            // What the first experiment's vector holds at the shared free positions.
            for (k, index) in part.free.iter().enumerate() {
                if let (Some(i), Some(Some(_))) = (index, free.get(k)) {
                    part.base[*i] = full[*i];
                }
            }
            part.free.clear();
            part.fingerprint = part.compute_fingerprint();
        }
        o.base = full;
        o.fingerprint = o.compute_fingerprint();
        o
    }

    /// The same objective whose evaluations also return each point's weighted residuals
    /// `sqrt(k_i) (y_i − w_i)` ([`Evaluation::residuals`], every experiment's in turn), for
    /// least-squares methods. Its fingerprint differs from this one's (a stored evaluation
    /// of it holds the residuals); the objective's value at a point does not.
    pub fn with_residuals(&self) -> Objective {
        let mut o = self.clone();
        o.residuals = true;
        for part in &mut o.more {
            part.residuals = true;
            part.fingerprint = part.compute_fingerprint();
        }
        o.fingerprint = o.compute_fingerprint();
        o
    }

    /// Whether evaluations return the weighted residuals.
    pub fn returns_residuals(&self) -> bool {
        self.residuals
    }

    /// A hash of everything that changes the value of the objective at a given point: model
    /// and version, fixed parameters, which parameters are free, grid, measured data,
    /// output mapping, weights and solver settings (and the other experiments').
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
        for &i in self.free.iter().flatten() {
            fixed[i] = 0.0;
        }
        h.series(&fixed);
        // A parameter that does not reach this experiment is written as u64::MAX.
        let free: Vec<usize> = self.free.iter().map(|i| i.unwrap_or(usize::MAX)).collect();
        indices(&mut h, &free);
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
        // Inputs and further experiments likewise: an objective without them keeps its
        // fingerprint.
        calib_model::inputs::hash_into(&mut h, &self.named_inputs());
        // User-defined effects, as written: another formula is another objective (nothing
        // replayed); an objective without them keeps its fingerprint.
        calib_model::user_effects::hash_into(&mut h, self.model.user_effects());
        if !self.more.is_empty() || !self.name.is_empty() {
            h.text("experiments")
                .text(&self.name)
                .count(self.more.len());
            for part in &self.more {
                h.bytes(&part.fingerprint);
            }
        }
        // Evaluations that carry residuals are other entries of the store; an objective
        // without them keeps its fingerprint.
        if self.residuals {
            h.text("residuals");
        }
        h.finish()
    }

    /// The driving signals under their inputs' names, as the wire carries them.
    pub fn named_inputs(&self) -> Vec<calib_model::inputs::NamedSignal> {
        self.inputs.named(self.model.info())
    }

    /// The full parameter vector of this experiment with the free parameters set to
    /// `free_values` (those of other experiments left out).
    pub fn full_parameters(&self, free_values: &[f64]) -> Vec<f64> {
        let mut full = self.base.clone();
        for (i, v) in self.free.iter().zip(free_values) {
            if let Some(i) = i {
                full[*i] = *v;
            }
        }
        full
    }

    /// This experiment and the further ones, in order.
    pub fn experiments(&self) -> impl Iterator<Item = &Objective> {
        std::iter::once(self).chain(&self.more)
    }

    /// Each experiment as an objective of its own (over the same points).
    pub fn parts(&self) -> Vec<Objective> {
        if self.more.is_empty() {
            return vec![self.clone()];
        }
        let mut first = self.clone();
        first.more.clear();
        first.fingerprint = first.compute_fingerprint();
        std::iter::once(first)
            .chain(self.more.iter().cloned())
            .collect()
    }

    /// How many series are compared over all experiments (the length of
    /// [`Evaluation::sse`] and of what [`Objective::simulate`] returns).
    pub fn series_count(&self) -> usize {
        self.experiments().map(|e| e.outputs.len()).sum()
    }

    /// What points of this experiment alone are scored against: grid, outputs, measured
    /// series, weights, solver, inputs.
    pub fn target(&self) -> Target<'_> {
        Target {
            grid: &self.grid,
            outputs: &self.outputs,
            measured: &self.measured,
            weights: &self.weights,
            solver: &self.solver,
            inputs: &self.inputs,
            residuals: self.residuals,
        }
    }

    /// Simulate at `free_values` and score against the measurement (the same computation a
    /// remote worker makes, bit for bit), summed over the experiments.
    pub fn evaluate(&self, free_values: &[f64]) -> Evaluation {
        let own = scoring::evaluate(
            self.model,
            &self.full_parameters(free_values),
            &self.target(),
        );
        if self.more.is_empty() {
            return own;
        }
        let parts: Vec<Evaluation> = std::iter::once(own)
            .chain(self.more.iter().map(|part| part.evaluate(free_values)))
            .collect();
        self.combine(parts)
    }

    /// The evaluations of each experiment (in order) as one: the sum of the objectives and
    /// the series' errors one after another; failed when one failed.
    pub fn combine(&self, parts: Vec<Evaluation>) -> Evaluation {
        if let Some(failed) = parts.iter().find(|e| e.failure.is_some()) {
            let why = failed.failure.clone().unwrap_or_default();
            return Evaluation::failed(self.series_count(), why);
        }
        let objective = parts.iter().map(|e| e.objective).sum();
        let mut sse = Vec::with_capacity(self.series_count());
        let mut residuals = Vec::new();
        for part in parts {
            sse.extend(part.sse);
            residuals.extend(part.residuals);
        }
        Evaluation {
            objective,
            sse,
            failure: None,
            residuals,
        }
    }

    /// The mapped outputs on the grid at `free_values` (one series per output), of each
    /// experiment in turn.
    pub fn simulate(&self, free_values: &[f64]) -> Result<Vec<Vec<f64>>, SimulationError> {
        let mut series = Vec::with_capacity(self.series_count());
        for part in self.experiments() {
            let params = part.full_parameters(free_values);
            let t = self.model.simulate(
                &Run::new(&params, &part.grid, &part.outputs, &part.solver).driven(&part.inputs),
            )?;
            series.extend(t.values);
        }
        Ok(series)
    }

    /// Score simulated series (one per output of each experiment in turn, on its grid).
    pub fn score(&self, simulated: &[Vec<f64>]) -> Evaluation {
        let mut parts = Vec::with_capacity(1 + self.more.len());
        let mut from = 0;
        for part in self.experiments() {
            let n = part.outputs.len();
            parts.push(scoring::score_with(
                &simulated[from..from + n],
                &part.measured,
                &part.weights,
                self.residuals,
            ));
            from += n;
        }
        if parts.len() == 1 {
            return parts.pop().expect("one experiment");
        }
        self.combine(parts)
    }
}

/// The record of a further experiment: the columns it compares and drives.
fn load_experiment(
    campaign: &Campaign,
    experiment: &Experiment,
    place: &str,
) -> Result<Measurement, CampaignError> {
    let mut columns: Vec<&str> = experiment
        .outputs
        .iter()
        .map(|o| o.measured.as_str())
        .collect();
    for i in &experiment.inputs {
        if !columns.contains(&i.measured.as_str()) {
            columns.push(&i.measured);
        }
    }
    Measurement::load(
        &experiment.measurement_file,
        &experiment.time_column,
        &columns,
    )
    .map_err(|e| CampaignError {
        file: campaign.source.clone().unwrap_or_default(),
        line: None,
        field: format!("{place}.file"),
        message: e.to_string(),
    })
}

/// The measured columns mapped to the campaign's inputs, as signals: the whole column. A
/// column that does not cover the simulated span `[start, stop]` (to the stop time, where
/// plots end) is refused naming file, column and times.
fn driving_inputs(
    campaign: &Campaign,
    experiment: &Experiment,
    measurement: &Measurement,
    start: f64,
    stop: f64,
    place: &str,
) -> Result<Inputs, CampaignError> {
    let time = &measurement.time;
    let (first, last) = (time[0], time[time.len() - 1]);
    let slack = 1e-9 * stop.abs().max(1.0);
    let mut signals = Vec::with_capacity(experiment.inputs.len());
    for (i, input) in experiment.inputs.iter().enumerate() {
        let error = |message: String| CampaignError {
            file: campaign.source.clone().unwrap_or_default(),
            line: None,
            field: format!("{place}inputs[{i}] ({})", input.model),
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
                "column `{}` of {} runs from {first} to {last} s and does not cover the \
                 simulation from {start} to {stop} s",
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

/// Refuses a record (its `grid` in the windows, `columns` compared columns and `inputs`)
/// whose numbers are more than one request to a worker carries.
fn record_fits(
    campaign: &Campaign,
    place: &str,
    grid: &[f64],
    columns: usize,
    inputs: &Inputs,
) -> Result<(), CampaignError> {
    let compared = grid.len() * (1 + columns);
    let driving: usize = inputs.signals.iter().map(|s| 2 * s.times.len()).sum();
    if compared + driving <= MAX_RECORD_VALUES {
        return Ok(());
    }
    let (field, what) = if driving > 0 {
        (
            "inputs",
            format!(
                "; the inputs' {driving} (their times and values): resample them (a set \
                 point held between changes needs a sample per change, with \
                 `interpolation = \"hold\"`)"
            ),
        )
    } else {
        ("window", "; narrow the window".to_string())
    };
    Err(field_error(
        campaign,
        place,
        field,
        format!(
            "the record holds {} numbers, more than the {MAX_RECORD_VALUES} one request to \
             a worker carries: {compared} compared (times and {columns} columns in the \
             window){what}",
            compared + driving
        ),
    ))
}

/// The rows of the measurement inside the experiment's windows: at least two, at most what
/// one simulation returns, none before t = 0.
fn window_rows(
    campaign: &Campaign,
    experiment: &Experiment,
    measurement: &Measurement,
    place: &str,
) -> Result<Vec<usize>, CampaignError> {
    let (start, stop) = experiment.window;
    let time = &measurement.time;
    let field_error = |field: &str, message: String| field_error(campaign, place, field, message);
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
    let inside = |t: f64| {
        experiment
            .windows
            .iter()
            .any(|&(a, b)| t >= a - slack && t <= b + slack)
    };
    let rows: Vec<usize> = (0..time.len()).filter(|&i| inside(time[i])).collect();
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
    Ok(rows)
}

/// Each output's weight: its own, or divided by the variance of its measured column over the
/// window (`scale = "variance"`).
fn output_weights(
    campaign: &Campaign,
    experiment: &Experiment,
    measurement: &Measurement,
    measured: &[Vec<f64>],
    place: &str,
) -> Result<Vec<f64>, CampaignError> {
    let (start, stop) = experiment.window;
    let mut weights = Vec::with_capacity(measured.len());
    for (i, (o, w)) in experiment.outputs.iter().zip(measured).enumerate() {
        weights.push(match o.scale {
            OutputScale::None => o.weight,
            OutputScale::Variance => {
                let var = variance(w);
                if !(var > 0.0 && (o.weight / var).is_finite()) {
                    return Err(field_error(
                        campaign,
                        place,
                        &format!("outputs[{i}] ({})", o.model),
                        format!(
                            "scale = \"variance\": column `{}` of {} has variance {var:e} \
                             over the window [{start}, {stop}] s, nothing to scale by",
                            o.measured,
                            measurement.source.display()
                        ),
                    ));
                }
                o.weight / var
            }
        });
    }
    Ok(weights)
}

/// An error in field `field` of the campaign (of the experiment `place` prefixes).
fn field_error(campaign: &Campaign, place: &str, field: &str, message: String) -> CampaignError {
    CampaignError {
        file: campaign.source.clone().unwrap_or_default(),
        line: None,
        field: format!("{place}{field}"),
        message,
    }
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
            hex(&calib_model::scoring::measurement_hash(
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
