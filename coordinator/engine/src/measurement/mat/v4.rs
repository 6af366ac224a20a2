//! MAT v4 files: a plain sequence of matrices.
//!
//! Each matrix is a 20-byte header of five `i32` (`type`, `mrows`, `ncols`, `imagf`,
//! `namlen`), the NUL-terminated name (`namlen` bytes), then the real part and, when
//! `imagf` is 1, the imaginary part, each column-major. `type` = M·1000 + O·100 + P·10
//! + T with:
//!
//! * M, byte order: 0 little-endian, 1 big-endian (per matrix; the header itself is
//!   written in that order). 2–4 (VAX, Cray) are not supported.
//! * O: always 0.
//! * P, precision: 0 double, 1 single, 2 int32, 3 int16, 4 uint16, 5 uint8.
//! * T: 0 numeric full, 1 text, 2 sparse. Text and sparse matrices are skipped over, and
//!   only numeric real matrices can be read as variables.
//!
//! Values are decoded lazily: a file is scanned once, and only the matrices asked for
//! are converted to `f64`.

use std::path::Path;

use super::{Samples, Variables};
use crate::measurement::MeasurementError;

/// Size of a matrix header in bytes.
const HEADER_LEN: usize = 20;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum ByteOrder {
    Little,
    Big,
}

/// How each stored value is encoded (the `P` digit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Precision {
    Double,
    Single,
    Int32,
    Int16,
    UInt16,
    UInt8,
}

impl Precision {
    fn from_digit(digit: i32) -> Option<Precision> {
        match digit {
            0 => Some(Precision::Double),
            1 => Some(Precision::Single),
            2 => Some(Precision::Int32),
            3 => Some(Precision::Int16),
            4 => Some(Precision::UInt16),
            5 => Some(Precision::UInt8),
            _ => None,
        }
    }

    fn size(self) -> usize {
        match self {
            Precision::Double => 8,
            Precision::Single | Precision::Int32 => 4,
            Precision::Int16 | Precision::UInt16 => 2,
            Precision::UInt8 => 1,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Precision::Double => "double",
            Precision::Single => "single",
            Precision::Int32 => "int32",
            Precision::Int16 => "int16",
            Precision::UInt16 => "uint16",
            Precision::UInt8 => "uint8",
        }
    }
}

/// What a matrix holds (the `T` digit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum MatrixKind {
    Numeric,
    Text,
    Sparse,
}

/// One matrix of a MAT v4 file, its values still encoded.
#[derive(Debug, Clone)]
pub(super) struct Matrix<'a> {
    pub name: String,
    pub rows: usize,
    pub cols: usize,
    pub kind: MatrixKind,
    pub precision: Precision,
    pub byte_order: ByteOrder,
    pub complex: bool,
    /// The real part: exactly `rows * cols` values.
    real: &'a [u8],
}

impl Matrix<'_> {
    pub fn len(&self) -> usize {
        self.rows * self.cols
    }

    /// The value at column-major `index`, or `None` past the end.
    pub fn value(&self, index: usize) -> Option<f64> {
        let size = self.precision.size();
        let start = index.checked_mul(size)?;
        let bytes = self.real.get(start..start.checked_add(size)?)?;
        Some(decode(bytes, self.precision, self.byte_order))
    }

    /// All values, column-major.
    pub fn values(&self) -> Vec<f64> {
        self.real
            .chunks_exact(self.precision.size())
            .map(|bytes| decode(bytes, self.precision, self.byte_order))
            .collect()
    }

    /// E.g. `801×1 double` or `4×11 uint8 text`, for messages.
    pub fn describe(&self) -> String {
        let kind = match self.kind {
            MatrixKind::Numeric => "",
            MatrixKind::Text => " text",
            MatrixKind::Sparse => " sparse",
        };
        let complex = if self.complex { " complex" } else { "" };
        format!(
            "{}×{}{complex} {}{kind}",
            self.rows,
            self.cols,
            self.precision.name()
        )
    }
}

