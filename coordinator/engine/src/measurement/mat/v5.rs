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
//! * A compressed element is inflated whole into memory by `matfile`, however much it
//!   expands (a 1 MB file of zeros inflates to 1 GB). Compressed elements are therefore
//!   inflated here, within [`MAX_MAT_INFLATED_BYTES`] for the whole file and never beyond
//!   the size the inflated element declares, and `matfile` parses the file with each of
//!   them replaced by what it inflated to: it never inflates anything itself. The
//!   pre-scan then also sees inside compressed arrays.
//! * Numeric arrays of more than [`MAX_MAT_VALUES`] values are refused by the pre-scan.
//! * Parse errors carry no position, so a corrupt file is reported as such, without an
//!   offset.
//! * It prints "Unsupported variable type" on standard output for unknown top-level
//!   element types, and the inflater's complaint on standard error for corrupt
//!   compressed elements; the error returned here is what callers should show.
//!
//! MAT v7.3 files have the same header but are HDF5 inside: they are rejected with a
//! hint to save in an older version.

use std::borrow::Cow;
use std::io::Read;
use std::path::Path;

use super::{Samples, Variables};
use crate::limits::{MAX_MAT_INFLATED_BYTES, MAX_MAT_VALUES};
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
/// Numeric array classes: double, single, int8 to uint64.
const NUMERIC_CLASSES: std::ops::RangeInclusive<u32> = 6..=15;

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
        let (scan, expanded) = scan(path, bytes, order, MAX_MAT_INFLATED_BYTES)?;
        let parsed = std::panic::catch_unwind(|| matfile::MatFile::parse(&expanded[..]));
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

/// Checks every top-level element's length against the file, inflates the compressed
/// ones (`inflate_limit` bytes at most in all), and looks inside every array for what
/// `matfile` would choke on or skip. Returns what it learnt and the file with each
/// compressed element replaced by the element it inflates to (the file itself when none
/// is compressed).
fn scan<'a>(
    path: &Path,
    bytes: &'a [u8],
    order: ByteOrder,
    inflate_limit: usize,
) -> Result<(Scan, Cow<'a, [u8]>), MeasurementError> {
    let mut scan = Scan::default();
    // Set at the first compressed element: everything before it, verbatim.
    let mut expanded: Option<Vec<u8>> = None;
    let mut inflated_total = 0usize;
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
        if tag.data_type == MI_COMPRESSED {
            let element =
                inflate_element(path, data, offset, order, inflate_limit - inflated_total)?;
            inflated_total += element.len();
            let inner = read_tag(&element, 0, order, true).expect("an inflated tag is whole");
            if inner.data_type == MI_MATRIX {
                let array = &element[inner.data_start..inner.data_start + inner.size];
                let place = format!("compressed array at offset {offset}");
                scan_array(path, array, &place, order, &mut scan)?;
            }
            expanded
                .get_or_insert_with(|| bytes[..offset].to_vec())
                .extend_from_slice(&element);
            offset = tag.data_start + tag.size;
            continue;
        }
        if tag.data_type == MI_MATRIX {
            let place = format!("array at offset {offset}");
            scan_array(path, data, &place, order, &mut scan)?;
        }
        if let Some(expanded) = &mut expanded {
            expanded.extend_from_slice(&bytes[offset..tag.next.min(bytes.len())]);
        }
        offset = tag.next;
    }
    let expanded = expanded.map_or(Cow::Borrowed(bytes), Cow::Owned);
    Ok((scan, expanded))
}

