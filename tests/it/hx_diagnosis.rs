//! Diagnosis on the heat exchanger: a slow heat-flow sensor and heat lost to the room are
//! found in records the project's own low-fidelity model makes, within 2,200 simulations.

use crate::common::*;
use calib_analysis::diagnosis::{diagnose, Verdict};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use calib_model::Run;
use calib_model::{models, SolverOptions};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::path::Path;

/// A 300 s `hx_lowfi` record with `set` applied, 50 Pa and 5 W of noise, on a 1 s grid.
fn record(dir: &Path, set: &[(&str, f64)]) -> std::path::PathBuf {
    let model = models::find("hx_lowfi").unwrap();
    let info = model.info();
    let mut p = info.default_vector();
    for (name, v) in [("CF_RefHT", 1.5), ("CF_Refdp", 1.3)].iter().chain(set) {
        p[info.parameter_index(name).unwrap()] = *v;
    }
    let grid: Vec<f64> = (0..=300).map(f64::from).collect();
    let outputs = [
        info.output_index("dp_ref").unwrap(),
        info.output_index("Qdot_refTotal").unwrap(),
    ];
    let t = model
        .simulate(&Run::new(&p, &grid, &outputs, &SolverOptions::default()))
        .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut noise = |sigma: f64| gaussian(&mut rng, sigma);
    let mut text = String::from("time,dp_ref,Qdot_refTotal\n");
    for (i, time) in grid.iter().enumerate() {
        let dp = t.values[0][i] + noise(50.0);
        let q = t.values[1][i] + noise(5.0);
        text.push_str(&format!("{time},{dp},{q}\n"));
    }
    write(dir, "hx.csv", &text)
}

fn campaign(dir: &Path, data: &Path) -> std::path::PathBuf {
    let text = format!(
        r#"
name = "hx_table"
[model]
name = "hx_lowfi"
stop_time = 300.0
[measurement]
file = "{}"
[[outputs]]
model = "dp_ref"
measured = "dp_ref"
[[outputs]]
model = "Qdot_refTotal"
measured = "Qdot_refTotal"
weight = 100.0
[[parameters]]
name = "CF_RefHT"
nominal = 1.0
min = 0.1
max = 5.0
[[parameters]]
name = "CF_Refdp"
nominal = 1.0
min = 0.1
max = 5.0
[window]
start = 50.0
stop = 230.0
[search]
methods = ["nelder-mead"]
starts = 1
max_evaluations = 150
seed = 1
[diagnosis]
holdout_start = 231.0
holdout_stop = 300.0
refit = 2
"#,
        data.display()
    );
    write(dir, "hx.toml", &text)
}

fn finds(effect: &str, value: f64) {
    let dir = tempfile::tempdir().unwrap();
    let data = record(dir.path(), &[(effect, value)]);
    let c = Campaign::load(&campaign(dir.path(), &data)).unwrap();
    let d = diagnose(&c, &LocalEvaluator, &Silent).unwrap();
    let simulations = d.stats.evaluations.simulated + d.stats.trajectories;
    println!(
        "{effect}: verdict {:?}, selected {:?}, {:.4e} -> {:.4e} (floor {:.4e}), ranked {:?}, \
         {simulations} simulations ({} evaluations, {} trajectories), {:.1} s",
        d.verdict,
        d.selected,
        d.baseline.objective,
        d.final_fit.objective,
        d.noise_floor,
        d.candidates
            .iter()
            .take(3)
            .map(|c| (&c.effect, c.score))
            .collect::<Vec<_>>(),
        d.stats.evaluations.simulated,
        d.stats.trajectories,
        d.elapsed.as_secs_f64()
    );
    assert_eq!(d.selected.first().map(String::as_str), Some(effect));
    // The refits start where the ranking left off and stop when the objective stops moving:
    // the whole diagnosis costs at most 2,200 simulations (before: over 10,000), with the
    // local refits of the swaps the equivalents' check tries (a lag for a dead time, a gain
    // or an offset of the same output) where no earlier refit answers them.
    assert!(simulations <= 2_200, "{simulations} simulations");
    assert_eq!(d.verdict, Verdict::Explained);
    let found = d
        .final_fit
        .parameters
        .iter()
        .find(|p| p.name == effect)
        .unwrap();
    assert!(
        (found.value / value - 1.0).abs() < 0.1,
        "{} vs {value}",
        found.value
    );
}

#[test]
fn a_slow_heat_flow_sensor_is_found() {
    finds("lag(Qdot_refTotal)", 8.0);
}

#[test]
fn heat_lost_to_the_room_is_found() {
    finds("ambient_loss", 20.0);
}

/// The shipped example (`examples/hx_lag.toml`, its record made with an 8 s sensor lag on
/// CF_RefHT = 1.5, CF_Refdp = 1.3) reaches the figures docs/diagnosis.md gives for it.
#[test]
fn the_shipped_lag_example_finds_the_lag_docs_report() {
    let c = Campaign::load(&repo().join("examples/hx_lag.toml")).unwrap();
    let d = diagnose(&c, &LocalEvaluator, &Silent).unwrap();
    let value = |name: &str| {
        d.final_fit
            .parameters
            .iter()
            .find(|p| p.name == name)
            .unwrap_or_else(|| panic!("{name} not in the final fit"))
            .value
    };
    let ratio = d.final_fit.objective / d.noise_floor;
    println!(
        "hx_lag: selected {:?}, lag {:.4}, CF_RefHT {:.4}, CF_Refdp {:.5}, {:.4e} -> {:.4e}, \
         {ratio:.3}x the floor",
        d.selected,
        value("lag(Qdot_refTotal)"),
        value("CF_RefHT"),
        value("CF_Refdp"),
        d.baseline.objective,
        d.final_fit.objective,
    );
    assert_eq!(d.verdict, Verdict::Explained);
    assert_eq!(d.selected, ["lag(Qdot_refTotal)"]);
    // docs: 7.982 s [7.915, 8.048], CF_RefHT 1.487, CF_Refdp 1.3002, 1.11x the floor.
    assert!((value("lag(Qdot_refTotal)") - 8.0).abs() < 0.1);
    assert!((value("CF_RefHT") / 1.5 - 1.0).abs() < 0.015);
    assert!((value("CF_Refdp") / 1.3 - 1.0).abs() < 0.002);
    assert!(ratio <= 1.2, "{ratio}x the noise floor");
    assert!(d.baseline.objective / d.final_fit.objective > 100.0);
    let simulations = d.stats.evaluations.simulated + d.stats.trajectories;
    println!("hx_lag: {simulations} simulations");
    // 1,670 measured: the swaps for the dead time and the gain, whose refits alone ended at
    // 33x and 175x the floor, are answered by those refits, not refitted again (1,999 when
    // they were; see diagnosis::equivalents::SETTLED_FAR).
    assert!(simulations <= 1_800, "{simulations} simulations");
}