/// Decodes one value; `bytes` has exactly the precision's size.
fn decode(bytes: &[u8], precision: Precision, order: ByteOrder) -> f64 {
    fn array<const N: usize>(bytes: &[u8], order: ByteOrder) -> [u8; N] {
        let mut array = [0; N];
        array.copy_from_slice(bytes);
        if order == ByteOrder::Big {
            array.reverse();
        }
        array
    }
    match precision {
        Precision::Double => f64::from_le_bytes(array(bytes, order)),
        Precision::Single => f64::from(f32::from_le_bytes(array(bytes, order))),
        Precision::Int32 => f64::from(i32::from_le_bytes(array(bytes, order))),
        Precision::Int16 => f64::from(i16::from_le_bytes(array(bytes, order))),
        Precision::UInt16 => f64::from(u16::from_le_bytes(array(bytes, order))),
        Precision::UInt8 => f64::from(bytes[0]),
    }
}

/// The fields of a matrix header, validated for plausibility only.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Header {
    byte_order: ByteOrder,
    precision: Precision,
    kind: MatrixKind,
    rows: usize,
    cols: usize,
    complex: bool,
    name_len: usize,
}

/// Why the bytes at an offset are not a usable matrix header.
#[derive(Debug, Clone, PartialEq, Eq)]
enum HeaderProblem {
    /// Fewer than 20 bytes left.
    Short,
    /// A valid header in a number format this reader does not decode.
    Unsupported(String),
    /// Not a header at all.
    Invalid(String),
}

fn decode_header(bytes: &[u8]) -> Result<Header, HeaderProblem> {
    let Some(fields) = bytes.get(..HEADER_LEN) else {
        return Err(HeaderProblem::Short);
    };
    let field = |index: usize, order: ByteOrder| {
        let mut raw = [0; 4];
        raw.copy_from_slice(&fields[index * 4..index * 4 + 4]);
        match order {
            ByteOrder::Little => i32::from_le_bytes(raw),
            ByteOrder::Big => i32::from_be_bytes(raw),
        }
    };
    let (byte_order, type_code) =
        byte_order_of(field(0, ByteOrder::Little), field(0, ByteOrder::Big))?;
    let (precision, kind) = matrix_type(type_code)?;
    let rows = field(1, byte_order);
    let cols = field(2, byte_order);
    let imaginary = field(3, byte_order);
    let name_len = field(4, byte_order);
    let (Ok(rows), Ok(cols)) = (usize::try_from(rows), usize::try_from(cols)) else {
        return Err(HeaderProblem::Invalid(format!(
            "negative dimensions {rows}×{cols}"
        )));
    };
    if !(0..=1).contains(&imaginary) {
        return Err(HeaderProblem::Invalid(format!(
            "imaginary flag {imaginary} (must be 0 or 1)"
        )));
    }
    let name_len = match usize::try_from(name_len) {
        Ok(name_len) if name_len >= 1 => name_len,
        _ => {
            return Err(HeaderProblem::Invalid(format!(
                "name length {name_len} (must count at least the terminating NUL)"
            )))
        }
    };
    Ok(Header {
        byte_order,
        precision,
        kind,
        rows,
        cols,
        complex: imaginary == 1,
        name_len,
    })
}

/// The byte order of a header whose type field reads `little` in little-endian and `big`
/// in big-endian order, and the type code without its byte-order digit M.
fn byte_order_of(little: i32, big: i32) -> Result<(ByteOrder, i32), HeaderProblem> {
    // The type field, read in the right byte order, is M·1000 + …, so M tells the order.
    if (0..1000).contains(&little) {
        Ok((ByteOrder::Little, little))
    } else if (1000..2000).contains(&big) {
        Ok((ByteOrder::Big, big - 1000))
    } else if (2000..5000).contains(&little) || (2000..5000).contains(&big) {
        Err(HeaderProblem::Unsupported(format!(
            "type {} uses the VAX or Cray number format",
            if (2000..5000).contains(&little) {
                little
            } else {
                big
            }
        )))
    } else {
        Err(HeaderProblem::Invalid(format!(
            "type field {little} is not a MAT v4 matrix type"
        )))
    }
}

