//! Models that are commands: a program the campaign runs with its parameters written into
//! input files and its outputs read back, in the formats PEST and PEST++ use for any
//! simulator (EnergyPlus, MODFLOW, a Python script): template files say where each
//! parameter's value goes ([`template`]), instruction files where each observation is read
//! ([`instructions`]).

pub mod instructions;
pub mod template;

pub use instructions::{InstructionError, Instructions};
pub use template::Template;

#[cfg(test)]
mod tests;
