//! Signals that drive a model: a measured motor torque, a valve command, the boundary
//! conditions of a test bench.
//!
//! A model declares its inputs ([`crate::model::InputSpec`]); a simulation is given a value
//! for some of them as samples in time ([`InputSignal`]), read between samples by linear
//! interpolation or held from one sample to the next (zero-order hold). An input left
//! without a signal keeps the model's own value (0 for the Furuta's arm torque, the built-in
//! ramps for the heat exchanger's boundary conditions).

use crate::content_hash::ContentHasher;
use crate::model::ModelInfo;
use std::sync::Arc;

/// How a sampled input is read between its samples.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, Hash, Default, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Interpolation {
    /// A straight line from one sample to the next.
    #[default]
    Linear,
    /// Each sample's value until the next sample (zero-order hold, as a digital controller
    /// or a data logger's set-point holds it).
    Hold,
}

impl Interpolation {
    pub fn as_str(self) -> &'static str {
        match self {
            Interpolation::Linear => "linear",
            Interpolation::Hold => "hold",
        }
    }

    /// The code the content hash and the wire use.
    pub fn code(self) -> u32 {
        match self {
            Interpolation::Linear => 0,
            Interpolation::Hold => 1,
        }
    }
}

/// One input's samples: `values[k]` at `times[k]`, times finite and non-decreasing.
#[derive(Debug, Clone, PartialEq)]
pub struct InputSignal {
    /// Index into [`ModelInfo::inputs`].
    pub input: usize,
    pub times: Arc<[f64]>,
    pub values: Arc<[f64]>,
    pub interpolation: Interpolation,
}

impl InputSignal {
    /// The signal's value at `t`; before the first sample it is the first value, after the
    /// last the last (requests are checked to cover the simulated span, see
    /// [`Inputs::check`]). At a time with several samples (a step recorded as two rows at one
    /// time) the last of them holds from that time on.
    pub fn at(&self, t: f64) -> f64 {
        let (times, values) = (&*self.times, &*self.values);
        // First sample strictly after t.
        let k = times.partition_point(|&s| s <= t);
        if k == 0 {
            return values[0];
        }
        if k == times.len() {
            return values[k - 1];
        }
        match self.interpolation {
            Interpolation::Hold => values[k - 1],
            Interpolation::Linear => {
                let (t0, t1) = (times[k - 1], times[k]);
                let (v0, v1) = (values[k - 1], values[k]);
                v0 + (v1 - v0) * ((t - t0) / (t1 - t0))
            }
        }
    }

    /// Sample times in `(from, to)` where the signal is not smooth: every sample of a held
    /// signal (a jump), every sample of a linear one (a kink).
    pub fn breaks(&self, from: f64, to: f64) -> impl Iterator<Item = f64> + '_ {
        self.times
            .iter()
            .copied()
            .filter(move |&s| s > from && s < to)
    }
}

/// The signals a simulation is driven by, at most one per model input.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Inputs {
    pub signals: Vec<InputSignal>,
}