/// The data element the zlib stream `compressed` (the data of the element at `offset`)
/// inflates to, padded to 8 bytes as an uncompressed element is: its tag, then as many
/// bytes as the tag declares. What follows them in the stream is ignored, as `matfile`
/// ignores it. Refused when the element declares more than `limit` bytes, and the stream
/// is never read past what it declares, so a lying tag cannot make it inflate more.
fn inflate_element(
    path: &Path,
    compressed: &[u8],
    offset: usize,
    order: ByteOrder,
    limit: usize,
) -> Result<Vec<u8>, MeasurementError> {
    let corrupt = |detail: String| MeasurementError::MalformedMat {
        path: path.to_owned(),
        detail: format!("the compressed element at offset {offset} {detail}"),
    };
    let mut inflater = flate2::read::ZlibDecoder::new(compressed);
    let mut tag = [0u8; 8];
    inflater
        .read_exact(&mut tag)
        .map_err(|e| corrupt(format!("does not inflate to a data element ({e})")))?;
    let inner = read_tag(&tag, 0, order, true).expect("8 bytes hold a tag");
    if inner.data_type == MI_COMPRESSED {
        return Err(corrupt("holds another compressed element".to_owned()));
    }
    // A small element's data is inside its 8-byte tag.
    let small = inner.data_start < tag.len();
    if small && inner.size > tag.len() - inner.data_start {
        return Err(corrupt(format!(
            "inflates to a small data element of {} bytes (at most 4)",
            inner.size
        )));
    }
    let body = (inner.data_start + inner.size).saturating_sub(tag.len());
    let padded = inner.next.max(tag.len());
    if padded > limit {
        return Err(MeasurementError::MatTooLarge {
            path: path.to_owned(),
            detail: format!(
                "the compressed element at offset {offset} inflates to a {padded}-byte element, \
                 more than the {} bytes left of the {MAX_MAT_INFLATED_BYTES} bytes \
                 (MAX_MAT_INFLATED_BYTES) a MAT file may inflate to",
                limit
            ),
        });
    }
    // Read through `take(body)`: the bound below is never passed, what follows is not read.
    let data = read_to_end_bounded(inflater.take(body as u64), body).map_err(|e| match e {
        BoundedReadError::Io(e) => corrupt(format!("does not inflate ({e})")),
        BoundedReadError::TooLarge => corrupt(format!("inflates past its {body} bytes")),
    })?;
    if data.len() < body {
        return Err(MeasurementError::MatTruncated {
            path: path.to_owned(),
            detail: format!(
                "the compressed element at offset {offset} inflates to {} bytes of data but its \
                 element declares {body}",
                data.len()
            ),
        });
    }
    let mut element = Vec::with_capacity(padded);
    element.extend_from_slice(&tag);
    element.extend_from_slice(&data);
    element.resize(padded, 0);
    Ok(element)
}

/// Why [`read_to_end_bounded`] stopped.
#[derive(Debug)]
pub(crate) enum BoundedReadError {
    /// The reader yields more than the bound.
    TooLarge,
    Io(std::io::Error),
}

/// Reads `reader` to its end, refusing once it yields more than `limit` bytes. Memory
/// grows with what the reader really yields (doubling, capped at `limit`), never with
/// what anything claims it will yield; the reader is read through `take(limit + 1)`, so
/// one byte past the bound is the most ever inflated or read.
pub(crate) fn read_to_end_bounded(
    reader: impl Read,
    limit: usize,
) -> Result<Vec<u8>, BoundedReadError> {
    let mut reader = reader.take((limit as u64).saturating_add(1));
    let mut out: Vec<u8> = Vec::new();
    let mut chunk = [0u8; 16 << 10];
    loop {
        let n = match reader.read(&mut chunk) {
            Ok(0) => return Ok(out),
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(BoundedReadError::Io(e)),
        };
        if n > limit - out.len() {
            return Err(BoundedReadError::TooLarge);
        }
        if n > out.capacity() - out.len() {
            let capacity = out
                .capacity()
                .saturating_mul(2)
                .max(out.len() + n)
                .min(limit);
            out.reserve_exact(capacity - out.len());
        }
        out.extend_from_slice(&chunk[..n]);
    }
}

