//! calib's analyses of a calibration, over the engine: what it leaves behind (`result.json`,
//! the table, the charts every report draws with), the residuals' statistics and Jacobian,
//! profile likelihoods, the diagnosis of a missing physical effect, global sensitivity.

pub mod diagnosis;
pub mod profile;
pub mod report;
pub mod residuals;
pub mod sensitivity;
