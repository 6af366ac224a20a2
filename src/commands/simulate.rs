use super::{Failure, Outcome};
use calib_worker::limits;
use calib_worker::validate::{self, SolverOverrides};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::Normal;
use std::io::Write;
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// Model to simulate (see `calib models`), or the path of an FMU (`Model.fmu`).
    model: String,
    /// For an FMU: Model Exchange (calib integrates it; the default when the FMU has it) or
    /// Co-Simulation (the FMU steps itself).
    #[arg(long, value_enum)]
    interface: Option<super::fmu::InterfaceArg>,
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

pub fn run(args: Args) -> Outcome {
    let model = super::fmu::model(&args.model, args.interface)?;
    let info = model.info();
    let mut params = info.default_vector();
    for assignment in &args.set {
        let Some((name, value)) = assignment.split_once('=') else {
            return Err(Failure::input(format!(
                "--set {assignment}: expected NAME=VALUE"
            )));
        };
        let (name, value) = (name.trim(), value.trim());
        let refused = |e: validate::Invalid| Failure::input(format!("--set {assignment}: {e}"));
        let index = validate::parameter(info, name).map_err(refused)?;
        let v: f64 = value.parse().map_err(|_| {
            Failure::input(format!("--set {assignment}: `{value}` is not a number"))
        })?;
        validate::parameter_value(info, index, v).map_err(refused)?;
        params[index] = v;
    }
    if args.stop.is_nan() || args.stop <= 0.0 {
        return Err(Failure::input(format!(
            "--stop {}: must be a positive time",
            args.stop
        )));
    }
    validate::stop_time(args.stop)
        .map_err(|e| Failure::input(format!("--stop {}: {e}", args.stop)))?;
    let rows = args.stop / args.step + 1.0;
    if !(args.step > 0.0 && rows <= limits::MAX_TIMES as f64) {
        return Err(Failure::input(format!(
            "--step {}: must be positive and give at most {} rows",
            args.step,
            limits::MAX_TIMES
        )));
    }
    // The CLI's one tolerance sets both: atol a hundredth of rtol.
    let overrides = SolverOverrides {
        rtol: args.rtol,
        atol: args.rtol.map(|rtol| rtol * 1e-2),
        max_steps: None,
    };
    let options = validate::solver_options(model, overrides).map_err(|(_, e)| {
        Failure::input(format!("--rtol {}: {e}", args.rtol.unwrap_or(f64::NAN)))
    })?;
    let outputs: Vec<usize> = if args.outputs.is_empty() {
        (0..info.outputs.len()).collect()
    } else {
        args.outputs
            .iter()
            .map(|name| {
                validate::output(info, name)
                    .map_err(|e| Failure::input(format!("--outputs {name}: {e}")))
            })
            .collect::<Result<_, _>>()?
    };
    let n = (args.stop / args.step + 1e-9).floor() as usize;
    let grid: Vec<f64> = (0..=n).map(|i| i as f64 * args.step).collect();
    validate::output_grid(&grid).map_err(|e| Failure::input(format!("--stop/--step: {e}")))?;
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
