//! Models that are commands: a program the campaign runs with its parameters written into
//! input files and its outputs read back, in the formats PEST and PEST++ use for any
//! simulator (EnergyPlus, MODFLOW, a Python script): template files say where each
//! parameter's value goes ([`template`]), instruction files where each observation is read
//! ([`instructions`]), and a control file (`.pst`) names them with the parameters, the
//! observations and the command ([`control`]).

pub mod control;
pub mod instructions;
pub mod run;
pub mod template;

pub use control::ControlFile;
pub use instructions::{Instructions, PestFileError};
pub use run::{CommandModel, RunFailure, RunFolder};
pub use template::Template;

#[cfg(test)]
mod tests;

#[cfg(test)]
#[path = "run_tests.rs"]
mod run_tests;
