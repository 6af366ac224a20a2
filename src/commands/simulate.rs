use super::{Failure, Outcome};
use calib_worker::inputs::{InputSignal, Inputs, Interpolation};
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
    /// Start of the simulation [s]: an FMU is initialised there (hosted models start at 0).
    #[arg(long, default_value_t = 0.0)]
    start: f64,
    /// End of the simulation [s]: always the last row, after a shorter interval when it is
    /// not a whole number of steps after the start.
    #[arg(long, default_value_t = 10.0)]
    stop: f64,
    /// Output interval [s].
    #[arg(long, default_value_t = 0.01)]
    step: f64,
    /// For a Co-Simulation FMU: the communication step [s], the most one `doStep` advances
    /// (several between two rows when it is smaller than --step; never past a row) [default:
    /// the FMU's DefaultExperiment stepSize, else --step].
    #[arg(long)]
    cs_step: Option<f64>,
    /// Outputs to write, comma separated (default: all).
    #[arg(long, value_delimiter = ',')]
    outputs: Vec<String>,
    /// Relative tolerance of the ODE solver, or the one a Co-Simulation FMU is told
    /// [default: the model's calibration tolerance; an FMU's DefaultExperiment tolerance
    /// when it gives one].
    #[arg(long)]
    rtol: Option<f64>,
    /// Drive a model input by a profile: NAME=T:V,T:V,... (repeatable), times in s and
    /// values in the input's unit, straight lines between the points, the first value
    /// before them and the last after; two points at one time make a step. The input is
    /// written as a column of its own, after `time`.
    #[arg(long = "input", value_name = "NAME=T:V,...")]
    input: Vec<String>,
    /// Add white Gaussian noise to an output, or to the column of a driven input (the model
    /// is driven by the profile itself, as a bench's sensor records its boundary condition):
    /// NAME=SIGMA in its unit (repeatable), to make a synthetic record.
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
    if args.stop.is_nan() || args.stop <= args.start {
        return Err(Failure::input(format!(
            "--stop {}: must be a time after the start ({} s)",
            args.stop, args.start
        )));
    }
    validate::stop_time(args.stop)
        .map_err(|e| Failure::input(format!("--stop {}: {e}", args.stop)))?;
    let rows = (args.stop - args.start) / args.step + 2.0;
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
        start_time: Some(args.start),
        communication_step: args.cs_step,
    };
    let options = validate::solver_options(model, overrides).map_err(|(option, e)| {
        let (flag, value) = match option {
            "start_time" => ("--start", Some(args.start)),
            "communication_step" => ("--cs-step", args.cs_step),
            _ => ("--rtol", args.rtol),
        };
        Failure::input(format!("{flag} {}: {e}", value.unwrap_or(f64::NAN)))
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
    let grid = output_times(args.start, args.stop, args.step);
    validate::output_grid(&grid).map_err(|e| Failure::input(format!("--stop/--step: {e}")))?;
    let inputs = Inputs {
        signals: args
            .input
            .iter()
            .map(|a| profile(info, a, args.stop))
            .collect::<Result<_, _>>()?,
    };
    inputs
        .check(info, 0.0f64.min(args.start), args.stop)
        .map_err(|e| Failure::input(format!("--input: {e}")))?;
    // Noise of the written outputs, then of the driven inputs' columns.
    let mut noise = vec![0.0; outputs.len() + inputs.signals.len()];
    for assignment in &args.noise {
        let Some((name, sigma)) = assignment.split_once('=') else {
            return Err(Failure::input(format!(
                "--noise {assignment}: expected NAME=SIGMA"
            )));
        };
        let Some(k) = outputs
            .iter()
            .position(|&o| info.outputs[o].name == name.trim())
            .or_else(|| {
                inputs
                    .signals
                    .iter()
                    .position(|s| info.inputs[s.input].name == name.trim())
                    .map(|k| outputs.len() + k)
            })
        else {
            return Err(Failure::input(format!(
                "--noise {assignment}: `{name}` is neither a written output nor a driven input"
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
        .simulate_driven(&params, &grid, &outputs, &options, &inputs)
        .map_err(|e| Failure::internal(format!("simulation failed: {e}")))?;
    let mut columns: Vec<Vec<f64>> = inputs
        .signals
        .iter()
        .map(|s| grid.iter().map(|&t| s.at(t)).collect())
        .collect();

    // The outputs' noise is drawn first, so a record without inputs keeps its draws.
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    for (series, &sigma) in trajectory
        .values
        .iter_mut()
        .chain(columns.iter_mut())
        .zip(&noise)
    {
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
    header.extend(
        inputs
            .signals
            .iter()
            .map(|s| info.inputs[s.input].name.clone()),
    );
    header.extend(outputs.iter().map(|&o| info.outputs[o].name.clone()));
    csv.write_record(&header).map_err(write_error)?;
    for (i, t) in grid.iter().enumerate() {
        let mut row = vec![format!("{t}")];
        row.extend(
            columns
                .iter()
                .chain(&trajectory.values)
                .map(|v| format!("{}", v[i])),
        );
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

/// The signal of `--input NAME=T:V,T:V,...`: the points, read linearly, extended to cover
/// the simulation from 0 (hosted models) to `stop` by the first and the last value.
fn profile(
    info: &calib_worker::ModelInfo,
    assignment: &str,
    stop: f64,
) -> Result<InputSignal, Failure> {
    let refused = |why: String| Failure::input(format!("--input {assignment}: {why}"));
    let Some((name, points)) = assignment.split_once('=') else {
        return Err(refused("expected NAME=T:V,T:V,...".into()));
    };
    let input = validate::input(info, name.trim()).map_err(|e| refused(e.to_string()))?;
    let mut times = Vec::new();
    let mut values = Vec::new();
    for point in points.split(',') {
        let parsed = point.split_once(':').and_then(|(t, v)| {
            Some((t.trim().parse::<f64>().ok()?, v.trim().parse::<f64>().ok()?))
        });
        let Some((t, v)) = parsed else {
            return Err(refused(format!("`{point}` is not TIME:VALUE")));
        };
        times.push(t);
        values.push(v);
    }
    // Checked with the other inputs; here only what extending them needs.
    if times.iter().chain(&values).any(|x| !x.is_finite()) {
        return Err(refused("times and values must be finite".into()));
    }
    if times[0] > 0.0 {
        times.insert(0, 0.0);
        values.insert(0, values[0]);
    }
    let last = times.len() - 1;
    if times[last] < stop {
        times.push(stop);
        values.push(values[last]);
    }
    Ok(InputSignal {
        input,
        times: times.into(),
        values: values.into(),
        interpolation: Interpolation::Linear,
    })
}

/// `start`, `start + step`, … up to `stop`, and `stop` itself: the last interval is shorter
/// when the span is not a whole number of steps (a last time within a billionth of a step of
/// the stop is the stop).
fn output_times(start: f64, stop: f64, step: f64) -> Vec<f64> {
    let n = ((stop - start) / step + 1e-9).floor() as usize;
    let mut grid: Vec<f64> = (0..=n).map(|i| start + i as f64 * step).collect();
    match grid.last_mut() {
        Some(last) if stop - *last <= 1e-9 * step => *last = stop,
        _ => grid.push(stop),
    }
    grid
}

#[cfg(test)]
mod tests {
    use super::output_times;

    #[test]
    fn the_stop_time_is_always_the_last_output_time() {
        assert_eq!(output_times(0.0, 1.0, 0.25), [0.0, 0.25, 0.5, 0.75, 1.0]);
        assert_eq!(output_times(0.0, 0.9, 0.25), [0.0, 0.25, 0.5, 0.75, 0.9]);
        assert_eq!(output_times(1.0, 1.5, 0.25), [1.0, 1.25, 1.5]);
        let g = output_times(0.0, 12.566, 0.1);
        assert_eq!((g.len(), g[125], g[126]), (127, 12.5, 12.566));
        let g = output_times(0.0, 20.0, 0.01);
        assert_eq!((g.len(), g[2000]), (2001, 20.0));
    }
}
