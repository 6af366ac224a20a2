//! Output grids: the times a simulation reports at.

use super::{Invalid, Result};
use crate::limits;

/// The end of a simulated horizon: finite, ≥ 0, within [`limits::MAX_STOP_TIME`].
pub fn stop_time(stop: f64) -> Result<()> {
    if !(stop.is_finite() && stop >= 0.0) {
        return Err(Invalid::new(format!(
            "stop time {stop} s is not a finite time ≥ 0"
        )));
    }
    if stop > limits::MAX_STOP_TIME {
        return Err(Invalid::new(format!(
            "stop time {stop} s is beyond what calib simulates ({} s)",
            limits::MAX_STOP_TIME
        )));
    }
    Ok(())
}

/// Output times: non-empty, at most [`limits::MAX_TIMES`], finite, ≥ 0, non-decreasing,
/// ending within [`limits::MAX_STOP_TIME`]. A refusal about one time carries its index.
pub fn output_grid(times: &[f64]) -> Result<()> {
    let Some(&stop) = times.last() else {
        return Err(Invalid::new("empty time grid"));
    };
    if times.len() > limits::MAX_TIMES {
        return Err(Invalid::new(format!(
            "{} times exceed the limit of {}",
            times.len(),
            limits::MAX_TIMES
        )));
    }
    if let Some(i) = times.iter().position(|t| !t.is_finite()) {
        return Err(Invalid::at(i, format!("{} is not a finite time", times[i])));
    }
    if let Some(i) = times.iter().position(|t| *t < 0.0) {
        return Err(Invalid::at(
            i,
            format!("{} s is negative: simulations start at 0 s", times[i]),
        ));
    }
    if let Some(i) = times.windows(2).position(|w| w[1] < w[0]) {
        return Err(Invalid::at(
            i + 1,
            format!(
                "{} s comes after {} s: times must not decrease",
                times[i + 1],
                times[i]
            ),
        ));
    }
    stop_time(stop)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_are_checked_against_the_limits() {
        assert!(output_grid(&[0.0, 0.5, 0.5, 2.0]).is_ok());
        assert_eq!(output_grid(&[]).unwrap_err().message, "empty time grid");
        assert_eq!(output_grid(&[0.0, f64::NAN]).unwrap_err().index, Some(1));
        assert_eq!(output_grid(&[-1.0, 0.0]).unwrap_err().index, Some(0));
        assert_eq!(output_grid(&[0.0, 2.0, 1.0]).unwrap_err().index, Some(2));
        assert!(output_grid(&[0.0, 2e6])
            .unwrap_err()
            .message
            .contains("beyond"));
        let long = vec![0.0; limits::MAX_TIMES + 1];
        assert!(output_grid(&long).unwrap_err().message.contains("exceed"));
    }
}
