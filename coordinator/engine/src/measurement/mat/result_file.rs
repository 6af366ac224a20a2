//! Modelica simulation results (the Dymola "Atrajectory 1.1" layout, also written by
//! OpenModelica and others) stored as MAT v4.
//!
//! The file holds these matrices:
//!
//! * `Aclass`: text, four rows: `Atrajectory`, `1.1`, (empty), then `binNormal` or
//!   `binTrans`. With `binTrans` every other matrix is stored transposed.
//! * `name`: text, one variable name per row (per column with `binTrans`).
//! * `description`: ignored.
//! * `dataInfo`: one row per variable, `[matrix, column, interpolation, extrapolation]`.
//!   `matrix` is 1 for `data_1`, 2 for `data_2`, 0 for the abscissa (time, the first
//!   column of `data_2`); `column` is 1-based, and negative for an alias stored negated.
//! * `data_1`: parameters, one row at the first and one at the last time; a parameter
//!   is expanded to a constant series over the time grid.
//! * `data_2`: the time-varying variables, one row per output time.
//!
//! At events a simulation stores two rows with the same time (before and after the
//! event); the measurement keeps the later one.

use std::path::Path;

use super::v4::Matrix;
use super::{Samples, Variables};
use crate::measurement::MeasurementError;

/// Whether the matrices are laid out as a Modelica result file.
pub(super) fn is_result_file(matrices: &[Matrix]) -> bool {
    matrices.iter().any(|matrix| matrix.name == "Aclass")
}

/// A matrix read in its logical orientation (rows = variables or time points).
#[derive(Clone, Copy)]
struct Table<'m, 'a> {
    matrix: &'m Matrix<'a>,
    transposed: bool,
}

impl Table<'_, '_> {
    fn rows(&self) -> usize {
        if self.transposed {
            self.matrix.cols
        } else {
            self.matrix.rows
        }
    }

    fn cols(&self) -> usize {
        if self.transposed {
            self.matrix.rows
        } else {
            self.matrix.cols
        }
    }

    /// The value at logical (`row`, `col`), or `None` outside the table.
    fn get(&self, row: usize, col: usize) -> Option<f64> {
        if row >= self.rows() || col >= self.cols() {
            return None;
        }
        let index = if self.transposed {
            col + self.matrix.rows * row
        } else {
            row + self.matrix.rows * col
        };
        self.matrix.value(index)
    }

    /// Row `row` read as text, trailing NULs and blanks removed.
    fn text_row(&self, row: usize) -> String {
        let text: String = (0..self.cols())
            .filter_map(|col| self.get(row, col))
            .map(|code| {
                u32::try_from(code as i64)
                    .ok()
                    .and_then(char::from_u32)
                    .unwrap_or(char::REPLACEMENT_CHARACTER)
            })
            .collect();
        text.trim_end_matches(|c: char| c == '\0' || c.is_whitespace())
            .to_owned()
    }
}

/// An opened result file: variable names resolved, values still encoded.
pub(super) struct ResultFile<'m, 'a> {
    names: Vec<String>,
    data_info: Table<'m, 'a>,
    data_1: Option<Table<'m, 'a>>,
    data_2: Table<'m, 'a>,
}

