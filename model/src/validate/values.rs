//! Values of parameters: finite and within what the model admits.

use super::{Invalid, Result};
use crate::ModelInfo;

/// A value for entry `index` of the model's full parameter vector: finite and within its
/// admissible range. Points mapped from a unit box may land an ulp outside the bounds they
/// came from, so a relative slack of 1e-9 of the range is allowed.
pub fn parameter_value(info: &ModelInfo, index: usize, value: f64) -> Result<()> {
    let name = info.name_at(index);
    if !value.is_finite() {
        return Err(Invalid::new(format!(
            "`{name}` = {value} is not a finite number"
        )));
    }
    let (lo, hi) = info.bounds_at(index);
    let slack = 1e-9 * (hi - lo).abs().max(f64::MIN_POSITIVE);
    if value < lo - slack || value > hi + slack {
        return Err(Invalid::new(format!(
            "`{name}` = {value} is outside its admissible range [{lo}, {hi}]"
        )));
    }
    Ok(())
}

/// Search bounds `[min, max]` for entry `index`: finite, `min < max`, within the admissible
/// range.
pub fn bounds(info: &ModelInfo, index: usize, min: f64, max: f64) -> Result<()> {
    if !min.is_finite() || !max.is_finite() {
        return Err(Invalid::new("min and max must be finite numbers"));
    }
    if min >= max {
        return Err(Invalid::new(format!(
            "min ({min}) must be below max ({max})"
        )));
    }
    let (lo, hi) = info.bounds_at(index);
    if min < lo || max > hi {
        return Err(Invalid::new(format!(
            "bounds [{min}, {max}] exceed the model's admissible range [{lo}, {hi}]"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validate::model;

    #[test]
    fn values_outside_the_admissible_range_or_not_finite_are_refused() {
        let info = model("furuta").unwrap().info();
        assert!(parameter_value(info, 0, 0.5).is_ok());
        assert!(parameter_value(info, 0, 0.9 + 1e-12).is_ok());
        let e = parameter_value(info, 0, 1.5).unwrap_err();
        assert_eq!(
            e.message,
            "`armFriction` = 1.5 is outside its admissible range [0, 0.9]"
        );
        assert!(parameter_value(info, 0, f64::NAN).is_err());
        assert!(bounds(info, 0, 0.0, 0.9).is_ok());
        assert!(bounds(info, 0, 0.5, 0.5).is_err());
        assert!(bounds(info, 0, 0.0, 1.0).is_err());
        assert!(bounds(info, 0, f64::NEG_INFINITY, 0.5).is_err());
    }
}