/// The precision (P digit) and kind (T digit) of type code `type_code` (O must be 0).
fn matrix_type(type_code: i32) -> Result<(Precision, MatrixKind), HeaderProblem> {
    let precision_digit = type_code / 10 % 10;
    let (Some(precision), 0) = (Precision::from_digit(precision_digit), type_code / 100) else {
        return Err(HeaderProblem::Invalid(format!(
            "type field {type_code} is not a MAT v4 matrix type"
        )));
    };
    let kind = match type_code % 10 {
        0 => MatrixKind::Numeric,
        1 => MatrixKind::Text,
        2 => MatrixKind::Sparse,
        other => {
            return Err(HeaderProblem::Invalid(format!(
                "type field {type_code} has matrix kind {other} (0 numeric, 1 text, 2 sparse)"
            )))
        }
    };
    Ok((precision, kind))
}

/// Whether `bytes` start with a plausible MAT v4 matrix header and name.
pub(super) fn looks_like_v4(bytes: &[u8]) -> bool {
    let Ok(header) = decode_header(bytes) else {
        return false;
    };
    let name_end = HEADER_LEN + header.name_len;
    bytes.get(name_end - 1) == Some(&0)
        && bytes[HEADER_LEN..name_end - 1]
            .iter()
            .all(|&byte| byte.is_ascii_graphic())
}

/// Scans every matrix of a MAT v4 file.
pub(super) fn parse<'a>(path: &Path, bytes: &'a [u8]) -> Result<Vec<Matrix<'a>>, MeasurementError> {
    let malformed = |detail: String| MeasurementError::MalformedMat {
        path: path.to_owned(),
        detail,
    };
    let truncated = |detail: String| MeasurementError::MatTruncated {
        path: path.to_owned(),
        detail,
    };
    if bytes.is_empty() {
        return Err(malformed("the file is empty".to_owned()));
    }
    let mut matrices = Vec::new();
    let mut offset = 0;
    while offset < bytes.len() {
        let rest = &bytes[offset..];
        let header = decode_header(rest).map_err(|problem| match problem {
            HeaderProblem::Short => truncated(format!(
                "{} bytes after the last matrix at offset {offset}, too few for a matrix header ({HEADER_LEN} bytes)",
                rest.len()
            )),
            HeaderProblem::Unsupported(detail) => MeasurementError::UnsupportedMat {
                path: path.to_owned(),
                detail: format!("the matrix at offset {offset} has {detail}"),
            },
            HeaderProblem::Invalid(detail) => {
                malformed(format!("no MAT v4 matrix header at offset {offset}: {detail}"))
            }
        })?;
        let name_bytes = rest
            .get(HEADER_LEN..HEADER_LEN + header.name_len)
            .ok_or_else(|| {
                truncated(format!(
                    "the matrix at offset {offset} has a {}-byte name but only {} bytes follow its header",
                    header.name_len,
                    rest.len() - HEADER_LEN
                ))
            })?;
        let name_bytes = name_bytes
            .iter()
            .position(|&byte| byte == 0)
            .map_or(name_bytes, |nul| &name_bytes[..nul]);
        let name = String::from_utf8_lossy(name_bytes).into_owned();

        let data_start = HEADER_LEN + header.name_len;
        let part_len = header
            .rows
            .checked_mul(header.cols)
            .and_then(|count| count.checked_mul(header.precision.size()));
        let data_len = part_len.and_then(|len| len.checked_mul(1 + usize::from(header.complex)));
        let (Some(part_len), Some(data_len)) = (part_len, data_len) else {
            return Err(malformed(format!(
                "matrix \"{name}\" at offset {offset} claims an impossible size {}×{}",
                header.rows, header.cols
            )));
        };
        let available = rest.len() - data_start;
        if data_len > available {
            return Err(truncated(format!(
                "matrix \"{name}\" at offset {offset} holds {}×{}{} {} values ({data_len} bytes) but only {available} bytes follow its name",
                header.rows,
                header.cols,
                if header.complex { " complex" } else { "" },
                header.precision.name(),
            )));
        }
        matrices.push(Matrix {
            name,
            rows: header.rows,
            cols: header.cols,
            kind: header.kind,
            precision: header.precision,
            byte_order: header.byte_order,
            complex: header.complex,
            real: &rest[data_start..data_start + part_len],
        });
        offset += data_start + data_len;
    }
    Ok(matrices)
}

