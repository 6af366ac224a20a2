//! What a calibration leaves behind, rendered from its outcome and its data: `result.json`
//! (the [`CalibrationOutcome`](calib_engine::outcome::CalibrationOutcome) serialized), a table
//! for the terminal, SVG plots.

pub mod chart;
pub use calib_engine::evidence;
pub mod plot;
pub mod runs;
pub mod table;
pub mod ticks;

use calib_engine::calibration::Calibration;
use calib_engine::error::{Error, Result};
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The machine-readable result of a calibration (`result.json`), as a JSON value: its
/// outcome serialized.
pub fn result_json(c: &Calibration) -> Value {
    serde_json::to_value(&c.outcome).expect("an outcome is plain data")
}

/// Write `result.json` and one plot per output into `dir`; the paths written.
pub fn write(c: &Calibration, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).map_err(|source| Error::Write {
        path: dir.to_path_buf(),
        source,
    })?;
    let mut written = Vec::new();
    let path = dir.join("result.json");
    let text = c.outcome.to_json_text();
    std::fs::write(&path, text + "\n").map_err(|source| Error::Write {
        path: path.clone(),
        source,
    })?;
    written.push(path);
    written.extend(plot::write_fit_plots(c, dir)?);
    written.push(plot::write_waterfall(c, dir)?);
    Ok(written)
}
