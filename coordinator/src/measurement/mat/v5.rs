//! MAT v5 files, read with the `matfile` crate (0.5).
//!
//! What `matfile` reads: numeric arrays of every class (double, single, int8–int64,
//! uint8–uint64, real or complex), stored plain or in miCOMPRESSED (zlib) elements,
//! little- or big-endian. It skips cell, struct, object, char and sparse arrays, so
//! those look absent; the pre-scan below recognises them when they are not compressed
//! and says why they cannot be used.
//!
//! Limitations of `matfile` 0.5 worked around here:
//!
//! * An int32 array stored as miINT32 (how MATLAB saves `int32` variables) fails the
//!   whole file; the pre-scan names the variable so the user can save it as double.
//! * A truncated last element is silently dropped, and some corrupt lengths panic the
//!   parser (arithmetic overflow): the pre-scan checks every element's length against
//!   the file, and the parser runs under `catch_unwind` for what the pre-scan cannot
//!   see (the insides of compressed elements).
//! * A compressed element is inflated whole into memory; deflate expands at most about
//!   1,000-fold, which bounds what a corrupt or hostile file can make it allocate.
//! * Parse errors carry no position, so a corrupt file is reported as such, without an
//!   offset.
//! * It prints "Unsupported variable type" on standard output for unknown top-level
//!   element types, and the inflater's complaint on standard error for corrupt
//!   compressed elements; the error returned here is what callers should show.
//!
//! MAT v7.3 files have the same header but are HDF5 inside: they are rejected with a
//! hint to save in an older version.

use std::path::Path;

use super::{Samples, Variables};
use crate::measurement::MeasurementError;

/// Size of the text-and-flags header.
const HEADER_LEN: usize = 128;
/// Data element types that matter to the pre-scan.
const MI_INT32: u32 = 5;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
/// Array classes that `matfile` does not load.
const NON_NUMERIC_CLASSES: [(u32, &str); 5] = [
    (1, "cell"),
    (2, "struct"),
    (3, "object"),
    (4, "char"),
    (5, "sparse"),
];
const CLASS_INT32: u32 = 12;

/// The version field of a MAT v5-style header.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum HeaderVersion {
    /// 0x0100: MAT v5 (also written by `save -v6` and `-v7`).
    V5,
    /// 0x0200: MAT v7.3, HDF5 inside.
    V73,
    Other(u16),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ByteOrder {
    Little,
    Big,
}

impl ByteOrder {
    fn u16(self, bytes: [u8; 2]) -> u16 {
        match self {
            ByteOrder::Little => u16::from_le_bytes(bytes),
            ByteOrder::Big => u16::from_be_bytes(bytes),
        }
    }

    /// The `u32` at `offset`, if the slice holds it.
    fn u32_at(self, bytes: &[u8], offset: usize) -> Option<u32> {
        let raw: [u8; 4] = bytes.get(offset..offset.checked_add(4)?)?.try_into().ok()?;
        Some(match self {
            ByteOrder::Little => u32::from_le_bytes(raw),
            ByteOrder::Big => u32::from_be_bytes(raw),
        })
    }
}

/// The byte order and version of a MAT v5-style header, or `None` if `bytes` do not
/// start with one. The first four bytes of such a header are text, never NUL, while a
/// MAT v4 file starts with a type field that always holds zero bytes.
fn header(bytes: &[u8]) -> Option<(ByteOrder, HeaderVersion)> {
    let header = bytes.get(..HEADER_LEN)?;
    if header[..4].contains(&0) {
        return None;
    }
    let order = match &header[126..128] {
        b"IM" => ByteOrder::Little,
        b"MI" => ByteOrder::Big,
        _ => return None,
    };
    let version = match order.u16([header[124], header[125]]) {
        0x0100 => HeaderVersion::V5,
        0x0200 => HeaderVersion::V73,
        other => HeaderVersion::Other(other),
    };
    Some((order, version))
}

