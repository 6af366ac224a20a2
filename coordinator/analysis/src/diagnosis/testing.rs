//! Fits made up for the unit tests of the diagnosis.

use super::Fit;
use crate::residuals::uncertainty::Interval;
use calib_engine::campaign::FreeParameter;

/// A fit of `(name, nominal, min, max, value, effect)` parameters.
pub fn fit(params: &[(&str, f64, f64, f64, f64, bool)]) -> Fit {
    Fit {
        effects: Vec::new(),
        parameters: params
            .iter()
            .map(|&(name, _, _, _, value, effect)| Interval {
                name: name.into(),
                value,
                ci_low: value,
                ci_high: value,
                std: 0.0,
                effect,
            })
            .collect(),
        correlation: (0..params.len())
            .map(|i| (0..params.len()).map(|j| f64::from(i == j)).collect())
            .collect(),
        objective: 1.0,
        held_out_objective: 1.0,
        rms: Vec::new(),
        held_out_rms: Vec::new(),
        residual: Vec::new(),
        effective_samples: 10.0,
        aic: 0.0,
        bic: 0.0,
        evaluations: 1,
        runs_at_best: calib_engine::evidence::runs_at_best(&[1.0]),
        point: params.iter().map(|p| p.4).collect(),
        free: params
            .iter()
            .map(|&(name, nominal, min, max, _, effect)| FreeParameter {
                name: name.into(),
                index: 0,
                nominal,
                min,
                max,
                effect,
                scale: calib_engine::campaign::Scale::Lin,
                experiment: None,
            })
            .collect(),
        residual_series: Vec::new(),
    }
}

/// [`fit`] with the given objectives, effective sample count and effects.
pub fn scored(effects: &[&str], parameters: usize, objective: f64, held_out: f64, n: f64) -> Fit {
    let names: Vec<String> = (0..parameters).map(|i| format!("p{i}")).collect();
    let params: Vec<(&str, f64, f64, f64, f64, bool)> = names
        .iter()
        .map(|n| (n.as_str(), 0.5, 0.0, 1.0, 0.5, false))
        .collect();
    Fit {
        effects: effects.iter().map(|e| e.to_string()).collect(),
        objective,
        held_out_objective: held_out,
        effective_samples: n,
        ..fit(&params)
    }
}
