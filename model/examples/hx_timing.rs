//! Median wall time of one 300 s simulation of each heat-exchanger model, all outputs on
//! a 1 s and a 0.5 s grid, at the model's own tolerance (`--tight`: rtol 1e-8;
//! `--rtol X`: rtol X), with the solver's step and right-hand-side counts. The models
//! integrate by Runge–Kutta–Chebyshev at rtol ≥ 1e-6 and by Dormand–Prince at tighter
//! tolerances (see the `hx` module documentation).
//!
//! `cargo run --release -p calib-worker --example hx_timing [-- --tight]`

use calib_model::models::hx;
use calib_model::Run;
use calib_model::{Model, SolverOptions};
use std::time::Instant;

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let tight = args.iter().any(|a| a == "--tight");
    let rtol: Option<f64> = args
        .iter()
        .position(|a| a == "--rtol")
        .and_then(|i| args.get(i + 1))
        .map(|v| v.parse().expect("--rtol takes a number"));
    for model in [hx::highfi(), hx::lowfi()] {
        let info = model.info();
        // The model's own (calibration) tolerance, or with `--tight` rtol 1e-8.
        let mut options = if tight {
            SolverOptions::default()
        } else {
            model.default_options()
        };
        if let Some(rtol) = rtol {
            options.rtol = rtol;
        }
        let params = info.default_vector();
        let outputs: Vec<usize> = (0..info.outputs.len()).collect();
        for step in [1.0, 0.5] {
            let grid: Vec<f64> = (0..=(300.0 / step) as usize)
                .map(|i| i as f64 * step)
                .collect();
            let mut times = Vec::new();
            let mut stats = None;
            for _ in 0..21 {
                let t0 = Instant::now();
                let tr = model
                    .simulate(&Run::new(&params, &grid, &outputs, &options))
                    .expect("simulation");
                times.push(t0.elapsed().as_secs_f64());
                stats = Some(tr.stats);
            }
            let s = stats.expect("at least one run");
            println!(
                "{:10} grid {step:3} s: median {:7.2} ms  ({} steps, {} rejected, {} rhs)",
                info.name,
                median(times) * 1e3,
                s.accepted_steps,
                s.rejected_steps,
                s.rhs_evaluations
            );
        }
    }
}
