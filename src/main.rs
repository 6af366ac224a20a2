//! `calib`: calibrate physical models against measured data.

mod commands;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "calib",
    version,
    about = "Calibrate physical simulation models against measured data",
    long_about = "calib fits the parameters of a simulation model (a Furuta pendulum, a heat \
exchanger test bench, ...) to measured data: weighted least squares over a time window, \
bounded parameters, Nelder-Mead, Powell, differential evolution and Levenberg-Marquardt \
(`methods = [\"levenberg-marquardt\"]`, on the weighted residuals) from several start points \
at once. Run `calib models` to see the hosted models and `calib calibrate \
examples/furuta.toml` for a first campaign.",
    propagate_version = true
)]
struct Cli {
    /// Log filter (e.g. `info`, `calib_engine=debug`); also read from RUST_LOG.
    #[arg(long, global = true, value_name = "FILTER")]
    log: Option<String>,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// List the hosted models, or an FMU's: parameters (unit, default, bounds), outputs and
    /// effects.
    Models(commands::models::Args),
    /// Simulate a model and write its outputs over time as CSV.
    Simulate(commands::simulate::Args),
    /// Run a calibration campaign: in this process on all cores, or spread over workers.
    Calibrate(commands::calibrate::Args),
    /// Calibrate, then trace what is left to the physical effect the model lacks: rank the
    /// candidate effects, refit the best, and report the error before and after.
    Diagnose(commands::diagnose::Args),
    /// Global sensitivity of the objective and of each output's contribution to the free
    /// parameters over their bounds: Morris effects and Sobol indices, a table, bar charts
    /// and sensitivity.json, and the parameters that can be held fixed.
    Sensitivity(commands::sensitivity::Args),
    /// Profile likelihoods of the free parameters around the campaign's best point: the
    /// others re-optimised along a grid of each, 95% intervals where the objective rises by
    /// the χ² threshold, profile.json and a plot per parameter, and which are not
    /// identifiable.
    Profile(commands::profile::Args),
    /// Serve the hosted models to coordinators (gRPC Simulator, health, reflection).
    Worker(commands::worker::Args),
    /// Serve the Calibration API (campaigns from `calib submit` and gRPC clients) and the
    /// worker registry, and keep a pool of workers (gRPC).
    Coordinator(commands::coordinator::Args),
    /// Ask a worker or coordinator whether it serves (gRPC health): exit 0 when it does, 1
    /// otherwise; for container healthchecks and scripts.
    Health(commands::health::Args),
    /// Measure simulation and calibration speed and print the figures.
    Bench(commands::bench::Args),
    /// Inspect, export or import an evaluation store (`calib calibrate --db`).
    Store(commands::store::Args),
    /// Run a campaign on a coordinator: upload its data, submit it, follow it (through a
    /// restart of the coordinator: it reconnects for up to 5 minutes), and write result.json
    /// and the plots as `calib calibrate` does.
    Submit(commands::submit::SubmitArgs),
    /// The state of one campaign of a coordinator, or of all of them.
    Status(commands::submit::StatusArgs),
    /// Follow a campaign on a coordinator until it ends, reconnecting for up to 5 minutes
    /// when the coordinator goes away.
    Watch(commands::submit::IdArgs),
    /// Stop a campaign on a coordinator.
    Cancel(commands::submit::IdArgs),
    /// The web app: Model, Measurement, Calibration and Diagnosis tabs in a browser, with
    /// campaigns running in this process.
    Ui(commands::ui::Args),
    /// Run the instances of one FMU for a parent process (internal).
    #[command(hide = true)]
    FmuHost(commands::fmu::HostArgs),
}

impl Command {
    /// Whether the command serves others for as long as it runs.
    fn is_server(&self) -> bool {
        matches!(
            self,
            Command::Worker(_) | Command::Coordinator(_) | Command::Ui(_)
        )
    }
}

/// SIGPIPE stays ignored (Rust's default) in every command: a write to a socket (TLS
/// writes with `writev`, which raises it) or to a child's pipe whose reader is gone
/// then fails with EPIPE, which the write's caller handles, instead of killing the
/// process without a word: a coordinator whose worker went away mid-write, a client
/// whose coordinator restarted, a parent whose FMU host crashed. A command that is not
/// a server still dies quietly when the reader of its standard output goes away
/// (`calib models | head`), as command-line tools do, by SIGPIPE as before: a print
/// that fails with EPIPE ends the process instead of panicking.
#[cfg(unix)]
fn die_quietly_when_stdout_closes() {
    let default = std::panic::take_hook();
    std::panic::set_hook(Box::new(move |info| {
        let message = info
            .payload()
            .downcast_ref::<String>()
            .map(String::as_str)
            .or_else(|| info.payload().downcast_ref::<&str>().copied())
            .unwrap_or_default();
        // `print!` panics with "failed printing to stdout: <the io::Error>".
        let broken_pipe = format!("(os error {})", libc::EPIPE);
        if message.starts_with("failed printing to stdout") && message.ends_with(&broken_pipe) {
            // SAFETY: restores SIGPIPE's default disposition and raises it, ending the
            // process as an unhandled SIGPIPE would have.
            unsafe {
                libc::signal(libc::SIGPIPE, libc::SIG_DFL);
                libc::raise(libc::SIGPIPE);
            }
        }
        default(info);
    }));
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    #[cfg(unix)]
    if !cli.command.is_server() {
        die_quietly_when_stdout_closes();
    }
    let filter = cli
        .log
        .clone()
        .or_else(|| std::env::var("RUST_LOG").ok())
        .unwrap_or_else(|| "warn".into());
    // The store (sled) logs at trace level from closures its epoch collector may run while
    // a thread is being torn down, when the log writer's thread-local buffer is gone: such a
    // line panicked the process at exit under `--log trace`. Its traces stay off unless
    // asked for by name.
    let filter = if filter.contains("sled") {
        filter
    } else {
        format!("{filter},sled=info")
    };
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_new(&filter)
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("warn")),
        )
        .with_writer(std::io::stderr)
        // Colour for a person at a terminal, plain text for log collectors (docker logs,
        // journald, files).
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .init();
    // FMU instances run in child processes of this binary, never in this one.
    if !matches!(cli.command, Command::FmuHost(_)) {
        commands::fmu::isolate();
    }
    let outcome = match cli.command {
        Command::Models(args) => commands::models::run(args),
        Command::Simulate(args) => commands::simulate::run(args),
        Command::Calibrate(args) => commands::calibrate::run(args),
        Command::Diagnose(args) => commands::diagnose::run(args),
        Command::Sensitivity(args) => commands::sensitivity::run(args),
        Command::Profile(args) => commands::profile::run(args),
        Command::Worker(args) => commands::worker::run(args),
        Command::Coordinator(args) => commands::coordinator::run(args),
        Command::Health(args) => commands::health::run(args),
        Command::Bench(args) => commands::bench::run(args),
        Command::Store(args) => commands::store::run(args),
        Command::Submit(args) => commands::submit::submit(args),
        Command::Status(args) => commands::submit::status(args),
        Command::Watch(args) => commands::submit::watch(args),
        Command::Cancel(args) => commands::submit::cancel(args),
        Command::Ui(args) => commands::ui::run(args),
        Command::FmuHost(args) => commands::fmu::host(args),
    };
    match outcome {
        Ok(()) => ExitCode::SUCCESS,
        Err(failure) => {
            eprintln!("error: {}", failure.message);
            ExitCode::from(failure.code)
        }
    }
}
