//! calib's calibration engine: a campaign file checked against its model, the measured
//! record, the objective over it, the evaluators that run it (in this process or, through a
//! dispatcher of the service, on workers), the optimisers that search it, the evaluation
//! store that remembers every point, and one calibration from start to end with its typed
//! outcome. No async runtime and no network: the service crate brings those.

pub mod calibration;
pub mod campaign;
pub mod error;
pub mod evaluator;
pub mod evidence;
pub mod limits;
pub mod measurement;
pub mod objective;
pub mod optim;
pub mod outcome;
pub mod store;

pub use error::{Error, Result};
