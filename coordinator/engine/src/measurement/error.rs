//! What can go wrong while loading a measurement.
//!
//! Every message names the file and, where it applies, the line (CSV) or the sample
//! and variable (MAT), so that a user can find and fix the offending data without a
//! debugger.

use std::fmt;
use std::path::{Path, PathBuf};

/// Where a value sits in its file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a text file, counting every line (the header is line 1 unless
    /// comments precede it).
    Line(usize),
    /// 1-based index of a sample within a MAT variable.
    Sample(usize),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(line) => write!(f, "line {line}"),
            Location::Sample(sample) => write!(f, "sample {sample}"),
        }
    }
}

/// What the MAT readers understand, quoted in every "unsupported" message.
pub const SUPPORTED_MAT_CONTENT: &str = "MAT v4 real full matrices (double, single, int32, \
int16, uint16, uint8; little- or big-endian), including Modelica result files \
(Aclass/name/dataInfo/data_1/data_2, binNormal or binTrans), and MAT v5 real numeric arrays \
(compressed or not)";

/// Error raised by [`Measurement::load`](super::Measurement::load).
#[derive(Debug, thiserror::Error)]
pub enum MeasurementError {
    #[error("measurement file {} does not exist", .path.display())]
    NotFound { path: PathBuf },

    #[error("cannot read measurement file {}: {source}", .path.display())]
    Unreadable {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },

    #[error(
        "{}: unrecognised format: expected CSV text (.csv, .txt) or a MAT file (.mat, v4 or v5)",
        .path.display()
    )]
    UnrecognizedFormat { path: PathBuf },

    #[error(
        "{}: no header row: the first line that is neither blank nor a `#` comment must name the columns",
        .path.display()
    )]
    MissingHeader { path: PathBuf },

    #[error(
        "{} line {line}: the header has no column \"{column}\"; its columns are: {}",
        .path.display(), name_list(.available)
    )]
    MissingColumn {
        path: PathBuf,
        /// Line of the header.
        line: usize,
        column: String,
        available: Vec<String>,
    },

    #[error(
        "{} line {line}: the header names column \"{column}\" {count} times; rename the duplicates",
        .path.display()
    )]
    DuplicateColumn {
        path: PathBuf,
        line: usize,
        column: String,
        count: usize,
    },

    #[error(
        "{}: no variable \"{variable}\"; the file's variables are: {}",
        .path.display(), name_list(.available)
    )]
    MissingVariable {
        path: PathBuf,
        variable: String,
        available: Vec<String>,
    },

    #[error("{} line {line}, column \"{column}\": {}", .path.display(), describe_cell(.text))]
    NonNumeric {
        path: PathBuf,
        line: usize,
        column: String,
        /// The cell as written, surrounding whitespace removed.
        text: String,
    },

    #[error(
        "{} {location}, column \"{column}\": value {value} is not finite (NaN and infinities are not allowed)",
        .path.display()
    )]
    NonFinite {
        path: PathBuf,
        location: Location,
        column: String,
        value: f64,
    },

    #[error(
        "{} {location}: time (\"{column}\") must strictly increase, but {value} follows {previous} at {previous_location}",
        .path.display()
    )]
    TimeNotIncreasing {
        path: PathBuf,
        column: String,
        previous_location: Location,
        previous: f64,
        location: Location,
        value: f64,
    },

    #[error("{}: no data rows after the header on line {header_line}", .path.display())]
    NoRows { path: PathBuf, header_line: usize },

    #[error("{}: variable \"{variable}\" has no samples", .path.display())]
    EmptyVariable { path: PathBuf, variable: String },

    #[error(
        "{} line {line}: the row has {found} {} but the header has {expected} columns",
        .path.display(), if *.found == 1 { "cell" } else { "cells" }
    )]
    RaggedRow {
        path: PathBuf,
        line: usize,
        expected: usize,
        found: usize,
    },

    #[error(
        "{}: variable \"{variable}\" has {found} samples but the time variable \"{time_variable}\" has {expected}",
        .path.display()
    )]
    LengthMismatch {
        path: PathBuf,
        variable: String,
        found: usize,
        time_variable: String,
        expected: usize,
    },

    #[error(
        "{}: variable \"{variable}\" is a {} array; expected a vector (n×1 or 1×n)",
        .path.display(), shape_text(.shape)
    )]
    NotAVector {
        path: PathBuf,
        variable: String,
        shape: Vec<usize>,
    },

    #[error("{}: MAT file is truncated: {detail}", .path.display())]
    MatTruncated { path: PathBuf, detail: String },

    /// Past one of the bounds of [`super::limits`].
    #[error("{}: MAT file is too large: {detail}", .path.display())]
    MatTooLarge { path: PathBuf, detail: String },

    #[error("{}: {detail}; supported are {SUPPORTED_MAT_CONTENT}", .path.display())]
    UnsupportedMat { path: PathBuf, detail: String },

    #[error("{}: not a valid MAT file: {detail}", .path.display())]
    MalformedMat { path: PathBuf, detail: String },

    #[error("{} line {line}: cannot parse CSV: {detail}", .path.display())]
    MalformedCsv {
        path: PathBuf,
        line: usize,
        detail: String,
    },
}

