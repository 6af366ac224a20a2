use super::{Failure, Outcome};
use calib_model::inputs::{InputSignal, Inputs, Interpolation};
use calib_model::limits;
use calib_model::model::{Model, ModelInfo, SolverOptions};
use calib_model::validate::{self, SolverOverrides};
use calib_model::Run;
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
    /// Drive model inputs (repeatable), from a file or by a profile. FILE.csv: the first
    /// column is time [s], the others are named after the model's inputs (see `calib
    /// models`), each covering the simulated span. NAME=T:V,T:V,...: times in s and values
    /// in the input's unit, straight lines between the points, the first value before them
    /// and the last after; two points at one time make a step; the input is written as a
    /// column of its own, after `time`. Inputs left undriven keep the model's own values.
    #[arg(long = "input", value_name = "FILE.csv | NAME=T:V,...")]
    input: Vec<String>,
    /// Add white Gaussian noise to an output, or to the column of a driven input (the model
    /// is driven by the profile itself, as a bench's sensor records its boundary condition):
    /// NAME=SIGMA in its unit (repeatable), to make a synthetic record.
    #[arg(long = "noise", value_name = "NAME=SIGMA")]
    noise: Vec<String>,
    /// Seed of the noise.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// How an input file's samples are read between them: `linear` (a straight line from
    /// one sample to the next) or `hold` (each sample until the next).
    #[arg(long, value_enum, default_value = "linear", requires = "input")]
    input_interpolation: InterpolationArg,
    /// CSV file to write (default: standard output).
    #[arg(long)]
    out: Option<PathBuf>,
}

#[derive(Clone, Copy, clap::ValueEnum)]
pub enum InterpolationArg {
    Linear,
    Hold,
}

/// The signals of an input file: time in the first column, one input per other column,
/// named after the model's inputs.
fn read_inputs(
    path: &std::path::Path,
    info: &calib_model::ModelInfo,
    interpolation: Interpolation,
) -> Result<Inputs, Failure> {
    let shown = path.display();
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| Failure::input(format!("--input {shown}: {e}")))?;
    let header: Vec<String> = reader
        .headers()
        .map_err(|e| Failure::input(format!("--input {shown}: {e}")))?
        .iter()
        .map(str::to_string)
        .collect();
    if header.len() < 2 {
        return Err(Failure::input(format!(
            "--input {shown}: expected a time column, then one column per input"
        )));
    }
    let mut indices = Vec::with_capacity(header.len() - 1);
    for name in &header[1..] {
        let index = validate::input(info, name)
            .map_err(|e| Failure::input(format!("--input {shown}: column `{name}`: {e}")))?;
        if indices.contains(&index) {
            return Err(Failure::input(format!(
                "--input {shown}: column `{name}` appears twice"
            )));
        }
        indices.push(index);
    }
    let mut times = Vec::new();
    let mut columns = vec![Vec::new(); indices.len()];
    for (row, record) in reader.records().enumerate() {
        let record = record.map_err(|e| Failure::input(format!("--input {shown}: {e}")))?;
        let line = row + 2;
        let number = |k: usize| -> Result<f64, Failure> {
            let cell = record.get(k).unwrap_or("");
            cell.parse::<f64>().map_err(|_| {
                Failure::input(format!(
                    "--input {shown}: line {line}, column `{}`: `{cell}` is not a number",
                    header[k]
                ))
            })
        };
        times.push(number(0)?);
        for (k, column) in columns.iter_mut().enumerate() {
            column.push(number(k + 1)?);
        }
    }
    let times: std::sync::Arc<[f64]> = times.into();
    Ok(Inputs {
        signals: indices
            .into_iter()
            .zip(columns)
            .map(|(input, values)| InputSignal {
                input,
                times: times.clone(),
                values: values.into(),
                interpolation,
            })
            .collect(),
    })
}

