//! Effects of the measurement chain, common to every model: per output, an offset, a gain
//! error, a dead time and a first-order sensor lag.
//!
//! [`WithOutputEffects`] wraps a model: its description gains four effects per output,
//! named `offset(<output>)`, `gain(<output>)`, `delay(<output>)` and `lag(<output>)`, each 0
//! when absent, with slots after the model's own parameters and effects. Applied to the
//! simulated output `y`, in this order:
//!
//! - `delay(o)` = τ [s]: `y(t − τ)` (the value at t = 0 before the start);
//! - `lag(o)` = T [s]: a first-order sensor `T·ẏm + ym = y`, settled at the start
//!   (`ym(0) = y(0)`), integrated exactly for an input linear between grid points;
//! - `gain(o)` = g: `(1 + g)·y`;
//! - `offset(o)` = c [output unit]: `y + c`.

use crate::model::{
    check_request, EffectSpec, Model, ModelInfo, SimulationError, SolverOptions, Trajectory,
};
use crate::Run;

/// The measurement-chain effects every output has, in the order of their slots.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum OutputEffect {
    /// `y + c`, in the output's unit.
    Offset,
    /// `(1 + g)·y`.
    Gain,
    /// `y(t − τ)`, τ in seconds.
    Delay,
    /// A first-order sensor of time constant T seconds.
    Lag,
}

impl OutputEffect {
    /// Every kind, in slot order.
    pub const ALL: [OutputEffect; 4] = [Self::Offset, Self::Gain, Self::Delay, Self::Lag];

    /// The kind's word in an effect's name: `offset` in `offset(<output>)`.
    pub fn word(self) -> &'static str {
        match self {
            Self::Offset => "offset",
            Self::Gain => "gain",
            Self::Delay => "delay",
            Self::Lag => "lag",
        }
    }

    /// The effect's slot among its output's [`PER_OUTPUT`].
    fn slot(self) -> usize {
        self as usize
    }

    /// The effect's name on `output`.
    pub fn name(self, output: &str) -> String {
        format!("{}({output})", self.word())
    }

    /// The kind and the output of an effect named `kind(output)`; `None` for any other
    /// effect (a model's own, such as `stiffness.arm`).
    pub fn parse(name: &str) -> Option<(OutputEffect, &str)> {
        let (word, rest) = name.split_once('(')?;
        let output = rest.strip_suffix(')')?;
        let kind = Self::ALL.into_iter().find(|k| k.word() == word)?;
        Some((kind, output))
    }

    /// Unit (`None`: the output's own), bounds and description of the effect on `output`.
    fn spec(self, output: &str) -> (Option<&'static str>, f64, f64, String) {
        match self {
            Self::Offset => (
                None,
                -1e9,
                1e9,
                format!("constant offset of the measured {output}"),
            ),
            Self::Gain => (
                Some("1"),
                -0.9,
                10.0,
                format!("relative gain error of the measured {output}: (1+g)*y"),
            ),
            Self::Delay => (
                Some("s"),
                0.0,
                10.0,
                format!("dead time of the measured {output}"),
            ),
            Self::Lag => (
                Some("s"),
                0.0,
                100.0,
                format!("time constant of a first-order sensor measuring {output}"),
            ),
        }
    }
}

/// Effect slots per output.
const PER_OUTPUT: usize = OutputEffect::ALL.len();

/// A model with the measurement-chain effects of every output.
pub struct WithOutputEffects<M> {
    inner: M,
    info: ModelInfo,
    /// Length of the inner model's full parameter vector.
    inner_len: usize,
}