impl MeasurementError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            MeasurementError::NotFound { path }
            | MeasurementError::Unreadable { path, .. }
            | MeasurementError::UnrecognizedFormat { path }
            | MeasurementError::MissingHeader { path }
            | MeasurementError::MissingColumn { path, .. }
            | MeasurementError::DuplicateColumn { path, .. }
            | MeasurementError::MissingVariable { path, .. }
            | MeasurementError::NonNumeric { path, .. }
            | MeasurementError::NonFinite { path, .. }
            | MeasurementError::TimeNotIncreasing { path, .. }
            | MeasurementError::NoRows { path, .. }
            | MeasurementError::EmptyVariable { path, .. }
            | MeasurementError::RaggedRow { path, .. }
            | MeasurementError::LengthMismatch { path, .. }
            | MeasurementError::NotAVector { path, .. }
            | MeasurementError::MatTruncated { path, .. }
            | MeasurementError::MatTooLarge { path, .. }
            | MeasurementError::UnsupportedMat { path, .. }
            | MeasurementError::MalformedMat { path, .. }
            | MeasurementError::MalformedCsv { path, .. } => path,
        }
    }
}

/// Names listed in "missing column/variable" messages; result files can hold thousands,
/// so the list is cut after a screenful.
const LISTED_NAMES: usize = 40;

fn name_list(names: &[String]) -> String {
    if names.is_empty() {
        return "(none)".to_owned();
    }
    let quoted: Vec<String> = names
        .iter()
        .take(LISTED_NAMES)
        .map(|name| format!("\"{name}\""))
        .collect();
    let mut list = quoted.join(", ");
    if names.len() > LISTED_NAMES {
        list.push_str(&format!(" and {} more", names.len() - LISTED_NAMES));
    }
    list
}

fn describe_cell(text: &str) -> String {
    if text.is_empty() {
        return "the cell is empty; expected a number".to_owned();
    }
    let with_decimal_point = text.replace(',', ".");
    if text.contains(',') && with_decimal_point.parse::<f64>().is_ok() {
        return format!(
            "\"{text}\" is not a number (decimal commas are not supported; write \"{with_decimal_point}\")"
        );
    }
    format!("\"{text}\" is not a number")
}

fn shape_text(shape: &[usize]) -> String {
    let dimensions: Vec<String> = shape.iter().map(usize::to_string).collect();
    dimensions.join("×")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn long_name_lists_are_cut() {
        let names: Vec<String> = (0..45).map(|i| format!("v{i}")).collect();
        let list = name_list(&names);
        assert!(list.starts_with("\"v0\", \"v1\""));
        assert!(list.ends_with("\"v39\" and 5 more"), "{list}");
        assert_eq!(name_list(&[]), "(none)");
    }

    #[test]
    fn cell_descriptions_help_fix_the_data() {
        assert_eq!(
            describe_cell(""),
            "the cell is empty; expected a number".to_owned()
        );
        assert_eq!(describe_cell("abc"), "\"abc\" is not a number");
        assert!(describe_cell("0,25").contains("write \"0.25\""));
    }

    #[test]
    fn shapes_read_like_matlab() {
        assert_eq!(shape_text(&[3, 4, 2]), "3×4×2");
    }
}