/// The version of a MAT v5-style header, or `None` if `bytes` do not start with one.
pub(super) fn header_version(bytes: &[u8]) -> Option<HeaderVersion> {
    header(bytes).map(|(_, version)| version)
}

/// What the pre-scan learnt about the uncompressed arrays.
#[derive(Debug, Default)]
struct Scan {
    /// Arrays `matfile` skips: name and class.
    non_numeric: Vec<(String, &'static str)>,
    /// int32 arrays stored as miINT32, which `matfile` 0.5 cannot parse.
    int32_arrays: Vec<String>,
}

/// A parsed MAT v5 file.
pub(super) struct V5File {
    file: matfile::MatFile,
    scan: Scan,
}

impl V5File {
    /// Parses `bytes`, which start with a MAT v5-style header (see [`header_version`]).
    pub fn parse(path: &Path, bytes: &[u8]) -> Result<V5File, MeasurementError> {
        let order = match header(bytes) {
            Some((order, HeaderVersion::V5)) => order,
            Some((_, HeaderVersion::V73)) => {
                return Err(MeasurementError::UnsupportedMat {
                    path: path.to_owned(),
                    detail: "this is a MAT v7.3 file (HDF5), which cannot be read; save it with \
                             `save(..., '-v7')` or '-v4' instead"
                        .to_owned(),
                })
            }
            Some((_, HeaderVersion::Other(version))) => {
                return Err(MeasurementError::MalformedMat {
                    path: path.to_owned(),
                    detail: format!("the header has the unknown version 0x{version:04x}"),
                })
            }
            None => {
                return Err(MeasurementError::MalformedMat {
                    path: path.to_owned(),
                    detail: "the MAT v5 header is missing".to_owned(),
                })
            }
        };
        let scan = scan(path, bytes, order)?;
        let parsed = std::panic::catch_unwind(|| matfile::MatFile::parse(bytes));
        let file = match parsed {
            Ok(Ok(file)) => file,
            Ok(Err(_)) if !scan.int32_arrays.is_empty() => {
                return Err(MeasurementError::UnsupportedMat {
                    path: path.to_owned(),
                    detail: format!(
                        "variable \"{}\" is an int32 array, which the MAT v5 reader cannot parse \
                         (the whole file fails); save it as double",
                        scan.int32_arrays[0]
                    ),
                })
            }
            Ok(Err(matfile::Error::ConversionError)) => {
                return Err(MeasurementError::UnsupportedMat {
                    path: path.to_owned(),
                    detail: "an array stores its values in a type that does not fit its class"
                        .to_owned(),
                })
            }
            Ok(Err(error)) => {
                return Err(MeasurementError::MalformedMat {
                    path: path.to_owned(),
                    detail: format!("the MAT v5 data elements are corrupt ({error})"),
                })
            }
            Err(_) => {
                return Err(MeasurementError::MalformedMat {
                    path: path.to_owned(),
                    detail: "the MAT v5 reader failed on a corrupt data element".to_owned(),
                })
            }
        };
        Ok(V5File { file, scan })
    }
}

impl Variables for V5File {
    fn samples(&self, path: &Path, name: &str) -> Result<Samples, MeasurementError> {
        let Some(array) = self.file.find_by_name(name) else {
            if let Some((_, class)) = self.scan.non_numeric.iter().find(|(n, _)| n == name) {
                return Err(MeasurementError::UnsupportedMat {
                    path: path.to_owned(),
                    detail: format!("variable \"{name}\" is a {class} array, not a numeric one"),
                });
            }
            return Err(MeasurementError::MissingVariable {
                path: path.to_owned(),
                variable: name.to_owned(),
                available: self
                    .file
                    .arrays()
                    .iter()
                    .map(|array| array.name().to_owned())
                    .collect(),
            });
        };
        let shape = array.size();
        if shape.iter().product::<usize>() == 0 {
            return Ok(Samples::Series(Vec::new()));
        }
        if !matches!(shape.as_slice(), [1, _] | [_, 1]) {
            return Err(MeasurementError::NotAVector {
                path: path.to_owned(),
                variable: name.to_owned(),
                shape: shape.clone(),
            });
        }
        real_values(array.data())
            .map(Samples::Series)
            .ok_or_else(|| MeasurementError::UnsupportedMat {
                path: path.to_owned(),
                detail: format!("variable \"{name}\" is complex"),
            })
    }
}

/// The values as `f64`, or `None` for a complex array. 64-bit integers beyond 2^53
/// lose precision.
fn real_values(data: &matfile::NumericData) -> Option<Vec<f64>> {
    use matfile::NumericData as Data;
    fn convert<T: Copy>(
        real: &[T],
        imag: &Option<Vec<T>>,
        to_f64: fn(T) -> f64,
    ) -> Option<Vec<f64>> {
        match imag {
            Some(_) => None,
            None => Some(real.iter().map(|&value| to_f64(value)).collect()),
        }
    }
    match data {
        Data::Double { real, imag } => convert(real, imag, |v| v),
        Data::Single { real, imag } => convert(real, imag, f64::from),
        Data::Int8 { real, imag } => convert(real, imag, f64::from),
        Data::UInt8 { real, imag } => convert(real, imag, f64::from),
        Data::Int16 { real, imag } => convert(real, imag, f64::from),
        Data::UInt16 { real, imag } => convert(real, imag, f64::from),
        Data::Int32 { real, imag } => convert(real, imag, f64::from),
        Data::UInt32 { real, imag } => convert(real, imag, f64::from),
        Data::Int64 { real, imag } => convert(real, imag, |v| v as f64),
        Data::UInt64 { real, imag } => convert(real, imag, |v| v as f64),
    }
}

/// A data element tag: type, data size, and where the data starts.
struct Tag {
    data_type: u32,
    size: usize,
    data_start: usize,
    /// Where the next element starts (after padding, which may run past the end).
    next: usize,
}

/// Reads the tag at `offset` of `bytes`; `padded` tells whether long elements are
/// padded to 8 bytes. `None` if the tag itself does not fit.
fn read_tag(bytes: &[u8], offset: usize, order: ByteOrder, padded: bool) -> Option<Tag> {
    let first = order.u32_at(bytes, offset)?;
    if first >> 16 != 0 {
        // Small element: size and type share four bytes, data fills the next four.
        return Some(Tag {
            data_type: first & 0xffff,
            size: (first >> 16) as usize,
            data_start: offset + 4,
            next: offset + 8,
        });
    }
    let size = order.u32_at(bytes, offset + 4)? as usize;
    let data_start = offset + 8;
    let end = data_start.checked_add(size)?;
    Some(Tag {
        data_type: first,
        size,
        data_start,
        next: if padded { end.next_multiple_of(8) } else { end },
    })
}

/// Checks every top-level element's length against the file, and looks inside the
/// uncompressed arrays for what `matfile` would choke on or skip.
fn scan(path: &Path, bytes: &[u8], order: ByteOrder) -> Result<Scan, MeasurementError> {
    let mut scan = Scan::default();
    let mut offset = HEADER_LEN;
    while offset < bytes.len() {
        let remaining = bytes.len() - offset;
        let tag = read_tag(bytes, offset, order, true)
            .filter(|tag| tag.data_start <= bytes.len())
            .ok_or_else(|| MeasurementError::MatTruncated {
                path: path.to_owned(),
                detail: format!(
                    "{remaining} bytes at offset {offset}, too few for a data element tag (8 bytes)"
                ),
            })?;
        let available = bytes.len() - tag.data_start;
        if tag.size > available {
            return Err(MeasurementError::MatTruncated {
                path: path.to_owned(),
                detail: format!(
                    "the data element at offset {offset} declares {} bytes but only {available} follow its tag",
                    tag.size
                ),
            });
        }
        let data = &bytes[tag.data_start..tag.data_start + tag.size];
        let next = if tag.data_type == MI_COMPRESSED {
            tag.data_start + tag.size
        } else {
            tag.next
        };
        if tag.data_type == MI_MATRIX {
            scan_array(path, data, offset, order, &mut scan)?;
        }
        offset = next;
    }
    Ok(scan)
}

/// Checks the sub-elements of an uncompressed array (flags, dimensions, name, data)
/// and records arrays `matfile` would skip or fail on.
fn scan_array(
    path: &Path,
    array: &[u8],
    offset: usize,
    order: ByteOrder,
    scan: &mut Scan,
) -> Result<(), MeasurementError> {
    let malformed = |detail: String| MeasurementError::MalformedMat {
        path: path.to_owned(),
        detail: format!("the array at offset {offset} {detail}"),
    };
    let mut class = None;
    let mut name = String::new();
    let mut position = 0;
    let mut index = 0;
    while position < array.len() {
        let tag = read_tag(array, position, order, true)
            .filter(|tag| tag.size <= array.len().saturating_sub(tag.data_start))
            .ok_or_else(|| {
                malformed(format!(
                    "has a sub-element overrunning it at byte {position}"
                ))
            })?;
        let data = &array[tag.data_start..tag.data_start + tag.size];
        match index {
            0 => class = order.u32_at(data, 0).map(|flags| flags & 0xff),
            1 => {
                let dims: Vec<i64> = data
                    .chunks_exact(4)
                    .filter_map(|chunk| order.u32_at(chunk, 0))
                    .map(|dim| i64::from(dim as i32))
                    .collect();
                let count = dims.iter().try_fold(1i64, |count, &dim| {
                    (dim >= 0).then(|| count.checked_mul(dim)).flatten()
                });
                if count.is_none_or(|count| count > i64::from(i32::MAX)) {
                    return Err(malformed(format!("has invalid dimensions {dims:?}")));
                }
            }
            2 => name = String::from_utf8_lossy(data).into_owned(),
            3 if class == Some(CLASS_INT32) && tag.data_type == MI_INT32 => {
                scan.int32_arrays.push(name.clone());
            }
            _ => {}
        }
        if index == 2 {
            if let Some((_, class_name)) = NON_NUMERIC_CLASSES
                .iter()
                .find(|(code, _)| Some(*code) == class)
            {
                // matfile does not look inside these, nor need we.
                scan.non_numeric.push((name, class_name));
                return Ok(());
            }
        }
        index += 1;
        position = tag.next;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measurement::testdata::{self, ByteOrder as Order, V5Writer};
    use crate::measurement::{Location, Measurement};
    use std::path::PathBuf;

    fn path() -> PathBuf {
        PathBuf::from("bench/log.mat")
    }

    fn load(bytes: &[u8], time: &str, columns: &[&str]) -> Result<Measurement, MeasurementError> {
        super::super::read(&path(), bytes, time, columns)
    }

    fn example(order: Order, compressed: bool) -> Vec<u8> {
        let writer = if compressed {
            V5Writer::new(order).compressed()
        } else {
            V5Writer::new(order)
        };
        writer
            .double("time", &[4, 1], &[0.0, 0.5, 1.0, 1.5])
            .single("phi", &[1, 4], &[0.25, -0.5, 1.0, 2.0])
            .double_as_uint8("count", &[4, 1], &[1, 2, 3, 200])
            .uint8("flags", &[1, 4], &[0, 1, 1, 0])
            .double("grid", &[2, 2], &[1.0, 2.0, 3.0, 4.0])
            .double("cube", &[1, 4, 1], &[1.0, 2.0, 3.0, 4.0])
            .double("nothing", &[0, 0], &[])
            .double("long_variable_name", &[4, 1], &[9.0, 8.0, 7.0, 6.0])
            .finish()
    }

    #[test]
    fn reads_vectors_plain_and_compressed_in_both_byte_orders() {
        for order in Order::BOTH {
            for compressed in [false, true] {
                let label = format!("{order:?} compressed={compressed}");
                let loaded = load(
                    &example(order, compressed),
                    "time",
                    &["phi", "count", "flags", "long_variable_name"],
                )
                .unwrap_or_else(|error| panic!("{label}: {error}"));
                assert_eq!(loaded.time, vec![0.0, 0.5, 1.0, 1.5], "{label}");
                assert_eq!(
                    loaded.column("phi"),
                    Some(&[0.25, -0.5, 1.0, 2.0][..]),
                    "{label}"
                );
                assert_eq!(
                    loaded.column("count"),
                    Some(&[1.0, 2.0, 3.0, 200.0][..]),
                    "{label}"
                );
                assert_eq!(
                    loaded.column("flags"),
                    Some(&[0.0, 1.0, 1.0, 0.0][..]),
                    "{label}"
                );
                assert_eq!(
                    loaded.column("long_variable_name"),
                    Some(&[9.0, 8.0, 7.0, 6.0][..]),
                    "{label}"
                );
            }
        }
    }

    #[test]
    fn non_vectors_name_their_shape() {
        let bytes = example(Order::Little, false);
        let error = load(&bytes, "time", &["grid"]).expect_err("matrix");
        assert_eq!(
            error.to_string(),
            "bench/log.mat: variable \"grid\" is a 2×2 array; expected a vector (n×1 or 1×n)"
        );
        let error = load(&bytes, "time", &["cube"]).expect_err("3-D");
        assert!(error.to_string().contains("is a 1×4×1 array"), "{error}");
        let error = load(&bytes, "time", &["nothing"]).expect_err("empty");
        assert_eq!(
            error.to_string(),
            "bench/log.mat: variable \"nothing\" has no samples"
        );
    }

    #[test]
    fn missing_variable_lists_the_arrays() {
        let error = load(&example(Order::Big, true), "time", &["theta"]).expect_err("missing");
        assert_eq!(
            error.to_string(),
            "bench/log.mat: no variable \"theta\"; the file's variables are: \"time\", \"phi\", \"count\", \"flags\", \"grid\", \"cube\", \"nothing\", \"long_variable_name\""
        );
    }

    #[test]
    fn non_numeric_and_complex_variables_are_unsupported() {
        let bytes = V5Writer::new(Order::Little)
            .double("time", &[2, 1], &[0.0, 1.0])
            .chars("label", "abc")
            .complex_double("z", &[2, 1], &[1.0, 2.0], &[0.0, 1.0])
            .finish();
        let error = load(&bytes, "time", &["label"]).expect_err("char");
        let message = error.to_string();
        assert!(
            message.contains("variable \"label\" is a char array, not a numeric one"),
            "{message}"
        );
        assert!(message.contains("MAT v5 real numeric arrays"), "{message}");
        let error = load(&bytes, "time", &["z"]).expect_err("complex");
        assert!(
            error.to_string().contains("variable \"z\" is complex"),
            "{error}"
        );
    }

    #[test]
    fn int32_arrays_are_named_as_the_cause() {
        let bytes = V5Writer::new(Order::Little)
            .double("time", &[2, 1], &[0.0, 1.0])
            .int32("ticks", &[2, 1], &[5, 6])
            .finish();
        // matfile 0.5 maps the int32 class to the uint32 type and rejects the data.
        assert!(matfile::MatFile::parse(bytes.as_slice()).is_err());
        let error = load(&bytes, "time", &[]).expect_err("int32");
        assert!(
            error
                .to_string()
                .contains("variable \"ticks\" is an int32 array"),
            "{error}"
        );
    }

    #[test]
    fn values_are_checked_like_any_measurement() {
        let bytes = V5Writer::new(Order::Little)
            .double("time", &[3, 1], &[0.0, 1.0, 0.5])
            .double("x", &[3, 1], &[0.0, f64::NAN, 1.0])
            .double("short", &[2, 1], &[0.0, 1.0])
            .finish();
        let error = load(&bytes, "time", &["x"]).expect_err("NaN first");
        assert!(
            matches!(
                error,
                MeasurementError::NonFinite {
                    location: Location::Sample(2),
                    ..
                }
            ),
            "{error}"
        );
        let error = load(&bytes, "time", &[]).expect_err("time decreases");
        assert!(
            matches!(error, MeasurementError::TimeNotIncreasing { .. }),
            "{error}"
        );
        let error = load(&bytes, "x", &["short"]).expect_err("length");
        assert!(
            matches!(
                error,
                MeasurementError::LengthMismatch {
                    found: 2,
                    expected: 3,
                    ..
                }
            ),
            "{error}"
        );
    }

    #[test]
    fn truncation_is_detected() {
        let bytes = example(Order::Little, false);
        let cut = &bytes[..bytes.len() - 3];
        // matfile 0.5 on its own drops the cut element without a word.
        let parsed = matfile::MatFile::parse(cut).expect("matfile accepts the cut file");
        assert!(parsed.find_by_name("long_variable_name").is_none());
        assert!(parsed.find_by_name("time").is_some());
        let error = load(cut, "time", &["phi"]).expect_err("cut");
        assert!(
            matches!(error, MeasurementError::MatTruncated { .. }),
            "{error}"
        );
        assert!(error.to_string().contains("declares"), "{error}");
        let error = load(&bytes[..HEADER_LEN + 5], "time", &[]).expect_err("cut tag");
        assert_eq!(
            error.to_string(),
            "bench/log.mat: MAT file is truncated: 5 bytes at offset 128, too few for a data element tag (8 bytes)"
        );
        let compressed = example(Order::Big, true);
        let error = load(&compressed[..compressed.len() - 1], "time", &[]).expect_err("cut");
        assert!(
            matches!(error, MeasurementError::MatTruncated { .. }),
            "{error}"
        );
    }

    #[test]
    fn header_without_data_has_no_variables() {
        let bytes = V5Writer::new(Order::Little).finish();
        let error = load(&bytes, "time", &[]).expect_err("no data");
        assert!(
            error.to_string().contains("variables are: (none)"),
            "{error}"
        );
    }

    #[test]
    fn mat73_is_unsupported_with_a_hint() {
        let bytes = testdata::mat73_start();
        assert_eq!(header_version(&bytes), Some(HeaderVersion::V73));
        let error = load(&bytes, "time", &[]).expect_err("HDF5");
        let message = error.to_string();
        assert!(message.contains("MAT v7.3 file (HDF5)"), "{message}");
        assert!(message.contains("-v7"), "{message}");
    }

    #[test]
    fn oversized_dimensions_are_rejected_before_parsing() {
        // 65536 × 65536 elements overflow matfile's i32 element count.
        let bytes = V5Writer::new(Order::Little)
            .double("x", &[65536, 65536], &[1.0])
            .finish();
        let error = load(&bytes, "x", &[]).expect_err("overflow");
        assert!(
            error
                .to_string()
                .contains("invalid dimensions [65536, 65536]"),
            "{error}"
        );
    }

    #[test]
    fn parser_failures_inside_compressed_elements_are_errors() {
        // The pre-scan cannot see inside; the parser's overflow is caught instead.
        let bytes = V5Writer::new(Order::Little)
            .compressed()
            .double("x", &[65536, 65536], &[1.0])
            .finish();
        let error = load(&bytes, "x", &[]).expect_err("overflow");
        assert!(
            matches!(error, MeasurementError::MalformedMat { .. }),
            "{error}"
        );
    }

    #[test]
    fn never_panics_on_mangled_files() {
        for (seed, compressed) in [(11, false), (12, true)] {
            let bytes = V5Writer::new(Order::Little);
            let bytes = if compressed {
                bytes.compressed()
            } else {
                bytes
            };
            let bytes = bytes
                .double("time", &[3, 1], &[0.0, 0.5, 1.0])
                .single("x", &[1, 3], &[1.0, 2.0, 3.0])
                .chars("s", "ab")
                .finish();
            for variant in testdata::mangled(&bytes, seed, 3000) {
                let _ = load(&variant, "time", &["x"]);
            }
        }
        let garbage = V5Writer::new(Order::Big).raw(&[0xff; 64]).finish();
        assert!(load(&garbage, "time", &[]).is_err());
    }
}
