//! Solver options: the model's own calibration tolerances, with overrides checked against
//! [`crate::limits`].

use super::{Invalid, Result};
use crate::{limits, Model, SolverOptions};

pub fn rtol(value: f64) -> Result<f64> {
    if limits::RTOL.contains(&value) {
        Ok(value)
    } else {
        Err(Invalid::new(format!(
            "{value} is not in [{:e}, {}]",
            limits::RTOL.start(),
            limits::RTOL.end()
        )))
    }
}

pub fn atol(value: f64) -> Result<f64> {
    if limits::ATOL.contains(&value) {
        Ok(value)
    } else {
        Err(Invalid::new(format!(
            "{value} is not a positive number in [{:e}, {:e}]",
            limits::ATOL.start(),
            limits::ATOL.end()
        )))
    }
}

pub fn max_steps(value: u64) -> Result<usize> {
    if limits::MAX_STEPS.contains(&value) {
        Ok(value as usize)
    } else {
        Err(Invalid::new(format!(
            "{value} is not between {} and {}",
            limits::MAX_STEPS.start(),
            limits::MAX_STEPS.end()
        )))
    }
}

/// A start time: finite, in [0, [`limits::MAX_STOP_TIME`]]; other than 0 only for an FMU.
pub fn start_time(model: &dyn Model, value: f64) -> Result<f64> {
    if !(0.0..=limits::MAX_STOP_TIME).contains(&value) {
        return Err(Invalid::new(format!(
            "{value} s is not a time in [0, {:e}] s",
            limits::MAX_STOP_TIME
        )));
    }
    if value != 0.0 && crate::fmu::interface_in_name(&model.info().name).is_none() {
        return Err(Invalid::new(format!(
            "{value} s: the hosted model `{}` starts at 0 s; a start time applies to an FMU",
            model.info().name
        )));
    }
    Ok(value)
}

/// A communication step: positive and finite, and only for a Co-Simulation FMU.
pub fn communication_step(model: &dyn Model, value: f64) -> Result<f64> {
    if !(value > 0.0 && value.is_finite()) {
        return Err(Invalid::new(format!("{value} s is not a positive time")));
    }
    if crate::fmu::interface_in_name(&model.info().name)
        != Some(crate::fmu::Interface::CoSimulation)
    {
        return Err(Invalid::new(format!(
            "`{}` is not run through Co-Simulation: a communication step applies to a \
             Co-Simulation FMU",
            model.info().name
        )));
    }
    Ok(value)
}

/// Options a request sets; those it leaves out keep the model's own.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SolverOverrides {
    pub rtol: Option<f64>,
    pub atol: Option<f64>,
    pub max_steps: Option<u64>,
    pub start_time: Option<f64>,
    pub communication_step: Option<f64>,
}

/// The model's calibration options ([`Model::default_options`]) with `overrides`, each
/// checked; the error names the option (`rtol`, `atol`, `max_steps`, `start_time` or
/// `communication_step`).
pub fn solver_options(
    model: &dyn Model,
    overrides: SolverOverrides,
) -> std::result::Result<SolverOptions, (&'static str, Invalid)> {
    let mut options = model.default_options();
    if let Some(v) = overrides.rtol {
        options.rtol = rtol(v).map_err(|e| ("rtol", e))?;
    }
    if let Some(v) = overrides.atol {
        options.atol = atol(v).map_err(|e| ("atol", e))?;
    }
    if let Some(v) = overrides.max_steps {
        options.max_steps = max_steps(v).map_err(|e| ("max_steps", e))?;
    }
    if let Some(v) = overrides.start_time {
        options.start_time = start_time(model, v).map_err(|e| ("start_time", e))?;
    }
    if let Some(v) = overrides.communication_step {
        options.communication_step =
            Some(communication_step(model, v).map_err(|e| ("communication_step", e))?);
    }
    Ok(options)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validate::model;

    #[test]
    fn no_override_keeps_the_models_own_tolerances() {
        for name in ["furuta", "hx_highfi", "hx_lowfi"] {
            let m = model(name).unwrap();
            assert_eq!(
                solver_options(m, SolverOverrides::default()),
                Ok(m.default_options())
            );
        }
        assert_eq!(model("hx_lowfi").unwrap().default_options().rtol, 1e-6);
    }

    #[test]
    fn overrides_outside_the_limits_name_their_option() {
        let m = model("furuta").unwrap();
        let with = |rtol, atol, max_steps| SolverOverrides {
            rtol,
            atol,
            max_steps,
            ..Default::default()
        };
        let o = solver_options(m, with(Some(1e-6), None, Some(5))).unwrap();
        assert_eq!((o.rtol, o.atol, o.max_steps), (1e-6, 1e-10, 5));
        for (overrides, option) in [
            (with(Some(0.0), None, None), "rtol"),
            (with(Some(1.0), None, None), "rtol"),
            (with(Some(f64::NAN), None, None), "rtol"),
            (with(None, Some(0.0), None), "atol"),
            (with(None, Some(f64::INFINITY), None), "atol"),
            (with(None, None, Some(0)), "max_steps"),
            (with(None, None, Some(10_000_001)), "max_steps"),
        ] {
            assert_eq!(solver_options(m, overrides).unwrap_err().0, option);
        }
    }
}
