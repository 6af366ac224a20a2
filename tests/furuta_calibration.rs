//! Calibrating the Furuta pendulum's frictions: synthetic record (truth known) and the real rig.

mod common;

use calib_coordinator::calibration::calibrate;
use calib_coordinator::campaign::Campaign;
use calib_coordinator::evaluator::LocalEvaluator;
use calib_coordinator::optim::problem::Silent;
use common::*;

/// Calibrate both frictions on the clean record with one method from the nominal point and
/// one Sobol start, over the seed's bounds [0, 0.9] (much wider than the frictions: the
/// population of differential evolution needs its larger budget to close in).
fn calibrate_clean(method: &str, max_evaluations: usize) {
    let dir = tempfile::tempdir().unwrap();
    let search = format!(
        "methods = [\"{method}\"]\nstarts = 2\nmax_evaluations = {max_evaluations}\nseed = 1"
    );
    let path = write(dir.path(), "clean.toml", &clean_campaign(&search));
    let campaign = Campaign::load(&path).unwrap();
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    let (arm, pendulum) = true_frictions();
    let floor = synthetic_noise_floor(2, c.objective.grid.len());
    println!(
        "{method}: armFriction {:.6e} pendulumFriction {:.6e} objective {:.5} (floor {floor:.5}), {} evaluations",
        best.point[0],
        best.point[1],
        best.objective,
        c.evaluations()
    );
    assert!(
        (best.point[0] / arm - 1.0).abs() < 0.01,
        "armFriction {}",
        best.point[0]
    );
    assert!(
        (best.point[1] / pendulum - 1.0).abs() < 0.01,
        "pendulumFriction {}",
        best.point[1]
    );
    assert!(
        best.objective < 1.3 * floor,
        "objective {} vs floor {floor}",
        best.objective
    );
    assert!(c.nominal.objective > 10.0 * best.objective);
}

#[test]
fn nelder_mead_recovers_the_true_frictions() {
    calibrate_clean("nelder-mead", 600);
}

#[test]
fn powell_recovers_the_true_frictions() {
    calibrate_clean("powell", 600);
}

#[test]
fn differential_evolution_recovers_the_true_frictions() {
    calibrate_clean("differential-evolution", 2500);
}

#[test]
fn runs_are_deterministic_for_a_seed() {
    let dir = tempfile::tempdir().unwrap();
    let search = "methods = [\"nelder-mead\", \"differential-evolution\"]\nstarts = 2\nmax_evaluations = 120\nseed = 11";
    let path = write(dir.path(), "clean.toml", &clean_campaign(search));
    let campaign = Campaign::load(&path).unwrap();
    let a = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let b = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    for (x, y) in a.runs.iter().zip(&b.runs) {
        assert_eq!(x.point, y.point);
        assert_eq!(x.objective.to_bits(), y.objective.to_bits());
        assert_eq!(x.evaluations, y.evaluations);
    }
}

#[test]
fn the_real_rig_fits_better_than_the_seed() {
    let Some(_) = real_record() else { return };
    let campaign = Campaign::load(&repo().join("examples/furuta_real.toml")).unwrap();
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    println!(
        "real rig: nominal {:.3} -> {:.4} at armFriction {:.6e} pendulumFriction {:.6e} ({} by {}, {} evaluations)",
        c.nominal.objective,
        best.objective,
        best.point[0],
        best.point[1],
        best.method,
        best.start,
        c.evaluations()
    );
    assert!(
        c.nominal.objective > 150.0,
        "nominal objective {}",
        c.nominal.objective
    );
    assert!(
        best.objective < 2.729,
        "calibrated objective {}",
        best.objective
    );
}