impl<'m, 'a> ResultFile<'m, 'a> {
    pub fn open(path: &Path, matrices: &'m [Matrix<'a>]) -> Result<Self, MeasurementError> {
        let malformed = |detail: String| MeasurementError::MalformedMat {
            path: path.to_owned(),
            detail,
        };
        let find = |name: &str| matrices.iter().find(|matrix| matrix.name == name);
        let require = |name: &str| {
            find(name).ok_or_else(|| {
                malformed(format!(
                    "the result file (it has an Aclass matrix) lacks the \"{name}\" matrix"
                ))
            })
        };

        let transposed = aclass_layout(
            path,
            Table {
                matrix: require("Aclass")?,
                transposed: false,
            },
        )?;
        let table = |matrix| Table { matrix, transposed };

        let name_table = table(require("name")?);
        let data_info = table(require("dataInfo")?);
        // Checked before the names are built: an empty `name` matrix may claim any
        // number of rows, while dataInfo's rows of two or more values must all be in
        // the file, so agreeing with it bounds the names by the file's size.
        if data_info.rows() != name_table.rows() || data_info.cols() < 2 {
            return Err(malformed(format!(
                "dataInfo is {} but \"name\" lists {} variables (expected {} rows of at least 2 columns)",
                data_info.matrix.describe(),
                name_table.rows(),
                name_table.rows()
            )));
        }
        let names: Vec<String> = (0..name_table.rows())
            .map(|row| name_table.text_row(row))
            .collect();
        let data_2 = table(require("data_2")?);
        let data_1 = find("data_1").map(table);
        reject_complex(path, &data_2, data_1.as_ref())?;
        Ok(ResultFile {
            names,
            data_info,
            data_1,
            data_2,
        })
    }

    /// The integer in `dataInfo` at (`row`, `col`).
    fn info(&self, path: &Path, row: usize, col: usize) -> Result<i64, MeasurementError> {
        match self.data_info.get(row, col) {
            Some(value) if value.fract() == 0.0 && value.abs() < 1e15 => Ok(value as i64),
            other => Err(MeasurementError::MalformedMat {
                path: path.to_owned(),
                detail: format!(
                    "dataInfo row {} (variable \"{}\") has {} in column {}, expected an integer",
                    row + 1,
                    self.names.get(row).map_or("", String::as_str),
                    other.map_or_else(|| "nothing".to_owned(), |v| v.to_string()),
                    col + 1
                ),
            }),
        }
    }
}

/// An unsupported-file error saying `detail`.
fn unsupported(path: &Path, detail: String) -> MeasurementError {
    MeasurementError::UnsupportedMat {
        path: path.to_owned(),
        detail,
    }
}

/// Checks that `aclass` names an `Atrajectory` result file of version 1.1, and returns
/// whether its layout stores the other matrices transposed (`binTrans`).
fn aclass_layout(path: &Path, aclass: Table<'_, '_>) -> Result<bool, MeasurementError> {
    let class_row = |row: usize| {
        if row < aclass.rows() {
            aclass.text_row(row)
        } else {
            String::new()
        }
    };
    let (class, version, layout) = (class_row(0), class_row(1), class_row(3));
    if class != "Atrajectory" {
        return Err(unsupported(
            path,
            format!(
                "Aclass names the class \"{class}\"; only \"Atrajectory\" result files can be read"
            ),
        ));
    }
    if version != "1.1" {
        return Err(unsupported(
            path,
            format!("Aclass names result file version \"{version}\"; only version 1.1 can be read"),
        ));
    }
    let transposed = match layout.as_str() {
        "binTrans" => true,
        "binNormal" | "" => false,
        other => {
            return Err(unsupported(
                path,
                format!(
                    "Aclass names the layout \"{other}\"; only binNormal and binTrans can be read"
                ),
            ))
        }
    };
    Ok(transposed)
}

/// Refuses complex data matrices: only real values can be read as variables.
fn reject_complex(
    path: &Path,
    data_2: &Table<'_, '_>,
    data_1: Option<&Table<'_, '_>>,
) -> Result<(), MeasurementError> {
    for data in std::iter::once(data_2).chain(data_1) {
        if data.matrix.complex {
            return Err(unsupported(
                path,
                format!(
                    "\"{}\" is a {} matrix",
                    data.matrix.name,
                    data.matrix.describe()
                ),
            ));
        }
    }
    Ok(())
}

