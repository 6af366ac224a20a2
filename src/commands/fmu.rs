//! What the commands share about FMUs: choosing the interface, opening one named on the
//! command line, and the hidden `fmu-host` subcommand that runs FMU instances in a child
//! process.

use super::{Failure, Outcome};
use calib_model::fmu::{self, Interface};
use calib_model::Model;
use std::path::{Path, PathBuf};

/// How an FMU is run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum InterfaceArg {
    /// calib integrates the FMU's equations (Dormand–Prince, events).
    ModelExchange,
    /// The FMU integrates itself; calib steps it from one output time to the next.
    CoSimulation,
}

impl From<InterfaceArg> for Interface {
    fn from(arg: InterfaceArg) -> Self {
        match arg {
            InterfaceArg::ModelExchange => Interface::ModelExchange,
            InterfaceArg::CoSimulation => Interface::CoSimulation,
        }
    }
}

/// A hosted model by name, or the FMU at a path ending in `.fmu`.
pub fn model(name: &str, interface: Option<InterfaceArg>) -> Result<&'static dyn Model, Failure> {
    if fmu::is_fmu_path(name) {
        return fmu::open(Path::new(name), interface.map(Into::into))
            .map_err(|e| Failure::input(format!("{name}: {e}")));
    }
    if interface.is_some() {
        return Err(Failure::input(format!(
            "--interface: `{name}` is a hosted model, not an FMU"
        )));
    }
    calib_model::validate::model(name).map_err(|e| Failure::input(e.message))
}

/// Run FMU instances of later simulations in child processes of this binary.
pub fn isolate() {
    if let Ok(program) = std::env::current_exe() {
        fmu::isolate_with(fmu::HostCommand {
            program,
            args: vec!["fmu-host".into()],
        });
    }
}

#[derive(clap::Args)]
pub struct HostArgs {
    /// The unpacked FMU.
    dir: PathBuf,
    /// `me` or `cs`.
    interface: String,
}

/// The child's side: serve simulations of one FMU on stdin/stdout.
pub fn host(args: HostArgs) -> Outcome {
    let interface = fmu::host::parse_interface(&args.interface)
        .ok_or_else(|| Failure::input(format!("unknown interface `{}`", args.interface)))?;
    fmu::host::serve(&args.dir, interface).map_err(|e| Failure::internal(e.to_string()))
}
