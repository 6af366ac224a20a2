//! MAT measurements: MAT v4 (plain variables or Modelica result files) and MAT v5.
//!
//! The version is told apart by the header: a MAT v5 (and v7.3) file starts with 116
//! bytes of text and carries `IM` or `MI` at offset 126, while a MAT v4 file starts
//! directly with a matrix header whose type field always holds zero bytes.
//!
//! * [`v4`]: plain matrices, little- or big-endian, any of the six v4 precisions.
//! * [`result_file`]: MAT v4 files laid out as Modelica/Dymola simulation results;
//!   recognised by their `Aclass` matrix.
//! * [`v5`]: numeric arrays, read with the `matfile` crate (compressed or not).
//! * MAT v7.3 is HDF5 and is rejected with a hint to save in an older version.
//!
//! Whatever the version, a variable must be a vector (n×1 or 1×n) of real numbers;
//! samples are numbered from 1 in error messages.

mod result_file;
mod v4;
mod v5;

use std::path::Path;

use super::{check_finite, check_time_step, Location, Measurement, MeasurementError, TimeOrder};
use crate::limits::MAX_MAT_VALUES;

/// Whether `bytes` start like a MAT file of a version this module knows.
pub(super) fn looks_like_mat(bytes: &[u8]) -> bool {
    v5::header_version(bytes).is_some() || v4::looks_like_v4(bytes)
}

/// Reads a MAT measurement from the bytes of `path`.
pub(super) fn read(
    path: &Path,
    bytes: &[u8],
    time_column: &str,
    columns: &[&str],
) -> Result<Measurement, MeasurementError> {
    if v5::header_version(bytes).is_some() {
        let file = v5::V5File::parse(path, bytes)?;
        return assemble(path, &file, time_column, columns, TimeOrder::Strict);
    }
    let matrices = v4::parse(path, bytes)?;
    if result_file::is_result_file(&matrices) {
        let file = result_file::ResultFile::open(path, &matrices)?;
        assemble(
            path,
            &file,
            time_column,
            columns,
            TimeOrder::RepeatsAtEvents,
        )
    } else {
        let file = v4::PlainVariables::new(&matrices);
        assemble(path, &file, time_column, columns, TimeOrder::Strict)
    }
}

/// Refuses a variable of more than [`MAX_MAT_VALUES`] values, before they are converted.
fn check_value_count(
    path: &Path,
    name: &str,
    shape: &[usize],
    count: usize,
) -> Result<(), MeasurementError> {
    if count <= MAX_MAT_VALUES {
        return Ok(());
    }
    Err(MeasurementError::MatTooLarge {
        path: path.to_owned(),
        detail: format!(
            "variable \"{name}\" has dimensions {shape:?}, {count} values, more than the \
             {MAX_MAT_VALUES} (MAX_MAT_VALUES) a variable may hold"
        ),
    })
}

/// A variable's values as stored.
#[derive(Debug, Clone, PartialEq)]
enum Samples {
    /// One value per sample.
    Series(Vec<f64>),
    /// A parameter: one value for the whole record.
    Constant(f64),
}

/// The named variables of one MAT file.
trait Variables {
    /// The values of the variable `name`, or why they cannot be had.
    fn samples(&self, path: &Path, name: &str) -> Result<Samples, MeasurementError>;
}

/// Looks up the time and the requested variables, expands constants to the time grid,
/// checks every sample and, for simulation results, collapses repeated event times.
fn assemble(
    path: &Path,
    file: &dyn Variables,
    time_column: &str,
    columns: &[&str],
    order: TimeOrder,
) -> Result<Measurement, MeasurementError> {
    let time = match file.samples(path, time_column)? {
        Samples::Series(values) => values,
        Samples::Constant(_) => {
            return Err(MeasurementError::UnsupportedMat {
                path: path.to_owned(),
                detail: format!(
                    "time variable \"{time_column}\" is a parameter (a constant) and cannot be a time axis"
                ),
            })
        }
    };
    if time.is_empty() {
        return Err(MeasurementError::EmptyVariable {
            path: path.to_owned(),
            variable: time_column.to_owned(),
        });
    }
    let mut loaded = Vec::with_capacity(columns.len());
    for &name in columns {
        let values = match file.samples(path, name)? {
            Samples::Constant(value) => vec![value; time.len()],
            Samples::Series(values) if values.is_empty() => {
                return Err(MeasurementError::EmptyVariable {
                    path: path.to_owned(),
                    variable: name.to_owned(),
                })
            }
            Samples::Series(values) if values.len() != time.len() => {
                return Err(MeasurementError::LengthMismatch {
                    path: path.to_owned(),
                    variable: name.to_owned(),
                    found: values.len(),
                    time_variable: time_column.to_owned(),
                    expected: time.len(),
                })
            }
            Samples::Series(values) => values,
        };
        loaded.push((name.to_owned(), values));
    }

    let mut previous = None;
    for (index, &sample_time) in time.iter().enumerate() {
        let location = Location::Sample(index + 1);
        check_finite(path, location, time_column, sample_time)?;
        check_time_step(path, time_column, previous, location, sample_time, order)?;
        previous = Some((location, sample_time));
        for (name, values) in &loaded {
            check_finite(path, location, name, values[index])?;
        }
    }

    let (time, columns) = match order {
        TimeOrder::Strict => (time, loaded),
        TimeOrder::RepeatsAtEvents => keep_last_at_each_time(time, loaded),
    };
    Ok(Measurement {
        source: path.to_owned(),
        time,
        columns,
    })
}