impl Variables for ResultFile<'_, '_> {
    fn samples(&self, path: &Path, name: &str) -> Result<Samples, MeasurementError> {
        let Some(row) = self.names.iter().position(|candidate| candidate == name) else {
            return Err(MeasurementError::MissingVariable {
                path: path.to_owned(),
                variable: name.to_owned(),
                available: self.names.clone(),
            });
        };
        let matrix_number = self.info(path, row, 0)?;
        let column = self.info(path, row, 1)?;
        let sign = if column < 0 { -1.0 } else { 1.0 };
        let (data, column, sign) = match matrix_number {
            // The abscissa: time is the first column of data_2.
            0 => (&self.data_2, 1, 1.0),
            1 => match &self.data_1 {
                Some(data_1) => (data_1, column.unsigned_abs(), sign),
                None => {
                    return Err(MeasurementError::MalformedMat {
                        path: path.to_owned(),
                        detail: format!(
                            "dataInfo places \"{name}\" in data_1, but the file has no data_1 matrix"
                        ),
                    })
                }
            },
            2 => (&self.data_2, column.unsigned_abs(), sign),
            other => {
                return Err(MeasurementError::UnsupportedMat {
                    path: path.to_owned(),
                    detail: format!(
                        "dataInfo places \"{name}\" in matrix {other}; only data_1 and data_2 can be read"
                    ),
                })
            }
        };
        let in_range = usize::try_from(column)
            .ok()
            .filter(|&column| (1..=data.cols()).contains(&column));
        let Some(column) = in_range else {
            return Err(MeasurementError::MalformedMat {
                path: path.to_owned(),
                detail: format!(
                    "dataInfo places \"{name}\" in column {column} of {}, which has {} columns",
                    data.matrix.name,
                    data.cols()
                ),
            });
        };
        if matrix_number != 1 {
            super::check_value_count(path, name, &[data.rows(), 1], data.rows())?;
        }
        let values = (0..data.rows())
            .filter_map(|time_index| data.get(time_index, column - 1))
            .map(|value| sign * value);
        if matrix_number == 1 {
            // Parameters are stored at the first and the last time; both are equal.
            match values.into_iter().next() {
                Some(value) => Ok(Samples::Constant(value)),
                None => Err(MeasurementError::EmptyVariable {
                    path: path.to_owned(),
                    variable: name.to_owned(),
                }),
            }
        } else {
            Ok(Samples::Series(values.collect()))
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::measurement::testdata::{self, precision, ResultFile as Written, V4};
    use crate::measurement::{Location, Measurement, MeasurementError};
    use std::path::PathBuf;

    fn path() -> PathBuf {
        PathBuf::from("sim/Furuta_res.mat")
    }

    fn load(bytes: &[u8], time: &str, columns: &[&str]) -> Result<Measurement, MeasurementError> {
        super::super::read(&path(), bytes, time, columns)
    }

    /// (time, x, der(x)) with an event at t = 0.2 (stored twice) and at t = 0.4.
    const SAMPLES: [[f64; 3]; 7] = [
        [0.0, 1.0, -1.0],
        [0.1, 0.9, -1.0],
        [0.2, 0.8, -1.0],
        [0.2, 0.8, 1.0],
        [0.3, 0.9, 1.0],
        [0.4, 1.0, 1.0],
        [0.4, 1.0, -2.0],
    ];

    fn every_layout() -> Vec<Written> {
        let mut layouts = Vec::new();
        for order in testdata::ByteOrder::BOTH {
            for transposed in [false, true] {
                layouts.push(Written::example(order, transposed, &SAMPLES));
                let mut single = Written::example(order, transposed, &SAMPLES);
                single.data_precision = precision::SINGLE;
                single
                    .data_2
                    .iter_mut()
                    .flatten()
                    .for_each(|v| *v = f64::from(*v as f32));
                layouts.push(single);
            }
        }
        layouts
    }

    #[test]
    fn reads_every_layout_and_byte_order() {
        for written in every_layout() {
            let label = format!(
                "{:?} transposed={} P={}",
                written.order, written.transposed, written.data_precision
            );
            let loaded = load(&written.write(), "time", &["der(x)", "x", "m", "y"])
                .unwrap_or_else(|error| panic!("{label}: {error}"));
            let rounded = |v: f64| f64::from(v as f32);
            let expect = |v: f64| {
                if written.data_precision == precision::SINGLE {
                    rounded(v)
                } else {
                    v
                }
            };
            // Events collapse onto the later sample.
            assert_eq!(
                loaded.time,
                [0.0, 0.1, 0.2, 0.3, 0.4].map(expect),
                "{label}"
            );
            assert_eq!(
                loaded.column("der(x)"),
                Some(&[-1.0, -1.0, 1.0, 1.0, -2.0][..]),
                "{label}"
            );
            assert_eq!(
                loaded.column("x"),
                Some(&[1.0, 0.9, 0.8, 0.9, 1.0].map(expect)[..]),
                "{label}"
            );
            assert_eq!(
                loaded.column("m"),
                Some(&[2.5; 5][..]),
                "{label}: parameter expanded"
            );
            assert_eq!(
                loaded.column("y"),
                Some(&[-1.0, -0.9, -0.8, -0.9, -1.0].map(expect)[..]),
                "{label}: negated alias"
            );
        }
    }

    #[test]
    fn missing_variable_lists_result_variables() {
        let written = Written::example(testdata::ByteOrder::Little, true, &SAMPLES);
        let error = load(&written.write(), "time", &["z"]).expect_err("missing");
        assert_eq!(
            error.to_string(),
            "sim/Furuta_res.mat: no variable \"z\"; the file's variables are: \"time\", \"m\", \"x\", \"y\", \"der(x)\""
        );
    }

    #[test]
    fn decreasing_time_is_still_an_error() {
        let mut samples = SAMPLES.to_vec();
        samples[4][0] = 0.15;
        let written = Written::example(testdata::ByteOrder::Big, false, &samples);
        let error = load(&written.write(), "time", &["x"]).expect_err("decreasing");
        assert!(
            matches!(
                error,
                MeasurementError::TimeNotIncreasing {
                    previous_location: Location::Sample(4),
                    location: Location::Sample(5),
                    ..
                }
            ),
            "{error}"
        );
    }

    #[test]
    fn non_finite_result_values_are_rejected() {
        let mut samples = SAMPLES.to_vec();
        samples[1][1] = f64::NAN;
        let written = Written::example(testdata::ByteOrder::Little, true, &samples);
        let error = load(&written.write(), "time", &["x"]).expect_err("NaN");
        assert_eq!(
            error.to_string(),
            "sim/Furuta_res.mat sample 2, column \"x\": value NaN is not finite (NaN and infinities are not allowed)"
        );
        // Variables nobody asked for are not checked.
        assert!(load(&written.write(), "time", &["der(x)"]).is_ok());
    }

    #[test]
    fn parameter_time_is_rejected() {
        let written = Written::example(testdata::ByteOrder::Little, false, &SAMPLES);
        let error = load(&written.write(), "m", &[]).expect_err("parameter as time");
        assert!(
            error.to_string().contains("\"m\" is a parameter"),
            "{error}"
        );
    }

    #[test]
    fn broken_data_info_is_reported() {
        let mut written = Written::example(testdata::ByteOrder::Little, false, &SAMPLES);
        written.variables[2].1 = [2, 7, 0, -1];
        written.variables[4].1 = [3, 1, 0, -1];
        let bytes = written.write();
        let error = load(&bytes, "time", &["x"]).expect_err("column out of range");
        assert_eq!(
            error.to_string(),
            "sim/Furuta_res.mat: not a valid MAT file: dataInfo places \"x\" in column 7 of data_2, which has 3 columns"
        );
        let error = load(&bytes, "time", &["der(x)"]).expect_err("matrix 3");
        assert!(
            matches!(error, MeasurementError::UnsupportedMat { .. }),
            "{error}"
        );
        written.variables[2].1 = [2, 0, 0, -1];
        let error = load(&written.write(), "time", &["x"]).expect_err("column 0");
        assert!(error.to_string().contains("column 0 of data_2"), "{error}");
    }

    #[test]
    fn missing_matrices_and_foreign_classes_are_reported() {
        let order = testdata::ByteOrder::Little;
        let writer = V4::new(order);
        let mut file = Vec::new();
        writer.text(
            &mut file,
            "Aclass",
            &["Atrajectory", "1.1", "", "binTrans"],
            false,
        );
        writer.text(&mut file, "name", &["time"], true);
        let error = load(&file, "time", &[]).expect_err("no dataInfo");
        assert_eq!(
            error.to_string(),
            "sim/Furuta_res.mat: not a valid MAT file: the result file (it has an Aclass matrix) lacks the \"dataInfo\" matrix"
        );

        let mut file = Vec::new();
        writer.text(&mut file, "Aclass", &["Atrajectory", "1.0"], false);
        let error = load(&file, "time", &[]).expect_err("old version");
        assert!(error.to_string().contains("version \"1.0\""), "{error}");

        let mut file = Vec::new();
        writer.text(&mut file, "Aclass", &["Amatrix"], false);
        let error = load(&file, "time", &[]).expect_err("other class");
        assert!(
            matches!(error, MeasurementError::UnsupportedMat { .. }),
            "{error}"
        );
    }

    #[test]
    fn data_info_must_match_the_names() {
        let writer = V4::new(testdata::ByteOrder::Little);
        let mut file = Vec::new();
        writer.text(
            &mut file,
            "Aclass",
            &["Atrajectory", "1.1", "", "binNormal"],
            false,
        );
        writer.text(&mut file, "name", &["time", "x"], false);
        writer.table(
            &mut file,
            "dataInfo",
            precision::INT32,
            &[vec![0.0, 1.0, 0.0, -1.0]],
            false,
        );
        writer.table(
            &mut file,
            "data_2",
            precision::DOUBLE,
            &[vec![0.0, 1.0]],
            false,
        );
        let error = load(&file, "time", &["x"]).expect_err("dataInfo too short");
        assert!(
            error.to_string().contains("\"name\" lists 2 variables"),
            "{error}"
        );
    }

    #[test]
    fn an_empty_name_matrix_claiming_billions_of_rows_is_refused_without_allocating() {
        // 2^31 − 1 names of no characters take no bytes in the file; building them
        // would take 48 GiB. dataInfo must agree with them before any name is read.
        let writer = V4::new(testdata::ByteOrder::Little);
        let mut file = Vec::new();
        writer.text(
            &mut file,
            "Aclass",
            &["Atrajectory", "1.1", "", "binNormal"],
            false,
        );
        writer.header(
            &mut file,
            i32::from(precision::UINT8) * 10 + 1,
            i32::MAX,
            0,
            false,
            "name",
        );
        writer.table(
            &mut file,
            "dataInfo",
            precision::INT32,
            &[vec![0.0, 1.0, 0.0, -1.0]],
            false,
        );
        writer.table(
            &mut file,
            "data_2",
            precision::DOUBLE,
            &[vec![0.0, 1.0]],
            false,
        );
        let error = load(&file, "time", &[]).expect_err("name and dataInfo disagree");
        assert_eq!(
            error.to_string(),
            "sim/Furuta_res.mat: not a valid MAT file: dataInfo is 1×4 int32 but \"name\" \
             lists 2147483647 variables (expected 2147483647 rows of at least 2 columns)"
        );
    }

    #[test]
    fn never_panics_on_mangled_result_files() {
        for (seed, written) in every_layout().into_iter().enumerate() {
            let bytes = written.write();
            for variant in testdata::mangled(&bytes, seed as u64 + 100, 1500) {
                let _ = load(&variant, "time", &["x", "m", "y"]);
            }
        }
    }
}
