use super::{Failure, Outcome};
use calib_worker::models;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::Normal;
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Model to simulate (see `calib models`).
    model: String,
    /// Set a parameter or effect: NAME=VALUE (repeatable). Others keep their defaults.
    #[arg(long = "set", value_name = "NAME=VALUE")]
    set: Vec<String>,
    /// End of the simulation [s].
    #[arg(long, default_value_t = 10.0)]
    stop: f64,
    /// Output interval [s].
    #[arg(long, default_value_t = 0.01)]
    step: f64,
    /// Outputs to write, comma separated (default: all).
    #[arg(long, value_delimiter = ',')]
    outputs: Vec<String>,
    /// Relative tolerance of the ODE solver [default: the model's calibration tolerance].
    #[arg(long)]
    rtol: Option<f64>,
    /// Add white Gaussian noise to an output: NAME=SIGMA in the output's unit (repeatable),
    /// to make a synthetic record.
    #[arg(long = "noise", value_name = "NAME=SIGMA")]
    noise: Vec<String>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// CSV file to write (default: standard output).
    #[arg(long)]
    out: Option<PathBuf>,
}

/// Most output rows `calib simulate` writes.
const MAX_ROWS: f64 = 1e7;

pub fn run(args: Args) -> Outcome {
    let Some(model) = models::find(&args.model) else {
        let known: Vec<_> = models::all()
            .iter()
            .map(|m| m.info().name.clone())
            .collect();
        return Err(Failure::input(format!(
            "unknown model `{}` (hosted: {})",
            args.model,
            known.join(", ")
        )));
    };
    let info = model.info();
    let mut params = info.default_vector();
    for assignment in &args.set {
        let Some((name, value)) = assignment.split_once('=') else {
            return Err(Failure::input(format!(
                "--set {assignment}: expected NAME=VALUE"
            )));
        };
        let (name, value) = (name.trim(), value.trim());
        let Some(index) = info.parameter_index(name) else {
            return Err(Failure::input(format!(
                "--set {assignment}: model `{}` has no parameter `{name}`",
                info.name
            )));
        };
        let v: f64 = value.parse().map_err(|_| {
            Failure::input(format!("--set {assignment}: `{value}` is not a number"))
        })?;
        let (lo, hi) = info.bounds_at(index);
        if !v.is_finite() || v < lo || v > hi {
            return Err(Failure::input(format!(
                "--set {assignment}: {v} is outside the admissible range [{lo}, {hi}]"
            )));
        }
        params[index] = v;
    }
    if !(args.stop > 0.0 && args.stop.is_finite()) {
        return Err(Failure::input(format!(
            "--stop {}: must be a positive time",
            args.stop
        )));
    }
    if !(args.step > 0.0 && args.stop / args.step <= MAX_ROWS) {
        return Err(Failure::input(format!(
            "--step {}: must be positive and give at most {MAX_ROWS} rows",
            args.step
        )));
    }
    let mut options = model.default_options();
    if let Some(rtol) = args.rtol {
        if !(rtol > 0.0 && rtol < 1.0) {
            return Err(Failure::input(format!("--rtol {rtol}: must be in (0, 1)")));
        }
        options.rtol = rtol;
        options.atol = rtol * 1e-2;
    }
    let outputs: Vec<usize> = if args.outputs.is_empty() {
        (0..info.outputs.len()).collect()
    } else {
        args.outputs
            .iter()
            .map(|name| {
                info.output_index(name).ok_or_else(|| {
                    Failure::input(format!(
                        "--outputs: model `{}` has no output `{name}`",
                        info.name
                    ))
                })
            })
            .collect::<Result<_, _>>()?
    };
    let n = (args.stop / args.step + 1e-9).floor() as usize;
    let grid: Vec<f64> = (0..=n).map(|i| i as f64 * args.step).collect();
    let mut noise = vec![0.0; outputs.len()];
    for assignment in &args.noise {
        let Some((name, sigma)) = assignment.split_once('=') else {
            return Err(Failure::input(format!(
                "--noise {assignment}: expected NAME=SIGMA"
            )));
        };
        let Some(k) = outputs
            .iter()
            .position(|&o| info.outputs[o].name == name.trim())
        else {
            return Err(Failure::input(format!(
                "--noise {assignment}: `{name}` is not among the written outputs"
            )));
        };
        match sigma.trim().parse::<f64>() {
            Ok(s) if s >= 0.0 && s.is_finite() => noise[k] = s,
            _ => {
                return Err(Failure::input(format!(
                    "--noise {assignment}: `{sigma}` is not a standard deviation"
                )))
            }
        }
    }
    let mut trajectory = model
        .simulate(&params, &grid, &outputs, &options)
        .map_err(|e| Failure::internal(format!("simulation failed: {e}")))?;

    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    for (series, &sigma) in trajectory.values.iter_mut().zip(&noise) {
        if sigma > 0.0 {
            // Checked above: every σ is finite and not negative.
            let normal = Normal::new(0.0, sigma)
                .map_err(|e| Failure::internal(format!("noise of σ = {sigma}: {e}")))?;
            for v in series.iter_mut() {
                *v += rng.sample(normal);
            }
        }
    }

    let sink: Box<dyn Write> = match &args.out {
        Some(path) => Box::new(
            std::fs::File::create(path)
                .map_err(|e| Failure::internal(format!("cannot write {}: {e}", path.display())))?,
        ),
        None => Box::new(std::io::stdout().lock()),
    };
    let mut csv = csv::Writer::from_writer(std::io::BufWriter::new(sink));
    let write_error = |e: csv::Error| Failure::internal(format!("cannot write CSV: {e}"));
    let mut header = vec!["time".to_string()];
    header.extend(outputs.iter().map(|&o| info.outputs[o].name.clone()));
    csv.write_record(&header).map_err(write_error)?;
    for (i, t) in grid.iter().enumerate() {
        let mut row = vec![format!("{t}")];
        row.extend(trajectory.values.iter().map(|v| format!("{}", v[i])));
        csv.write_record(&row).map_err(write_error)?;
    }
    csv.flush()
        .map_err(|e| Failure::internal(format!("cannot write CSV: {e}")))?;
    if let Some(path) = &args.out {
        eprintln!(
            "wrote {} rows of {} outputs to {}",
            grid.len(),
            outputs.len(),
            path.display()
        );
    }
    Ok(())
}