impl Inputs {
    /// No input driven: every input keeps the model's own value.
    pub fn none() -> &'static Inputs {
        static NONE: Inputs = Inputs {
            signals: Vec::new(),
        };
        &NONE
    }

    pub fn is_empty(&self) -> bool {
        self.signals.is_empty()
    }

    /// The signal of model input `input`, when one drives it.
    pub fn signal(&self, input: usize) -> Option<&InputSignal> {
        self.signals.iter().find(|s| s.input == input)
    }

    /// The value of model input `input` at `t`, when a signal drives it.
    pub fn value(&self, input: usize, t: f64) -> Option<f64> {
        self.signal(input).map(|s| s.at(t))
    }

    /// Check the signals against the model and the simulated span `[start, stop]`: each
    /// names an input of the model once, has as many values as times (at least one), finite
    /// values at non-decreasing finite times, and covers the span. Messages name the input.
    pub fn check(&self, info: &ModelInfo, start: f64, stop: f64) -> Result<(), String> {
        let mut seen = vec![false; info.inputs.len()];
        for s in &self.signals {
            let Some(spec) = info.inputs.get(s.input) else {
                return Err(format!(
                    "model `{}` has no input #{} (it has {})",
                    info.name,
                    s.input,
                    info.inputs.len()
                ));
            };
            let name = &spec.name;
            if std::mem::replace(&mut seen[s.input], true) {
                return Err(format!("input `{name}` is given twice"));
            }
            if s.times.is_empty() || s.times.len() != s.values.len() {
                return Err(format!(
                    "input `{name}`: {} times and {} values; they must be as many, at least one",
                    s.times.len(),
                    s.values.len()
                ));
            }
            if let Some(k) = s.times.iter().position(|t| !t.is_finite()) {
                return Err(format!("input `{name}`: time #{k} is not finite"));
            }
            if let Some(k) = s.times.windows(2).position(|w| w[1] < w[0]) {
                return Err(format!(
                    "input `{name}`: times must be non-decreasing, {} s follows {} s",
                    s.times[k + 1],
                    s.times[k]
                ));
            }
            if let Some(k) = s.values.iter().position(|v| !v.is_finite()) {
                return Err(format!(
                    "input `{name}`: value at {} s is {}",
                    s.times[k], s.values[k]
                ));
            }
            let (first, last) = (s.times[0], s.times[s.times.len() - 1]);
            let slack = 1e-9 * stop.abs().max(1.0);
            if first > start + slack || last < stop - slack {
                return Err(format!(
                    "input `{name}`: samples from {first} to {last} s do not cover the \
                     simulation from {start} to {stop} s"
                ));
            }
        }
        Ok(())
    }

    /// The signals under their inputs' names (as the wire and the content hash name them).
    pub fn named(&self, info: &ModelInfo) -> Vec<NamedSignal> {
        self.signals
            .iter()
            .map(|s| NamedSignal {
                name: info.inputs[s.input].name.clone(),
                times: s.times.clone(),
                values: s.values.clone(),
                interpolation: s.interpolation,
            })
            .collect()
    }

    /// Signals named by input, resolved against `info`: the position of a signal whose name
    /// the model lacks, with a message that suggests the nearest name.
    pub fn resolve(info: &ModelInfo, named: &[NamedSignal]) -> Result<Inputs, (usize, String)> {
        let mut signals = Vec::with_capacity(named.len());
        for (k, n) in named.iter().enumerate() {
            let input = crate::validate::input(info, &n.name).map_err(|e| (k, e.message))?;
            signals.push(InputSignal {
                input,
                times: n.times.clone(),
                values: n.values.clone(),
                interpolation: n.interpolation,
            });
        }
        Ok(Inputs { signals })
    }
}

/// A signal under the name of the input it drives, before it is resolved against a model.
#[derive(Debug, Clone, PartialEq)]
pub struct NamedSignal {
    pub name: String,
    pub times: Arc<[f64]>,
    pub values: Arc<[f64]>,
    pub interpolation: Interpolation,
}

/// Write named signals into a content hash, after the rest of a measurement (nothing when
/// there are none, so the hash of an undriven measurement stays what it was before models
/// took inputs). The layout is the Simulator protocol's (`EvaluateRequest.measurement_hash`).
pub fn hash_into(h: &mut ContentHasher, signals: &[NamedSignal]) {
    if signals.is_empty() {
        return;
    }
    h.text("inputs").count(signals.len());
    for s in signals {
        h.text(&s.name)
            .count(s.interpolation.code() as usize)
            .series(&s.times)
            .series(&s.values);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn signal(interpolation: Interpolation) -> InputSignal {
        InputSignal {
            input: 0,
            times: vec![0.0, 1.0, 1.0, 3.0].into(),
            values: vec![0.0, 2.0, 5.0, 9.0].into(),
            interpolation,
        }
    }

    #[test]
    fn linear_reads_between_samples_and_a_repeated_time_is_a_step() {
        let s = signal(Interpolation::Linear);
        assert_eq!(s.at(-1.0), 0.0);
        assert_eq!(s.at(0.5), 1.0);
        assert_eq!(s.at(1.0), 5.0);
        assert_eq!(s.at(2.0), 7.0);
        assert_eq!(s.at(3.0), 9.0);
        assert_eq!(s.at(4.0), 9.0);
    }

    #[test]
    fn hold_keeps_each_sample_until_the_next() {
        let s = signal(Interpolation::Hold);
        assert_eq!(s.at(0.0), 0.0);
        assert_eq!(s.at(0.999), 0.0);
        assert_eq!(s.at(1.0), 5.0);
        assert_eq!(s.at(2.9), 5.0);
        assert_eq!(s.at(3.0), 9.0);
    }
}