impl<M: Model> WithOutputEffects<M> {
    pub fn new(inner: M) -> Self {
        let mut info = inner.info().clone();
        let inner_len = info.full_len();
        for output in inner.info().outputs.iter() {
            let o = &output.name;
            info.effects
                .extend(OutputEffect::ALL.into_iter().map(|kind| {
                    let (unit, min, max, description) = kind.spec(o);
                    EffectSpec {
                        name: kind.name(o),
                        unit: unit.unwrap_or(&output.unit).into(),
                        min,
                        max,
                        description,
                        parameter: None,
                    }
                }));
        }
        Self {
            inner,
            info,
            inner_len,
        }
    }

    pub fn inner(&self) -> &M {
        &self.inner
    }
}

impl<M: Model> Model for WithOutputEffects<M> {
    fn info(&self) -> &ModelInfo {
        &self.info
    }

    fn default_options(&self) -> SolverOptions {
        self.inner.default_options()
    }

    fn tolerance_origin(&self) -> &'static str {
        self.inner.tolerance_origin()
    }

    fn default_stop_time(&self) -> f64 {
        self.inner.default_stop_time()
    }

    fn places(&self) -> Vec<crate::PlaceSpec> {
        self.inner.places()
    }

    fn state_names(&self) -> Vec<String> {
        self.inner.state_names()
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
        let (inner_params, effects) = params.split_at(self.inner_len);
        let effect = |output: usize, kind: OutputEffect| effects[output * PER_OUTPUT + kind.slot()];
        let delays: Vec<f64> = outputs
            .iter()
            .map(|&o| effect(o, OutputEffect::Delay))
            .collect();
        if delays.iter().any(|d| *d < 0.0)
            || (0..effects.len() / PER_OUTPUT).any(|o| effect(o, OutputEffect::Lag) < 0.0)
        {
            return Err(SimulationError::InvalidInput(
                "delays and lags must be non-negative".into(),
            ));
        }

        let mut trajectory = if delays.iter().all(|d| *d == 0.0) {
            self.inner.simulate(
                &Run::new(inner_params, grid, outputs, options)
                    .driven(inputs)
                    .forced(forces),
            )?
        } else {
            // Simulate on the grid and every delayed copy of it, then pick.
            let mut times: Vec<f64> = grid.to_vec();
            for &d in delays.iter().filter(|d| **d > 0.0) {
                times.extend(grid.iter().map(|t| (t - d).max(0.0)));
            }
            times.sort_by(f64::total_cmp);
            times.dedup();
            let full = self.inner.simulate(
                &Run::new(inner_params, &times, outputs, options)
                    .driven(inputs)
                    .forced(forces),
            )?;
            let at = |k: usize, t: f64| {
                let i = times.partition_point(|x| *x < t);
                full.values[k][i]
            };
            let values = (0..outputs.len())
                .map(|k| {
                    grid.iter()
                        .map(|t| at(k, (t - delays[k]).max(0.0)))
                        .collect()
                })
                .collect();
            Trajectory {
                time: grid.to_vec(),
                values,
                stats: full.stats,
            }
        };

        for (k, &o) in outputs.iter().enumerate() {
            let series = &mut trajectory.values[k];
            let lag = effect(o, OutputEffect::Lag);
            if lag > 0.0 {
                first_order_lag(grid, series, lag);
            }
            let gain = effect(o, OutputEffect::Gain);
            let offset = effect(o, OutputEffect::Offset);
            if gain != 0.0 || offset != 0.0 {
                for v in series.iter_mut() {
                    *v = (1.0 + gain) * *v + offset;
                }
            }
        }
        Ok(trajectory)
    }
}

