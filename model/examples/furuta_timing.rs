//! Median wall time of one 40 s `furuta` simulation (4001 output points, the default
//! tolerance, default parameters): the figure `calib bench` reports as `furuta_ms`, measured
//! without building the whole workspace; and the same with larger stick–slip frictions.
//!
//! `cargo run --release -p calib-worker --example furuta_timing [-- --repeat N]`

use calib_model::models::furuta::Furuta;
use calib_model::Run;
use calib_model::{Model, SolverOptions};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let repeat: usize = args
        .iter()
        .position(|a| a == "--repeat")
        .and_then(|i| args.get(i + 1))
        .map_or(201, |v| v.parse().expect("--repeat takes a count"));
    let model = Furuta::new();
    let info = model.info();
    let grid: Vec<f64> = (0..=4000).map(|i| i as f64 * 0.01).collect();
    let options = SolverOptions::default();
    let default = info.default_vector();
    let mut frictions = default.clone();
    frictions[0] = 0.05; // armFriction
    frictions[1] = 0.02; // pendulumFriction
    for (name, params) in [("default", default), ("frictions", frictions)] {
        let mut times = Vec::with_capacity(repeat);
        let mut stats = None;
        for _ in 0..repeat {
            let t0 = Instant::now();
            let tr = model
                .simulate(&Run::new(&params, &grid, &[0, 1], &options))
                .expect("simulation");
            times.push(t0.elapsed().as_secs_f64());
            stats = Some(tr.stats);
        }
        let s = stats.expect("at least one run");
        println!(
            "furuta {name:8}: median {:.3} ms  ({} steps, {} rejected, {} events, {} rhs)",
            median(times) * 1e3,
            s.accepted_steps,
            s.rejected_steps,
            s.events,
            s.rhs_evaluations
        );
    }
}
