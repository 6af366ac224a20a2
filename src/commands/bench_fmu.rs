//! `calib bench fmu`: what running a model as an FMU costs per evaluation, against the same
//! equations built in.
//!
//! The model is the Reference FMUs' VanDerPol (`../shared/fmus/build.sh OUT 2` builds it);
//! the built-in twin integrates the same right-hand side, written in Rust, with the same
//! Dormand–Prince and tolerances, and gives the same trajectory bit for bit
//! (`model/tests/it/fmu_reference.rs`).

use super::{Failure, Outcome};
use calib_model::fmu::{self, Interface};
use calib_model::ode::{self, HybridSystem};
use calib_model::Run;
use calib_model::{Model, SolverOptions};
use std::path::PathBuf;
use std::time::{Duration, Instant};

#[derive(clap::Args)]
pub struct Args {
    /// The Reference FMUs' VanDerPol.fmu (FMI 2.0 or 3.0).
    #[arg(long)]
    fmu: PathBuf,
    /// Repetitions of each measurement (the median is reported).
    #[arg(long, default_value_t = 101)]
    repeat: usize,
}

struct VanDerPol {
    mu: f64,
}

impl HybridSystem for VanDerPol {
    fn dim(&self) -> usize {
        2
    }
    fn rhs(&self, _t: f64, y: &[f64], dy: &mut [f64]) {
        dy[0] = y[1];
        dy[1] = self.mu * ((1.0 - y[0] * y[0]) * y[1]) - y[0];
    }
}

fn median(repeat: usize, mut f: impl FnMut()) -> Duration {
    f();
    let mut samples: Vec<Duration> = (0..repeat.max(1))
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed()
        })
        .collect();
    samples.sort();
    samples[samples.len() / 2]
}

fn us(d: Duration) -> f64 {
    d.as_secs_f64() * 1e6
}

pub fn run(args: Args) -> Outcome {
    let options = SolverOptions::default();
    let grid: Vec<f64> = (0..=400).map(|i| i as f64 * 0.05).collect();
    let failed =
        |e: &dyn std::fmt::Display| Failure::internal(format!("{}: {e}", args.fmu.display()));

    let mut sink = 0.0;
    let native = median(args.repeat, || {
        let mut last = 0.0;
        ode::integrate(
            &mut VanDerPol { mu: 1.7 },
            &[2.0, 0.0],
            &grid,
            &options,
            |_, y| last += y[0],
        )
        .expect("van der Pol integrates");
        sink += last;
    });

    let mut rows = vec![("built-in (Rust right-hand side)".to_string(), native)];
    for interface in [Interface::ModelExchange, Interface::CoSimulation] {
        let local = fmu::open_local(&args.fmu, Some(interface)).map_err(|e| failed(&e))?;
        let isolated: &dyn Model = fmu::open(&args.fmu, Some(interface)).map_err(|e| failed(&e))?;
        for (place, model) in [
            ("in this process", &local as &dyn Model),
            ("in a child process", isolated),
        ] {
            let info = model.info();
            let mut params = info.default_vector();
            let mu = info
                .parameter_index("mu")
                .ok_or_else(|| failed(&"no parameter `mu`: not VanDerPol"))?;
            params[mu] = 1.7;
            let outputs = [info.output_index("x0").unwrap_or(0)];
            let mut error = None;
            let t = median(args.repeat, || {
                if let Err(e) = model.simulate(&Run::new(&params, &grid, &outputs, &options)) {
                    error = Some(e);
                }
            });
            if let Some(e) = error {
                return Err(failed(&e));
            }
            rows.push((format!("FMU, {}, {place}", interface.name()), t));
        }
        if interface == Interface::ModelExchange {
            let (fresh, reset) = local.instance_costs(args.repeat).map_err(|e| failed(&e))?;
            println!(
                "instance: instantiate + free {:.1} µs, reset {:.1} µs (reused with a reset)",
                us(fresh),
                us(reset)
            );
        }
    }
    println!(
        "VanDerPol, 20 s, 401 output times, rtol {:e}; medians of {}:",
        options.rtol, args.repeat
    );
    for (what, t) in &rows {
        println!(
            "  {what:<52} {:>9.1} µs  overhead {:>8.1} µs",
            us(*t),
            us(*t) - us(native)
        );
    }
    std::hint::black_box(sink);
    Ok(())
}