/// Drops every sample whose time the next sample repeats: at an event a simulation
/// stores the state before and after it, and the measurement keeps the one after.
fn keep_last_at_each_time(
    time: Vec<f64>,
    columns: Vec<(String, Vec<f64>)>,
) -> (Vec<f64>, Vec<(String, Vec<f64>)>) {
    let kept: Vec<bool> = (0..time.len())
        .map(|index| time.get(index + 1) != time.get(index))
        .collect();
    let filter = |values: Vec<f64>| -> Vec<f64> {
        values
            .into_iter()
            .zip(&kept)
            .filter_map(|(value, &keep)| keep.then_some(value))
            .collect()
    };
    let columns = columns
        .into_iter()
        .map(|(name, values)| (name, filter(values)))
        .collect();
    (filter(time), columns)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;
    use std::path::PathBuf;

    /// Variables held in memory, to test the assembly alone.
    struct InMemory(HashMap<&'static str, Samples>);

    impl Variables for InMemory {
        fn samples(&self, path: &Path, name: &str) -> Result<Samples, MeasurementError> {
            self.0
                .get(name)
                .cloned()
                .ok_or_else(|| MeasurementError::MissingVariable {
                    path: path.to_owned(),
                    variable: name.to_owned(),
                    available: Vec::new(),
                })
        }
    }

    fn file(variables: Vec<(&'static str, Samples)>) -> InMemory {
        InMemory(variables.into_iter().collect())
    }

    fn path() -> PathBuf {
        PathBuf::from("run.mat")
    }

    #[test]
    fn constants_expand_to_the_time_grid() {
        let variables = file(vec![
            ("t", Samples::Series(vec![0.0, 1.0, 2.0])),
            ("k", Samples::Constant(4.0)),
        ]);
        let loaded = assemble(&path(), &variables, "t", &["k"], TimeOrder::Strict).expect("valid");
        assert_eq!(loaded.column("k"), Some(&[4.0, 4.0, 4.0][..]));
    }

    #[test]
    fn constant_time_is_rejected() {
        let variables = file(vec![("t", Samples::Constant(0.0))]);
        let error = assemble(&path(), &variables, "t", &[], TimeOrder::Strict).expect_err("const");
        assert!(
            error.to_string().contains("\"t\" is a parameter"),
            "{error}"
        );
    }

    #[test]
    fn lengths_must_agree() {
        let variables = file(vec![
            ("t", Samples::Series(vec![0.0, 1.0, 2.0])),
            ("x", Samples::Series(vec![0.0, 1.0])),
            ("e", Samples::Series(vec![])),
        ]);
        let error = assemble(&path(), &variables, "t", &["x"], TimeOrder::Strict).expect_err("len");
        assert_eq!(
            error.to_string(),
            "run.mat: variable \"x\" has 2 samples but the time variable \"t\" has 3"
        );
        let error =
            assemble(&path(), &variables, "t", &["e"], TimeOrder::Strict).expect_err("empty");
        assert_eq!(error.to_string(), "run.mat: variable \"e\" has no samples");
        let error =
            assemble(&path(), &variables, "e", &["x"], TimeOrder::Strict).expect_err("empty");
        assert!(
            matches!(error, MeasurementError::EmptyVariable { .. }),
            "{error}"
        );
    }

    #[test]
    fn samples_are_checked_in_order() {
        let variables = file(vec![
            ("t", Samples::Series(vec![0.0, 1.0, 1.0, 0.5])),
            ("x", Samples::Series(vec![0.0, 1.0, 2.0, f64::NAN])),
            ("y", Samples::Series(vec![0.0, f64::INFINITY, 2.0, 3.0])),
        ]);
        let error = assemble(&path(), &variables, "t", &["x"], TimeOrder::Strict).expect_err("t");
        assert_eq!(
            error.to_string(),
            "run.mat sample 3: time (\"t\") must strictly increase, but 1 follows 1 at sample 2"
        );
        let error = assemble(&path(), &variables, "t", &["y"], TimeOrder::Strict).expect_err("y");
        assert_eq!(
            error.to_string(),
            "run.mat sample 2, column \"y\": value inf is not finite (NaN and infinities are not allowed)"
        );
        let error =
            assemble(&path(), &variables, "t", &["x"], TimeOrder::RepeatsAtEvents).expect_err("t");
        assert!(
            matches!(
                error,
                MeasurementError::TimeNotIncreasing {
                    location: Location::Sample(4),
                    ..
                }
            ),
            "{error}"
        );
    }

    #[test]
    fn repeated_event_times_keep_the_last_sample() {
        let variables = file(vec![
            ("t", Samples::Series(vec![0.0, 1.0, 1.0, 1.0, 2.0, 2.0])),
            ("x", Samples::Series(vec![0.0, 1.0, 5.0, 6.0, 7.0, 8.0])),
        ]);
        let loaded =
            assemble(&path(), &variables, "t", &["x"], TimeOrder::RepeatsAtEvents).expect("events");
        assert_eq!(loaded.time, vec![0.0, 1.0, 2.0]);
        assert_eq!(loaded.column("x"), Some(&[0.0, 6.0, 8.0][..]));
    }
}
