//! `calib bench diagnose --matrix`: does the diagnosis give the same verdict whatever search
//! settings a user picks?
//!
//! Records of the Furuta rig from the independent simulator `tests/python/furuta_driven.py`
//! (scipy; free swing, 40 s, 2 mrad noise, 4096 counts), one per effect, each diagnosed with
//! both frictions free on linear [0, 0.9] or log10 [1e-4, 0.9] bounds, by Nelder–Mead,
//! Nelder–Mead + Powell or all three methods, from 1 or 4 starts. A cell passes when the
//! diagnosis selects exactly the effect the record carries ("nothing" for the clean record)
//! and ends within 1.5× the noise floor. The real rig's record with a viscous-only model
//! (`examples/furuta_real_naive.toml`'s model, both viscous coefficients on [0, 0.9] or log10
//! [1e-5, 0.9]) must lead to both Coulomb frictions and end below 2.729 (the seed model's
//! objective in the seed's tool chain).

use super::{Failure, Outcome};
use calib_analysis::diagnosis::matrix::*;
use calib_analysis::diagnosis::{diagnose, Diagnosis, NOISE_FACTOR};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::Instant;

/// A row of the matrix: name, the simulator's options, the friction the campaign holds at 0,
/// and the effect the diagnosis must select (`None`: nothing).
pub type Row = (
    &'static str,
    &'static [&'static str],
    Option<&'static str>,
    Option<&'static str>,
);

/// The effects of the matrix.
pub const EFFECTS: [Row; 10] = [
    (
        "viscous-arm",
        &["--arm-viscous", "0.002"],
        None,
        Some("viscous_friction.arm"),
    ),
    (
        "viscous-pendulum",
        &["--pendulum-viscous", "0.0003"],
        None,
        Some("viscous_friction.pendulum"),
    ),
    (
        "coulomb-arm",
        &[],
        Some("armFriction"),
        Some("coulomb_friction.arm"),
    ),
    (
        "coulomb-pendulum",
        &[],
        Some("pendulumFriction"),
        Some("coulomb_friction.pendulum"),
    ),
    (
        "drag-arm",
        &["--arm-drag", "0.003"],
        None,
        Some("quadratic_drag.arm"),
    ),
    (
        "stiffness-arm",
        &["--arm-stiffness", "0.01"],
        None,
        Some("stiffness.arm"),
    ),
    (
        "offset-arm",
        &["--arm-offset", "0.05"],
        None,
        Some("offset(armJoint.phi)"),
    ),
    (
        "delay-arm",
        &["--arm-delay", "0.08"],
        None,
        Some("delay(armJoint.phi)"),
    ),
    (
        "gain-arm",
        &["--arm-gain", "0.1"],
        None,
        Some("gain(armJoint.phi)"),
    ),
    ("clean", &[], None, None),
];

/// A record from the independent simulator, `args` its effect's options.
pub fn simulator_record(script: &Path, out: &Path, args: &[&str]) -> Result<(), String> {
    let run = std::process::Command::new("python3")
        .arg(script)
        .arg("--out")
        .arg(out)
        .args(["--no-torque", "--stop", "40", "--seed", "1"])
        .args(args)
        .output()
        .map_err(|e| format!("python3 cannot run {}: {e}", script.display()))?;
    if !run.status.success() {
        return Err(format!(
            "{} failed: {}",
            script.display(),
            String::from_utf8_lossy(&run.stderr)
        ));
    }
    Ok(())
}

/// One cell of the matrix.
pub struct Cell {
    pub effect: String,
    pub bounds: &'static str,
    pub methods: &'static str,
    pub starts: usize,
    pub campaign: String,
    /// What must be selected, in any order.
    pub expected: Vec<String>,
    /// The final objective must be below this.
    pub limit: Limit,
}

#[derive(Clone, Copy)]
pub enum Limit {
    /// At most this factor of the diagnosis's noise floor.
    Floor(f64),
    /// Below this objective.
    Objective(f64),
}

/// What a cell's diagnosis gave.
pub struct Outcome1 {
    pub selected: Vec<String>,
    pub objective: f64,
    pub floor: f64,
    pub simulated: u64,
    pub seconds: f64,
    pub pass: bool,
}

pub fn judge(cell: &Cell, d: &Diagnosis) -> bool {
    let mut selected = d.selected.clone();
    let mut expected = cell.expected.clone();
    selected.sort();
    expected.sort();
    let low = match cell.limit {
        Limit::Floor(f) => d.final_fit.objective <= f * d.noise_floor,
        Limit::Objective(o) => d.final_fit.objective < o,
    };
    selected == expected && low
}

fn run_cell(cell: &Cell) -> Result<Outcome1, String> {
    let campaign = Campaign::parse(&cell.campaign, Path::new("matrix.toml"))
        .map_err(|e| format!("{}: {e}", cell.effect))?;
    let started = Instant::now();
    let d = diagnose(&campaign, &LocalEvaluator, &Silent).map_err(|e| e.to_string())?;
    Ok(Outcome1 {
        pass: judge(cell, &d),
        selected: d.selected.clone(),
        objective: d.final_fit.objective,
        floor: d.noise_floor,
        simulated: d.stats.evaluations.simulated + d.stats.trajectories,
        seconds: started.elapsed().as_secs_f64(),
    })
}