/// Filter `series` (sampled at `time`) in place through `T·ẏ + y = u`, settled at the start,
/// exactly for an input that is linear between samples.
fn first_order_lag(time: &[f64], series: &mut [f64], tau: f64) {
    let Some(&first) = series.first() else {
        return;
    };
    let mut y = first;
    let mut u_prev = first;
    for i in 1..series.len() {
        let h = time[i] - time[i - 1];
        let u = series[i];
        if h > 0.0 {
            let a = (-h / tau).exp();
            let slope = (u - u_prev) / h;
            y = u - slope * tau + (y - u_prev + slope * tau) * a;
        }
        u_prev = u;
        series[i] = y;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{OutputSpec, ParameterSpec, SolverStats};

    #[test]
    fn effect_names_parse_back_to_their_kind_and_output() {
        for kind in OutputEffect::ALL {
            let name = kind.name("armJoint.phi");
            assert_eq!(OutputEffect::parse(&name), Some((kind, "armJoint.phi")));
        }
        assert_eq!(
            OutputEffect::parse("lag(a(b))"),
            Some((OutputEffect::Lag, "a(b)"))
        );
        for other in ["stiffness.arm", "offset", "offset(x", "drift(x)", "(x)"] {
            assert_eq!(OutputEffect::parse(other), None, "{other}");
        }
    }

    /// y = a·t, for checking the effects in closed form.
    struct Ramp {
        info: ModelInfo,
    }

    impl Ramp {
        fn new() -> Self {
            Self {
                info: ModelInfo {
                    name: "ramp".into(),
                    version: 1,
                    description: String::new(),
                    parameters: vec![ParameterSpec {
                        name: "a".into(),
                        unit: "1/s".into(),
                        default: 1.0,
                        min: -10.0,
                        max: 10.0,
                        description: String::new(),
                    }],
                    outputs: vec![OutputSpec {
                        name: "y".into(),
                        unit: "1".into(),
                        description: String::new(),
                    }],
                    effects: vec![],
                    inputs: vec![],
                },
            }
        }
    }

    impl Model for Ramp {
        fn info(&self) -> &ModelInfo {
            &self.info
        }
        fn simulate(&self, run: &Run) -> Result<Trajectory, SimulationError> {
            let Run { params, grid, .. } = *run;
            Ok(Trajectory {
                time: grid.to_vec(),
                values: vec![grid.iter().map(|t| params[0] * t).collect()],
                stats: SolverStats::default(),
            })
        }
    }

    fn run(effects: [f64; 4]) -> Vec<f64> {
        let model = WithOutputEffects::new(Ramp::new());
        assert_eq!(model.info().full_len(), 5);
        let grid: Vec<f64> = (0..=100).map(|i| i as f64 * 0.1).collect();
        let mut p = vec![1.0];
        p.extend(effects);
        model
            .simulate(&Run::new(&p, &grid, &[0], &SolverOptions::default()))
            .unwrap()
            .values
            .remove(0)
    }

    #[test]
    fn effects_are_named_per_output_and_absent_at_zero() {
        let model = WithOutputEffects::new(Ramp::new());
        let names: Vec<_> = model
            .info()
            .effects
            .iter()
            .map(|e| e.name.as_str())
            .collect();
        assert_eq!(names, ["offset(y)", "gain(y)", "delay(y)", "lag(y)"]);
        assert_eq!(model.info().parameter_index("lag(y)"), Some(4));
        let plain = run([0.0; 4]);
        assert!((plain[100] - 10.0).abs() < 1e-12);
    }

    #[test]
    fn offset_gain_and_delay_in_closed_form() {
        let y = run([0.5, 0.1, 0.0, 0.0]);
        assert!((y[100] - (1.1 * 10.0 + 0.5)).abs() < 1e-12);
        let y = run([0.0, 0.0, 2.0, 0.0]);
        assert!((y[100] - 8.0).abs() < 1e-12);
        assert_eq!(y[10], 0.0); // before the start: the initial value
    }

    #[test]
    fn a_lag_on_a_ramp_trails_by_its_time_constant() {
        // T·ẏ + y = t from y(0) = 0: y = t − T·(1 − e^(−t/T)).
        let y = run([0.0, 0.0, 0.0, 0.5]);
        let exact = 10.0 - 0.5 * (1.0 - (-20.0f64).exp());
        assert!((y[100] - exact).abs() < 1e-12, "{} vs {exact}", y[100]);
    }
}