/// Checks the sub-elements of an uncompressed array (flags, dimensions, name, data)
/// and records arrays `matfile` would skip or fail on.
fn scan_array(
    path: &Path,
    array: &[u8],
    place: &str,
    order: ByteOrder,
    scan: &mut Scan,
) -> Result<(), MeasurementError> {
    let at = ArrayPlace { path, place };
    let mut class = None;
    let mut name = String::new();
    // Dimensions and value count of a numeric array over MAX_MAT_VALUES, refused once its
    // name is known (before `matfile` reads any of its values).
    let mut too_large: Option<(Vec<i64>, i64)> = None;
    let mut position = 0;
    let mut index = 0;
    while position < array.len() {
        let tag = read_tag(array, position, order, true)
            .filter(|tag| tag.size <= array.len().saturating_sub(tag.data_start))
            .ok_or_else(|| {
                at.malformed(format!(
                    "has a sub-element overrunning it at byte {position}"
                ))
            })?;
        let data = &array[tag.data_start..tag.data_start + tag.size];
        match index {
            0 => class = order.u32_at(data, 0).map(|flags| flags & 0xff),
            1 => {
                if let Some(oversized) = at.dimensions(data, order, class)? {
                    too_large = Some(oversized);
                }
            }
            2 => {
                name = String::from_utf8_lossy(data).into_owned();
                if let Some((dims, count)) = &too_large {
                    return Err(at.refuse(Some(&name), dims, *count));
                }
            }
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
    match too_large {
        Some((dims, count)) => Err(at.refuse(None, &dims, count)),
        None => Ok(()),
    }
}

/// The array [`scan_array`] is checking, named in its errors.
struct ArrayPlace<'p> {
    path: &'p Path,
    /// Where the array is, as the errors describe it.
    place: &'p str,
}

impl ArrayPlace<'_> {
    /// A malformed-file error saying `detail` about the array.
    fn malformed(&self, detail: String) -> MeasurementError {
        let place = self.place;
        MeasurementError::MalformedMat {
            path: self.path.to_owned(),
            detail: format!("the {place} {detail}"),
        }
    }

    /// The refusal of a numeric array of `count` values, over MAX_MAT_VALUES, naming
    /// the variable when its name is known.
    fn refuse(&self, name: Option<&str>, dims: &[i64], count: i64) -> MeasurementError {
        let place = self.place;
        let what = match name {
            Some(name) => format!("variable \"{name}\" ({place})"),
            None => format!("the {place}"),
        };
        MeasurementError::MatTooLarge {
            path: self.path.to_owned(),
            detail: format!(
                "{what} has dimensions {dims:?}, {count} values, more than the \
                 {MAX_MAT_VALUES} (MAX_MAT_VALUES) a variable may hold"
            ),
        }
    }

    /// Checks the dimensions sub-element `data` of an array of class `class`: the
    /// dimensions and value count when it is numeric and over MAX_MAT_VALUES (refused
    /// once its name is known), an error when they are invalid.
    fn dimensions(
        &self,
        data: &[u8],
        order: ByteOrder,
        class: Option<u32>,
    ) -> Result<Option<(Vec<i64>, i64)>, MeasurementError> {
        let dims: Vec<i64> = data
            .chunks_exact(4)
            .filter_map(|chunk| order.u32_at(chunk, 0))
            .map(|dim| i64::from(dim as i32))
            .collect();
        let count = dims.iter().try_fold(1i64, |count, &dim| {
            (dim >= 0).then(|| count.checked_mul(dim)).flatten()
        });
        match count {
            Some(count) if count <= i64::from(i32::MAX) => {
                let numeric = class.is_some_and(|class| NUMERIC_CLASSES.contains(&class));
                if numeric && count > MAX_MAT_VALUES as i64 {
                    return Ok(Some((dims, count)));
                }
                Ok(None)
            }
            _ => Err(self.malformed(format!("has invalid dimensions {dims:?}"))),
        }
    }
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

    /// A reader that counts the bytes it yields.
    struct Counted<R> {
        inner: R,
        yielded: usize,
    }

    impl<R: Read> Read for Counted<R> {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = self.inner.read(buf)?;
            self.yielded += n;
            Ok(n)
        }
    }

    fn zlib_zeros(zeros: usize) -> Vec<u8> {
        use std::io::Write;
        let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
        let chunk = vec![0u8; 1 << 20];
        let mut left = zeros;
        while left > 0 {
            let n = left.min(chunk.len());
            encoder.write_all(&chunk[..n]).unwrap();
            left -= n;
        }
        encoder.finish().unwrap()
    }

    #[test]
    fn bounded_reading_holds_at_most_the_bound_and_reads_one_byte_past_it() {
        let data = vec![7u8; 100_000];
        let read = read_to_end_bounded(&data[..], 100_000).expect("at the bound");
        assert_eq!(read, data);
        assert!(read.capacity() <= 100_000, "{}", read.capacity());
        let mut source = Counted {
            inner: &data[..],
            yielded: 0,
        };
        assert!(matches!(
            read_to_end_bounded(&mut source, 99_999),
            Err(BoundedReadError::TooLarge)
        ));
        assert!(source.yielded <= 100_000, "{}", source.yielded);
        // A zlib bomb: 64 MiB of zeros in about 64 KB, read with a 1 MiB bound.
        let bomb = zlib_zeros(64 << 20);
        assert!(bomb.len() < 128 << 10, "{}", bomb.len());
        let mut inflater = Counted {
            inner: flate2::read::ZlibDecoder::new(&bomb[..]),
            yielded: 0,
        };
        assert!(matches!(
            read_to_end_bounded(&mut inflater, 1 << 20),
            Err(BoundedReadError::TooLarge)
        ));
        assert!(
            inflater.yielded <= (1 << 20) + (16 << 10),
            "{}",
            inflater.yielded
        );
        let small = read_to_end_bounded(flate2::read::ZlibDecoder::new(&bomb[..]), 64 << 20)
            .expect("within the bound");
        assert_eq!(small.len(), 64 << 20);
        assert!(small.capacity() <= 64 << 20);
    }

    #[test]
    fn compressed_elements_are_inflated_within_the_file_limit() {
        let file = example(Order::Little, true);
        let plain = example(Order::Little, false);
        let (_, expanded) =
            scan(&path(), &file, ByteOrder::Little, MAX_MAT_INFLATED_BYTES).expect("valid");
        // Inflated, the compressed file is the plain one.
        assert_eq!(&expanded[..], &plain[..]);
        let (_, unchanged) =
            scan(&path(), &plain, ByteOrder::Little, MAX_MAT_INFLATED_BYTES).expect("valid");
        assert!(matches!(unchanged, Cow::Borrowed(_)));
        // The same file with a bound smaller than what it inflates to.
        let error = scan(&path(), &file, ByteOrder::Little, 200).expect_err("over the limit");
        assert!(
            matches!(error, MeasurementError::MatTooLarge { .. }),
            "{error}"
        );
        assert!(
            error.to_string().contains("MAX_MAT_INFLATED_BYTES"),
            "{error}"
        );
    }

    #[test]
    fn numeric_arrays_past_the_value_limit_are_refused_naming_the_variable() {
        // 4097 × 4097 = 16,785,409 values, over MAX_MAT_VALUES; the values are not there.
        for compressed in [false, true] {
            let writer = V5Writer::new(Order::Little);
            let writer = if compressed {
                writer.compressed()
            } else {
                writer
            };
            let bytes = writer
                .double("time", &[2, 1], &[0.0, 1.0])
                .double("huge", &[4097, 4097], &[1.0])
                .finish();
            let error = load(&bytes, "time", &[]).expect_err("too many values");
            let message = error.to_string();
            assert!(
                matches!(error, MeasurementError::MatTooLarge { .. }),
                "{message}"
            );
            assert!(message.contains("variable \"huge\""), "{message}");
            assert!(message.contains("MAX_MAT_VALUES"), "{message}");
        }
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