/// Every cell: the synthetic effects (records written into `dir`), then the real record's
/// when `real` is given. `only` keeps the effects whose name contains one of its words.
pub fn cells(
    script: &Path,
    dir: &Path,
    real: Option<&Path>,
    only: &[String],
) -> Result<Vec<Cell>, String> {
    let keep = |name: &str| only.is_empty() || only.iter().any(|w| name.contains(w.as_str()));
    let mut cells = Vec::new();
    for (effect, args, hold, expected) in EFFECTS.iter().filter(|e| keep(e.0)) {
        let csv = dir.join(format!("{effect}.csv"));
        simulator_record(script, &csv, args)?;
        for bounds in BOUNDS {
            for methods in METHODS {
                for starts in STARTS {
                    cells.push(Cell {
                        effect: effect.to_string(),
                        bounds,
                        methods,
                        starts,
                        campaign: synthetic_campaign(&csv, *hold, bounds, methods, starts),
                        expected: expected.iter().map(|e| e.to_string()).collect(),
                        limit: Limit::Floor(NOISE_FACTOR),
                    });
                }
            }
        }
    }
    if let Some(real) = real.filter(|_| keep("real-naive")) {
        for bounds in BOUNDS {
            for methods in METHODS {
                for starts in STARTS {
                    cells.push(Cell {
                        effect: "real-naive".into(),
                        bounds,
                        methods,
                        starts,
                        campaign: naive_real_campaign(real, bounds, methods, starts),
                        expected: vec![
                            "coulomb_friction.arm".into(),
                            "coulomb_friction.pendulum".into(),
                        ],
                        limit: Limit::Objective(SEED_REAL_OBJECTIVE),
                    });
                }
            }
        }
    }
    Ok(cells)
}

#[derive(clap::Args)]
pub struct MatrixArgs {
    /// The independent simulator that makes the records.
    #[arg(long, default_value = "tests/python/furuta_driven.py")]
    simulator: PathBuf,
    /// The real rig's record (skipped when absent).
    #[arg(long, default_value = "../shared/data/real/FurutaData.mat")]
    real: PathBuf,
    /// Keep only the rows whose effect contains one of these words (comma-separated, e.g.
    /// `stiffness,real`).
    #[arg(long, value_delimiter = ',')]
    only: Vec<String>,
    /// Cells diagnosed at the same time.
    #[arg(long, default_value_t = 2)]
    pub jobs: usize,
}

pub fn run(args: MatrixArgs) -> Outcome {
    let dir = std::env::temp_dir().join(format!("calib-matrix-{}", std::process::id()));
    std::fs::create_dir_all(&dir).map_err(|e| Failure::input(format!("{}: {e}", dir.display())))?;
    let real = args.real.exists().then_some(args.real.as_path());
    if real.is_none() {
        eprintln!(
            "{} is absent: the real record's cells are left out",
            args.real.display()
        );
    }
    let cells = cells(&args.simulator, &dir, real, &args.only).map_err(Failure::input)?;
    let next = Mutex::new(0usize);
    let results: Mutex<Vec<Option<Result<Outcome1, String>>>> =
        Mutex::new((0..cells.len()).map(|_| None).collect());
    std::thread::scope(|scope| {
        for _ in 0..args.jobs.max(1) {
            scope.spawn(|| loop {
                let i = {
                    let mut n = next.lock().unwrap();
                    *n += 1;
                    *n - 1
                };
                let Some(cell) = cells.get(i) else { break };
                let outcome = run_cell(cell);
                if let Ok(o) = &outcome {
                    eprintln!(
                        "{:<17} {:<6} {:<9} {} start(s): {:<48} {:>8.3} x floor {:>6} sims {:>6.1} s {}",
                        cell.effect,
                        cell.bounds,
                        cell.methods,
                        cell.starts,
                        format!("{:?}", o.selected),
                        o.objective / o.floor,
                        o.simulated,
                        o.seconds,
                        if o.pass { "ok" } else { "FAIL" }
                    );
                }
                results.lock().unwrap()[i] = Some(outcome);
            });
        }
    });
    let results: Vec<Result<Outcome1, String>> = results
        .into_inner()
        .unwrap()
        .into_iter()
        .map(|r| r.expect("every cell ran"))
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    table(&cells, &results);
    let failed = results
        .iter()
        .filter(|r| !matches!(r, Ok(o) if o.pass))
        .count();
    if failed > 0 {
        return Err(Failure::internal(format!(
            "{failed} of {} cells failed",
            cells.len()
        )));
    }
    Ok(())
}

/// The table: one row per cell, then the pass count and the cost.
fn table(cells: &[Cell], results: &[Result<Outcome1, String>]) {
    println!(
        "| record | bounds | methods | starts | selected | objective / floor | simulations | |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let mut sims = Vec::new();
    for (cell, r) in cells.iter().zip(results) {
        match r {
            Ok(o) => {
                sims.push(o.simulated);
                let ratio = match cell.limit {
                    Limit::Floor(_) => format!("{:.3}", o.objective / o.floor),
                    Limit::Objective(_) => {
                        format!(
                            "{:.3} (objective {:.4})",
                            o.objective / o.floor,
                            o.objective
                        )
                    }
                };
                let selected = if o.selected.is_empty() {
                    "nothing missing".to_string()
                } else {
                    o.selected.join(" + ")
                };
                println!(
                    "| {} | {} | {} | {} | {} | {} | {} | {} |",
                    cell.effect,
                    cell.bounds,
                    cell.methods,
                    cell.starts,
                    selected,
                    ratio,
                    o.simulated,
                    if o.pass { "ok" } else { "**FAIL**" }
                );
            }
            Err(e) => println!(
                "| {} | {} | {} | {} | error: {e} | | | **FAIL** |",
                cell.effect, cell.bounds, cell.methods, cell.starts
            ),
        }
    }
    let passed = results
        .iter()
        .filter(|r| matches!(r, Ok(o) if o.pass))
        .count();
    sims.sort_unstable();
    let median = sims.get(sims.len() / 2).copied().unwrap_or(0);
    println!(
        "\n{passed} of {} cells pass; simulations per diagnosis: median {median}, most {}",
        cells.len(),
        sims.last().copied().unwrap_or(0)
    );
}
