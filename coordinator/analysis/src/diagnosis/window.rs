//! The fitted and held-out windows of a diagnosis.

use calib_engine::campaign::Campaign;
use calib_engine::error::{Error, Result};
use calib_engine::measurement::Measurement;

/// Share of the window held out when the data does not extend beyond it.
pub const HOLDOUT_FRACTION: f64 = 0.2;

/// The fitted and held-out windows of a campaign on its data.
pub fn windows(campaign: &Campaign, measurement: &Measurement) -> Result<((f64, f64), (f64, f64))> {
    let (start, stop) = campaign.window;
    if let Some(holdout) = campaign.diagnosis.holdout {
        return Ok(((start, stop), holdout));
    }
    let last = *measurement.time.last().unwrap_or(&stop);
    let after: Vec<f64> = measurement
        .time
        .iter()
        .copied()
        .filter(|t| *t > stop)
        .collect();
    if last - stop >= HOLDOUT_FRACTION * 0.5 * (stop - start) && after.len() >= 2 {
        return Ok(((start, stop), (after[0], last)));
    }
    let split = start + (1.0 - HOLDOUT_FRACTION) * (stop - start);
    let first_after = measurement
        .time
        .iter()
        .copied()
        .find(|t| *t > split)
        .ok_or_else(|| {
            Error::InvalidRequest("the window is too short to hold part of it out".into())
        })?;
    Ok(((start, split), (first_after, stop)))
}

/// `campaign` over another time window.
/// The objective reads the fitted intervals (`windows`), so both change; the campaign's own
/// window keeps its intervals (disjoint ones included).
pub(super) fn with_window(campaign: &Campaign, window: (f64, f64)) -> Campaign {
    let mut c = campaign.clone();
    if window != c.window {
        c.window = window;
        c.windows = vec![window];
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    fn example(name: &str) -> Campaign {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples");
        Campaign::load(&dir.join(name)).unwrap()
    }

    /// A record sampled every 0.5 s from 0 to `last`.
    fn record(last: f64) -> Measurement {
        let time: Vec<f64> = (0..=(2.0 * last) as usize)
            .map(|i| 0.5 * i as f64)
            .collect();
        Measurement {
            source: "record.csv".into(),
            columns: vec![("y".into(), vec![0.0; time.len()])],
            time,
        }
    }

    #[test]
    fn a_campaign_may_name_its_held_out_window() {
        let c = example("furuta_viscous_arm.toml");
        assert_eq!(
            windows(&c, &record(40.0)).unwrap(),
            ((0.0, 30.0), (30.01, 40.0))
        );
    }

    #[test]
    fn data_after_the_window_is_held_out() {
        let mut c = example("furuta.toml");
        c.window = (0.0, 30.0);
        assert_eq!(
            windows(&c, &record(40.0)).unwrap(),
            ((0.0, 30.0), (30.5, 40.0))
        );
    }

    #[test]
    fn without_data_after_it_the_window_gives_up_its_last_fifth() {
        let mut c = example("furuta.toml");
        c.window = (0.0, 40.0);
        assert_eq!(
            windows(&c, &record(40.0)).unwrap(),
            ((0.0, 32.0), (32.5, 40.0))
        );
        // Too little data beyond the window to hold out: the last fifth again.
        c.window = (0.0, 37.5);
        assert_eq!(
            windows(&c, &record(40.0)).unwrap(),
            ((0.0, 30.0), (30.5, 37.5))
        );
    }

    #[test]
    fn the_held_out_objective_reads_only_the_held_out_window() {
        let c = example("furuta_viscous_arm.toml");
        let measurement = calib_engine::calibration::load_measurement(&c).unwrap();
        let (fit, held_out) = windows(&c, &measurement).unwrap();
        for window in [fit, held_out] {
            let objective =
                calib_engine::objective::Objective::new(&with_window(&c, window), &measurement)
                    .unwrap();
            let (first, last) = (objective.grid[0], *objective.grid.last().unwrap());
            assert!(
                first >= window.0 - 1e-9 && last <= window.1 + 1e-9,
                "{window:?}: grid from {first} to {last}"
            );
        }
        // The campaign's own window leaves its intervals as they are.
        assert_eq!(with_window(&c, c.window).windows, c.windows);
    }
}
