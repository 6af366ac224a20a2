//! One validation of what a simulation is asked for: the model, the names and values of its
//! parameters, its outputs, the solver options and the output grid.
//!
//! A campaign file (coordinator), `calib simulate` and a worker's gRPC request all check
//! through these functions, against one set of [`crate::limits`]. Each function returns an
//! [`Invalid`] whose message says what is wrong with the value; the caller places it (a file
//! and line, a command-line option, a request field). Unknown names get a "did you mean"
//! suggestion rather than a list of every name.

mod grid;
mod names;
mod solver;
mod values;

pub use grid::{output_grid, stop_time};
pub(crate) use names::hint;
pub use names::{effect, input, model, output, parameter};
pub use solver::{
    atol, communication_step, max_steps, rtol, solver_options, start_time, SolverOverrides,
};
pub use values::{bounds, parameter_value};

/// A value or name refused, with the reason.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("{message}")]
pub struct Invalid {
    /// The element of a list the message is about (a time of a grid), if any.
    pub index: Option<usize>,
    pub message: String,
}

impl Invalid {
    pub fn new(message: impl Into<String>) -> Self {
        Self {
            index: None,
            message: message.into(),
        }
    }

    fn at(index: usize, message: impl Into<String>) -> Self {
        Self {
            index: Some(index),
            message: message.into(),
        }
    }
}

pub type Result<T, E = Invalid> = std::result::Result<T, E>;