pub fn run(args: Args) -> Outcome {
    let model = super::fmu::model(&args.model, args.interface)?;
    let info = model.info();
    let params = parameters(info, &args.set)?;
    check_times(&args)?;
    let options = solver_options(model, &args)?;
    let outputs = chosen_outputs(info, &args.outputs)?;
    let grid = output_times(args.start, args.stop, args.step);
    validate::output_grid(&grid).map_err(|e| Failure::input(format!("--stop/--step: {e}")))?;
    let (profiles, file) = split_inputs(&args.input)?;
    let inputs = Inputs {
        signals: profiles
            .iter()
            .map(|a| profile(info, a, args.stop))
            .collect::<Result<_, _>>()?,
    };
    inputs
        .check(info, 0.0f64.min(args.start), args.stop)
        .map_err(|e| Failure::input(format!("--input: {e}")))?;
    let noise = noise_levels(info, &outputs, &inputs, &args.noise)?;
    let driving = driving_inputs(info, &inputs, file, &args, options.start_time)?;
    let mut trajectory = model
        .simulate(&Run::new(&params, &grid, &outputs, &options).driven(&driving))
        .map_err(|e| Failure::internal(format!("simulation failed: {e}")))?;
    let mut columns: Vec<Vec<f64>> = inputs
        .signals
        .iter()
        .map(|s| grid.iter().map(|&t| s.at(t)).collect())
        .collect();
    // The outputs' noise is drawn first, so a record without inputs keeps its draws.
    add_noise(
        trajectory.values.iter_mut().chain(columns.iter_mut()),
        &noise,
        args.seed,
    )?;
    let header = csv_header(info, &inputs, &outputs);
    let series: Vec<&Vec<f64>> = columns.iter().chain(&trajectory.values).collect();
    write_csv(args.out.as_deref(), &header, &grid, &series)?;
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

/// The `--input` profiles (NAME=T:V,...) and the one input file at most (anything else), in
/// the order given: profiles are written as columns, a file is not.
fn split_inputs(input: &[String]) -> Result<(Vec<&String>, Option<&String>), Failure> {
    // A profile is NAME=T:V,...; anything else names a file.
    let is_profile = |a: &str| {
        a.split_once('=')
            .is_some_and(|(name, points)| !name.contains(['/', '.']) && points.contains(':'))
    };
    let (profiles, files): (Vec<&String>, Vec<&String>) = input.iter().partition(|a| is_profile(a));
    if files.len() > 1 {
        return Err(Failure::input(format!(
            "--input {}: one input file at most (put every input's column in it)",
            files[1]
        )));
    }
    Ok((profiles, files.first().copied()))
}

/// The signals that drive the model: the profiles' `inputs` and those of the input `file`,
/// checked over the simulated span from `start_time`.
fn driving_inputs(
    info: &ModelInfo,
    inputs: &Inputs,
    file: Option<&String>,
    args: &Args,
    start_time: f64,
) -> Result<Inputs, Failure> {
    // The file's signals drive the model beside the profiles; only the profiles are written
    // (the file holds its own columns already).
    let mut driving = inputs.clone();
    if let Some(path) = file {
        let path = PathBuf::from(path.as_str());
        let interpolation = match args.input_interpolation {
            InterpolationArg::Linear => Interpolation::Linear,
            InterpolationArg::Hold => Interpolation::Hold,
        };
        let read = read_inputs(&path, info, interpolation)?;
        read.check(info, start_time, args.stop)
            .map_err(|e| Failure::input(format!("--input {}: {e}", path.display())))?;
        driving.signals.extend(read.signals);
        driving
            .check(info, start_time, args.stop)
            .map_err(|e| Failure::input(format!("--input {}: {e}", path.display())))?;
    }
    Ok(driving)
}

/// The written CSV's column names: time, each profiled input, then each chosen output.
fn csv_header(info: &ModelInfo, inputs: &Inputs, outputs: &[usize]) -> Vec<String> {
    let mut header = vec!["time".to_string()];
    header.extend(
        inputs
            .signals
            .iter()
            .map(|s| info.inputs[s.input].name.clone()),
    );
    header.extend(outputs.iter().map(|&o| info.outputs[o].name.clone()));
    header
}

/// The model's default parameters with each `--set NAME=VALUE` applied, checked.
fn parameters(info: &ModelInfo, sets: &[String]) -> Result<Vec<f64>, Failure> {
    let mut params = info.default_vector();
    for assignment in sets {
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
    Ok(params)
}

/// `--start`, `--stop` and `--step` give a span the limits allow.
fn check_times(args: &Args) -> Outcome {
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
    Ok(())
}

/// The solver options of the command line, checked against the model; an error names the
/// flag.
fn solver_options(model: &dyn Model, args: &Args) -> Result<SolverOptions, Failure> {
    // The CLI's one tolerance sets both: atol a hundredth of rtol.
    let overrides = SolverOverrides {
        rtol: args.rtol,
        atol: args.rtol.map(|rtol| rtol * 1e-2),
        max_steps: None,
        start_time: Some(args.start),
        communication_step: args.cs_step,
    };
    validate::solver_options(model, overrides).map_err(|(option, e)| {
        let (flag, value) = match option {
            "start_time" => ("--start", Some(args.start)),
            "communication_step" => ("--cs-step", args.cs_step),
            _ => ("--rtol", args.rtol),
        };
        Failure::input(format!("{flag} {}: {e}", value.unwrap_or(f64::NAN)))
    })
}

/// The outputs `--outputs` names (every output when it names none).
fn chosen_outputs(info: &ModelInfo, names: &[String]) -> Result<Vec<usize>, Failure> {
    if names.is_empty() {
        return Ok((0..info.outputs.len()).collect());
    }
    names
        .iter()
        .map(|name| {
            validate::output(info, name)
                .map_err(|e| Failure::input(format!("--outputs {name}: {e}")))
        })
        .collect()
}

/// The noise of the written outputs, then of the driven inputs' columns, from each
/// `--noise NAME=SIGMA`.
fn noise_levels(
    info: &ModelInfo,
    outputs: &[usize],
    inputs: &Inputs,
    assignments: &[String],
) -> Result<Vec<f64>, Failure> {
    let mut noise = vec![0.0; outputs.len() + inputs.signals.len()];
    for assignment in assignments {
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
    Ok(noise)
}

/// Add Gaussian noise of standard deviation `noise[k]` to the k-th series, drawn in order
/// from one generator seeded with `seed`.
fn add_noise<'a>(
    series: impl Iterator<Item = &'a mut Vec<f64>>,
    noise: &[f64],
    seed: u64,
) -> Outcome {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    for (series, &sigma) in series.zip(noise) {
        if sigma > 0.0 {
            // Checked where read: every σ is finite and not negative.
            let normal = Normal::new(0.0, sigma)
                .map_err(|e| Failure::internal(format!("noise of σ = {sigma}: {e}")))?;
            for v in series.iter_mut() {
                *v += rng.sample(normal);
            }
        }
    }
    Ok(())
}

/// Write `header` and a row per time of `grid` (the time, then each series) as CSV to
/// `out`, or to standard output.
fn write_csv(
    out: Option<&std::path::Path>,
    header: &[String],
    grid: &[f64],
    series: &[&Vec<f64>],
) -> Outcome {
    let sink: Box<dyn Write> = match out {
        Some(path) => Box::new(
            std::fs::File::create(path)
                .map_err(|e| Failure::internal(format!("cannot write {}: {e}", path.display())))?,
        ),
        None => Box::new(std::io::stdout().lock()),
    };
    let mut csv = csv::Writer::from_writer(std::io::BufWriter::new(sink));
    let write_error = |e: csv::Error| Failure::internal(format!("cannot write CSV: {e}"));
    csv.write_record(header).map_err(write_error)?;
    for (i, t) in grid.iter().enumerate() {
        let mut row = vec![format!("{t}")];
        row.extend(series.iter().map(|v| format!("{}", v[i])));
        csv.write_record(&row).map_err(write_error)?;
    }
    csv.flush()
        .map_err(|e| Failure::internal(format!("cannot write CSV: {e}")))
}

/// The signal of `--input NAME=T:V,T:V,...`: the points, read linearly, extended to cover
/// the simulation from 0 (hosted models) to `stop` by the first and the last value.
fn profile(
    info: &calib_model::ModelInfo,
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
