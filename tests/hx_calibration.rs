//! Calibrating the low-fidelity evaporator on the high-fidelity record (the seed's case).

mod common;

use calib_coordinator::calibration::calibrate;
use calib_coordinator::campaign::{Campaign, Method};
use calib_coordinator::evaluator::LocalEvaluator;
use calib_coordinator::optim::problem::Silent;
use common::*;

/// `CF_RefHT` and `CF_Refdp` of `hx_lowfi` against `hx_highfi` over 50–200 s: the seed
/// reached a 37× lower objective (1.495e9 → 4.029e7). One Nelder–Mead run from the nominal
/// point on a small budget must do at least as well.
#[test]
fn two_factors_reduce_the_objective_at_least_as_much_as_the_seed() {
    let mut campaign = Campaign::load(&repo().join("examples/hx.toml")).unwrap();
    campaign.search.methods = vec![Method::NelderMead];
    campaign.search.starts = 1;
    campaign.search.max_evaluations = 120;
    let c = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let best = c.best_run();
    let reduction = c.nominal.objective / best.objective;
    println!(
        "hx: nominal {:.4e} -> {:.4e} ({reduction:.0}x) at CF_RefHT {:.4} CF_Refdp {:.4}, {} evaluations",
        c.nominal.objective,
        best.objective,
        best.point[0],
        best.point[1],
        c.evaluations()
    );
    assert!(reduction >= 37.0, "reduction {reduction}");
}