/// The matrices of a MAT v4 file taken as named vectors, the way MATLAB's `save -v4`
/// stores variables. A name stored twice resolves to the later matrix, as MATLAB's
/// `load` does.
pub(super) struct PlainVariables<'m, 'a> {
    matrices: &'m [Matrix<'a>],
}

impl<'m, 'a> PlainVariables<'m, 'a> {
    pub fn new(matrices: &'m [Matrix<'a>]) -> Self {
        PlainVariables { matrices }
    }
}

impl Variables for PlainVariables<'_, '_> {
    fn samples(&self, path: &Path, name: &str) -> Result<Samples, MeasurementError> {
        let Some(matrix) = self.matrices.iter().rev().find(|m| m.name == name) else {
            let mut available: Vec<String> = Vec::new();
            for matrix in self.matrices {
                if !available.contains(&matrix.name) {
                    available.push(matrix.name.clone());
                }
            }
            return Err(MeasurementError::MissingVariable {
                path: path.to_owned(),
                variable: name.to_owned(),
                available,
            });
        };
        numeric_vector(path, matrix).map(Samples::Series)
    }
}

/// The values of a matrix that must be a real numeric vector (or empty).
pub(super) fn numeric_vector(path: &Path, matrix: &Matrix) -> Result<Vec<f64>, MeasurementError> {
    if matrix.kind != MatrixKind::Numeric || matrix.complex {
        return Err(MeasurementError::UnsupportedMat {
            path: path.to_owned(),
            detail: format!(
                "variable \"{}\" is a {} matrix, not a real numeric one",
                matrix.name,
                matrix.describe()
            ),
        });
    }
    if matrix.len() > 0 && matrix.rows != 1 && matrix.cols != 1 {
        return Err(MeasurementError::NotAVector {
            path: path.to_owned(),
            variable: matrix.name.clone(),
            shape: vec![matrix.rows, matrix.cols],
        });
    }
    super::check_value_count(
        path,
        &matrix.name,
        &[matrix.rows, matrix.cols],
        matrix.len(),
    )?;
    Ok(matrix.values())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measurement::testdata::{self, precision, V4};
    use crate::measurement::Measurement;
    use std::path::PathBuf;

    fn path() -> PathBuf {
        PathBuf::from("rig.mat")
    }

    fn load(bytes: &[u8], time: &str, columns: &[&str]) -> Result<Measurement, MeasurementError> {
        super::super::read(&path(), bytes, time, columns)
    }

    fn furuta(order: testdata::ByteOrder) -> Vec<u8> {
        let writer = V4::new(order);
        let time: Vec<f64> = (0..801).map(|i| f64::from(i) * 0.05).collect();
        let phi: Vec<f64> = time.iter().map(|t| (t * 0.3).sin()).collect();
        let theta: Vec<f64> = time.iter().map(|t| 3.0 - (t * 0.7).cos()).collect();
        let mut file = Vec::new();
        writer.double(&mut file, "phi", 801, 1, &phi);
        writer.double(&mut file, "theta", 1, 801, &theta);
        writer.double(&mut file, "time", 801, 1, &time);
        file
    }

    #[test]
    fn reads_plain_vectors_in_both_byte_orders() {
        for order in testdata::ByteOrder::BOTH {
            let loaded = load(&furuta(order), "time", &["theta", "phi"]).expect("valid");
            assert_eq!(loaded.time.len(), 801, "{order:?}");
            assert_eq!(loaded.time[800], 40.0);
            assert_eq!(loaded.columns[0].0, "theta");
            assert_eq!(loaded.column("phi").map(|v| v[20]), Some(0.3f64.sin()));
            assert_eq!(loaded.column("theta").map(|v| v[0]), Some(2.0));
        }
    }

    #[test]
    fn reads_every_precision() {
        let cases = [
            (precision::DOUBLE, vec![-1.5, 0.25, 3.0]),
            (precision::SINGLE, vec![-1.5, 0.25, 3.0]),
            (precision::INT32, vec![-70000.0, 0.0, 70000.0]),
            (precision::INT16, vec![-300.0, 0.0, 300.0]),
            (precision::UINT16, vec![0.0, 300.0, 65535.0]),
            (precision::UINT8, vec![0.0, 7.0, 255.0]),
        ];
        for order in testdata::ByteOrder::BOTH {
            for (code, values) in &cases {
                let writer = V4::new(order);
                let mut file = Vec::new();
                writer.matrix(&mut file, "t", precision::INT16, 3, 1, &[1.0, 2.0, 3.0]);
                writer.matrix(&mut file, "x", *code, 1, 3, values);
                let loaded = load(&file, "t", &["x"]).expect("valid");
                assert_eq!(loaded.time, vec![1.0, 2.0, 3.0]);
                assert_eq!(loaded.column("x"), Some(&values[..]), "{order:?} P={code}");
            }
        }
    }

    #[test]
    fn missing_variable_lists_the_variables() {
        let error =
            load(&furuta(testdata::ByteOrder::Little), "time", &["alpha"]).expect_err("missing");
        assert_eq!(
            error.to_string(),
            "rig.mat: no variable \"alpha\"; the file's variables are: \"phi\", \"theta\", \"time\""
        );
    }

    #[test]
    fn matrices_are_not_vectors() {
        let writer = V4::new(testdata::ByteOrder::Little);
        let mut file = Vec::new();
        writer.double(&mut file, "time", 3, 1, &[0.0, 1.0, 2.0]);
        writer.double(&mut file, "m", 3, 2, &[0.0; 6]);
        let error = load(&file, "time", &["m"]).expect_err("matrix");
        assert_eq!(
            error.to_string(),
            "rig.mat: variable \"m\" is a 3×2 array; expected a vector (n×1 or 1×n)"
        );
    }

    #[test]
    fn text_and_complex_variables_are_unsupported() {
        let writer = V4::new(testdata::ByteOrder::Big);
        let mut file = Vec::new();
        writer.double(&mut file, "time", 3, 1, &[0.0, 1.0, 2.0]);
        writer.text(&mut file, "label", &["abc"], false);
        writer.header(&mut file, 0, 1, 3, true, "z");
        writer.values(
            &mut file,
            precision::DOUBLE,
            &[1.0, 2.0, 3.0, 0.0, 0.0, 1.0],
        );
        let error = load(&file, "time", &["label"]).expect_err("text");
        let message = error.to_string();
        assert!(matches!(error, MeasurementError::UnsupportedMat { .. }));
        assert!(
            message.contains("\"label\" is a 1×3 uint8 text matrix"),
            "{message}"
        );
        assert!(
            message.contains("supported are MAT v4 real full matrices"),
            "{message}"
        );
        let error = load(&file, "time", &["z"]).expect_err("complex");
        assert!(error.to_string().contains("1×3 complex double"), "{error}");
    }

    #[test]
    fn plain_time_must_strictly_increase() {
        let writer = V4::new(testdata::ByteOrder::Little);
        let mut file = Vec::new();
        writer.double(&mut file, "time", 4, 1, &[0.0, 1.0, 1.0, 2.0]);
        let error = load(&file, "time", &[]).expect_err("repeat");
        assert_eq!(
            error.to_string(),
            "rig.mat sample 3: time (\"time\") must strictly increase, but 1 follows 1 at sample 2"
        );
    }

    #[test]
    fn later_matrix_of_the_same_name_wins() {
        let writer = V4::new(testdata::ByteOrder::Little);
        let mut file = Vec::new();
        writer.double(&mut file, "time", 2, 1, &[0.0, 1.0]);
        writer.double(&mut file, "x", 2, 1, &[1.0, 1.0]);
        writer.double(&mut file, "x", 2, 1, &[2.0, 2.0]);
        let loaded = load(&file, "time", &["x"]).expect("valid");
        assert_eq!(loaded.column("x"), Some(&[2.0, 2.0][..]));
    }

    #[test]
    fn empty_variable_is_reported() {
        let writer = V4::new(testdata::ByteOrder::Little);
        let mut file = Vec::new();
        writer.double(&mut file, "time", 0, 0, &[]);
        let error = load(&file, "time", &[]).expect_err("empty");
        assert_eq!(
            error.to_string(),
            "rig.mat: variable \"time\" has no samples"
        );
    }

    #[test]
    fn truncation_names_the_matrix() {
        let file = furuta(testdata::ByteOrder::Little);
        let error = load(&file[..100], "time", &["phi"]).expect_err("cut");
        assert_eq!(
            error.to_string(),
            "rig.mat: MAT file is truncated: matrix \"phi\" at offset 0 holds 801×1 double values (6408 bytes) but only 76 bytes follow its name"
        );
        let error = load(&file[..22], "time", &["phi"]).expect_err("cut in name");
        assert!(
            matches!(error, MeasurementError::MatTruncated { .. }),
            "{error}"
        );
        let first_matrix_len = 20 + 4 + 801 * 8;
        let error = load(&file[..first_matrix_len + 7], "time", &["phi"]).expect_err("cut");
        assert_eq!(
            error.to_string(),
            format!("rig.mat: MAT file is truncated: 7 bytes after the last matrix at offset {first_matrix_len}, too few for a matrix header (20 bytes)")
        );
    }

    #[test]
    fn foreign_number_formats_are_unsupported() {
        let mut file = Vec::new();
        V4::new(testdata::ByteOrder::Little).header(&mut file, 2000, 1, 1, false, "x");
        file.extend_from_slice(&[0; 8]);
        let error = load(&file, "x", &[]).expect_err("VAX");
        assert!(
            matches!(error, MeasurementError::UnsupportedMat { .. }),
            "{error}"
        );
        assert!(error.to_string().contains("VAX or Cray"), "{error}");
    }

    #[test]
    fn garbage_headers_are_malformed() {
        let error = load(b"this is not a MAT file at all", "x", &[]).expect_err("text");
        assert!(
            matches!(error, MeasurementError::MalformedMat { .. }),
            "{error}"
        );
        assert!(error.to_string().contains("offset 0"), "{error}");
        let error = load(b"", "x", &[]).expect_err("empty");
        assert_eq!(
            error.to_string(),
            "rig.mat: not a valid MAT file: the file is empty"
        );
        let mut file = Vec::new();
        V4::new(testdata::ByteOrder::Little).header(&mut file, 0, -1, 1, false, "x");
        let error = load(&file, "x", &[]).expect_err("negative");
        assert!(
            error.to_string().contains("negative dimensions -1×1"),
            "{error}"
        );
        let mut file = Vec::new();
        V4::new(testdata::ByteOrder::Little).header(&mut file, 0, i32::MAX, i32::MAX, true, "x");
        assert!(load(&file, "x", &[]).is_err());
    }

    #[test]
    fn sniffing_accepts_v4_headers_only() {
        assert!(looks_like_v4(&furuta(testdata::ByteOrder::Little)));
        assert!(looks_like_v4(&furuta(testdata::ByteOrder::Big)));
        assert!(!looks_like_v4(b"time,phi\n0,1\n1,2\n3,4\n5,6\n"));
        assert!(!looks_like_v4(&[0; 40]));
        assert!(!looks_like_v4(&furuta(testdata::ByteOrder::Little)[..22]));
    }

    #[test]
    fn never_panics_on_mangled_files() {
        for (seed, order) in [
            (7, testdata::ByteOrder::Little),
            (8, testdata::ByteOrder::Big),
        ] {
            let writer = V4::new(order);
            let mut file = Vec::new();
            writer.double(&mut file, "time", 4, 1, &[0.0, 1.0, 2.0, 3.0]);
            writer.matrix(&mut file, "x", precision::SINGLE, 1, 4, &[1.0; 4]);
            writer.matrix(&mut file, "n", precision::UINT8, 4, 1, &[1.0; 4]);
            for variant in testdata::mangled(&file, seed, 3000) {
                let _ = load(&variant, "time", &["x", "n"]);
                let _ = looks_like_v4(&variant);
            }
        }
    }
}
