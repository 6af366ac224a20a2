//! Writers for the MAT fixtures of the tests, so that no binary fixture needs to be
//! committed. They write just enough of each format to exercise the readers.

/// Byte order of a written file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ByteOrder {
    Little,
    Big,
}

impl ByteOrder {
    pub const BOTH: [ByteOrder; 2] = [ByteOrder::Little, ByteOrder::Big];

    fn u16(self, value: u16) -> [u8; 2] {
        match self {
            ByteOrder::Little => value.to_le_bytes(),
            ByteOrder::Big => value.to_be_bytes(),
        }
    }

    fn i32(self, value: i32) -> [u8; 4] {
        match self {
            ByteOrder::Little => value.to_le_bytes(),
            ByteOrder::Big => value.to_be_bytes(),
        }
    }

    fn u32(self, value: u32) -> [u8; 4] {
        self.i32(value as i32)
    }
}

/// MAT v4 precision codes (the `P` digit of the matrix type).
pub mod precision {
    pub const DOUBLE: u8 = 0;
    pub const SINGLE: u8 = 1;
    pub const INT32: u8 = 2;
    pub const INT16: u8 = 3;
    pub const UINT16: u8 = 4;
    pub const UINT8: u8 = 5;
}

/// Writes MAT v4 matrices.
#[derive(Debug, Clone, Copy)]
pub struct V4 {
    order: ByteOrder,
}

impl V4 {
    pub fn new(order: ByteOrder) -> Self {
        V4 { order }
    }

    /// Writes the 20-byte header (type = M·1000 + P·10 + T) and the name.
    pub fn header(
        &self,
        out: &mut Vec<u8>,
        type_code: i32,
        rows: i32,
        cols: i32,
        complex: bool,
        name: &str,
    ) {
        let machine = match self.order {
            ByteOrder::Little => 0,
            ByteOrder::Big => 1000,
        };
        for field in [
            machine + type_code,
            rows,
            cols,
            i32::from(complex),
            name.len() as i32 + 1,
        ] {
            out.extend_from_slice(&self.order.i32(field));
        }
        out.extend_from_slice(name.as_bytes());
        out.push(0);
    }

    /// Writes `values`, column-major, in the given precision.
    pub fn values(&self, out: &mut Vec<u8>, precision: u8, values: &[f64]) {
        let order = self.order;
        for &value in values {
            match precision {
                precision::DOUBLE => out.extend_from_slice(&match order {
                    ByteOrder::Little => value.to_le_bytes(),
                    ByteOrder::Big => value.to_be_bytes(),
                }),
                precision::SINGLE => out.extend_from_slice(&match order {
                    ByteOrder::Little => (value as f32).to_le_bytes(),
                    ByteOrder::Big => (value as f32).to_be_bytes(),
                }),
                precision::INT32 => out.extend_from_slice(&order.i32(value as i32)),
                precision::INT16 => out.extend_from_slice(&match order {
                    ByteOrder::Little => (value as i16).to_le_bytes(),
                    ByteOrder::Big => (value as i16).to_be_bytes(),
                }),
                precision::UINT16 => out.extend_from_slice(&order.u16(value as u16)),
                precision::UINT8 => out.push(value as u8),
                other => panic!("no MAT v4 precision {other}"),
            }
        }
    }

    /// A real numeric matrix of `rows`×`cols` values, given column-major.
    pub fn matrix(
        &self,
        out: &mut Vec<u8>,
        name: &str,
        precision: u8,
        rows: usize,
        cols: usize,
        values: &[f64],
    ) {
        assert_eq!(
            rows * cols,
            values.len(),
            "{name}: shape and values disagree"
        );
        self.header(
            out,
            i32::from(precision) * 10,
            rows as i32,
            cols as i32,
            false,
            name,
        );
        self.values(out, precision, values);
    }

    pub fn double(&self, out: &mut Vec<u8>, name: &str, rows: usize, cols: usize, values: &[f64]) {
        self.matrix(out, name, precision::DOUBLE, rows, cols, values);
    }

    /// A text matrix holding `strings` as rows, or as columns when `as_columns` (the
    /// binTrans layout), padded with NULs, stored as uint8.
    pub fn text(&self, out: &mut Vec<u8>, name: &str, strings: &[&str], as_columns: bool) {
        let width = strings.iter().map(|s| s.len()).max().unwrap_or(0);
        let padded: Vec<Vec<u8>> = strings
            .iter()
            .map(|s| {
                let mut bytes = s.as_bytes().to_vec();
                bytes.resize(width, 0);
                bytes
            })
            .collect();
        let (rows, cols, values): (usize, usize, Vec<f64>) = if as_columns {
            let values = padded.iter().flatten().map(|&b| f64::from(b)).collect();
            (width, strings.len(), values)
        } else {
            let mut values = Vec::with_capacity(width * strings.len());
            for column in 0..width {
                for string in &padded {
                    values.push(f64::from(string[column]));
                }
            }
            (strings.len(), width, values)
        };
        self.header(
            out,
            i32::from(precision::UINT8) * 10 + 1,
            rows as i32,
            cols as i32,
            false,
            name,
        );
        self.values(out, precision::UINT8, &values);
    }

    /// Stores a logical matrix (`rows[r][c]`), transposed when `transposed`.
    pub fn table(
        &self,
        out: &mut Vec<u8>,
        name: &str,
        precision: u8,
        rows: &[Vec<f64>],
        transposed: bool,
    ) {
        let row_count = rows.len();
        let col_count = rows.first().map_or(0, Vec::len);
        if transposed {
            let values: Vec<f64> = rows.iter().flatten().copied().collect();
            self.matrix(out, name, precision, col_count, row_count, &values);
        } else {
            let mut values = Vec::with_capacity(row_count * col_count);
            for column in 0..col_count {
                for row in rows {
                    values.push(row[column]);
                }
            }
            self.matrix(out, name, precision, row_count, col_count, &values);
        }
    }
}

/// A Modelica result file (`Aclass`, `name`, `description`, `dataInfo`, `data_1`,
/// `data_2`) as logical tables; [`ResultFile::write`] lays them out.
#[derive(Debug, Clone)]
pub struct ResultFile {
    pub order: ByteOrder,
    /// binTrans layout: every matrix but `Aclass` stored transposed.
    pub transposed: bool,
    /// Name and `dataInfo` row of each variable.
    pub variables: Vec<(String, [i32; 4])>,
    /// Parameters: one row per time point (first and last).
    pub data_1: Vec<Vec<f64>>,
    /// Time-varying data: one row per time point, time first.
    pub data_2: Vec<Vec<f64>>,
    pub data_precision: u8,
}

impl ResultFile {
    /// The small model the tests use: `time`, a parameter `m` = 2.5, a state `x`, its
    /// negated alias `y = -x`, and `der(x)`, sampled at the given rows of
    /// (time, x, der(x)).
    pub fn example(order: ByteOrder, transposed: bool, samples: &[[f64; 3]]) -> Self {
        let variables = [
            ("time", [0, 1, 0, -1]),
            ("m", [1, 2, 0, 0]),
            ("x", [2, 2, 0, -1]),
            ("y", [2, -2, 0, -1]),
            ("der(x)", [2, 3, 0, -1]),
        ];
        let first = samples.first().map_or(0.0, |row| row[0]);
        let last = samples.last().map_or(0.0, |row| row[0]);
        ResultFile {
            order,
            transposed,
            variables: variables
                .iter()
                .map(|(name, info)| ((*name).to_owned(), *info))
                .collect(),
            data_1: vec![vec![first, 2.5], vec![last, 2.5]],
            data_2: samples.iter().map(|row| row.to_vec()).collect(),
            data_precision: precision::DOUBLE,
        }
    }

    pub fn write(&self) -> Vec<u8> {
        let writer = V4::new(self.order);
        let layout = if self.transposed {
            "binTrans"
        } else {
            "binNormal"
        };
        let names: Vec<&str> = self.variables.iter().map(|(n, _)| n.as_str()).collect();
        let descriptions: Vec<String> = names.iter().map(|n| format!("{n} [-]")).collect();
        let descriptions: Vec<&str> = descriptions.iter().map(String::as_str).collect();
        let info: Vec<Vec<f64>> = self
            .variables
            .iter()
            .map(|(_, info)| info.iter().map(|&v| f64::from(v)).collect())
            .collect();
        let mut out = Vec::new();
        writer.text(
            &mut out,
            "Aclass",
            &["Atrajectory", "1.1", "", layout],
            false,
        );
        writer.text(&mut out, "name", &names, self.transposed);
        writer.text(&mut out, "description", &descriptions, self.transposed);
        writer.table(
            &mut out,
            "dataInfo",
            precision::INT32,
            &info,
            self.transposed,
        );
        writer.table(
            &mut out,
            "data_1",
            self.data_precision,
            &self.data_1,
            self.transposed,
        );
        writer.table(
            &mut out,
            "data_2",
            self.data_precision,
            &self.data_2,
            self.transposed,
        );
        out
    }
}

/// MAT v5 array classes the writer knows.
const CLASS_CHAR: u32 = 4;
const CLASS_DOUBLE: u32 = 6;
const CLASS_SINGLE: u32 = 7;
const CLASS_INT32: u32 = 12;
const CLASS_UINT8: u32 = 9;

/// MAT v5 data types.
const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
const MI_UTF16: u32 = 17;

/// Writes a MAT v5 file: the 128-byte header, then one miMATRIX element per variable,
/// each optionally wrapped in a miCOMPRESSED element.
#[derive(Debug, Clone)]
pub struct V5Writer {
    order: ByteOrder,
    compress: bool,
    body: Vec<u8>,
}

impl V5Writer {
    pub fn new(order: ByteOrder) -> Self {
        V5Writer {
            order,
            compress: false,
            body: Vec::new(),
        }
    }

    /// Wraps the variables added from now on in miCOMPRESSED elements.
    pub fn compressed(mut self) -> Self {
        self.compress = true;
        self
    }

    pub fn double(self, name: &str, dims: &[i32], values: &[f64]) -> Self {
        let bytes = self.encode(values, |v| match self.order {
            ByteOrder::Little => v.to_le_bytes(),
            ByteOrder::Big => v.to_be_bytes(),
        });
        self.array(name, CLASS_DOUBLE, dims, MI_DOUBLE, &bytes, None)
    }

    pub fn complex_double(self, name: &str, dims: &[i32], real: &[f64], imag: &[f64]) -> Self {
        let encode = |v: &f64| match self.order {
            ByteOrder::Little => v.to_le_bytes(),
            ByteOrder::Big => v.to_be_bytes(),
        };
        let real = self.encode(real, encode);
        let imag = self.encode(imag, encode);
        self.array(name, CLASS_DOUBLE, dims, MI_DOUBLE, &real, Some(&imag))
    }

    pub fn single(self, name: &str, dims: &[i32], values: &[f32]) -> Self {
        let bytes = self.encode(values, |v| match self.order {
            ByteOrder::Little => v.to_le_bytes(),
            ByteOrder::Big => v.to_be_bytes(),
        });
        self.array(name, CLASS_SINGLE, dims, MI_SINGLE, &bytes, None)
    }

    /// A double array stored as uint8, as MATLAB does for small whole numbers.
    pub fn double_as_uint8(self, name: &str, dims: &[i32], values: &[u8]) -> Self {
        self.array(name, CLASS_DOUBLE, dims, MI_UINT8, values, None)
    }

    pub fn uint8(self, name: &str, dims: &[i32], values: &[u8]) -> Self {
        self.array(name, CLASS_UINT8, dims, MI_UINT8, values, None)
    }

    pub fn int32(self, name: &str, dims: &[i32], values: &[i32]) -> Self {
        let bytes = self.encode(values, |v| self.order.i32(*v));
        self.array(name, CLASS_INT32, dims, MI_INT32, &bytes, None)
    }

    pub fn chars(self, name: &str, text: &str) -> Self {
        let units: Vec<u16> = text.encode_utf16().collect();
        let bytes = self.encode(&units, |v| self.order.u16(*v));
        let dims = [1, units.len() as i32];
        self.array(name, CLASS_CHAR, &dims, MI_UTF16, &bytes, None)
    }

    /// Appends raw bytes after the elements written so far.
    pub fn raw(mut self, bytes: &[u8]) -> Self {
        self.body.extend_from_slice(bytes);
        self
    }

    pub fn finish(self) -> Vec<u8> {
        let mut out = header(
            self.order,
            0x0100,
            "MATLAB 5.0 MAT-file, written by the calib tests",
        );
        out.extend_from_slice(&self.body);
        out
    }

    fn encode<T, const N: usize>(&self, values: &[T], encode: impl Fn(&T) -> [u8; N]) -> Vec<u8> {
        values.iter().flat_map(encode).collect()
    }

    fn tag(&self, out: &mut Vec<u8>, data_type: u32, size: usize) {
        out.extend_from_slice(&self.order.u32(data_type));
        out.extend_from_slice(&self.order.u32(size as u32));
    }

    fn sub_element(&self, out: &mut Vec<u8>, data_type: u32, data: &[u8]) {
        if !data.is_empty() && data.len() <= 4 {
            // Small data element: size and type share the first four bytes.
            out.extend_from_slice(&self.order.u32(((data.len() as u32) << 16) | data_type));
            out.extend_from_slice(data);
            out.resize(out.len() + 4 - data.len(), 0);
        } else {
            self.tag(out, data_type, data.len());
            out.extend_from_slice(data);
            out.resize(out.len().next_multiple_of(8), 0);
        }
    }

    fn array(
        mut self,
        name: &str,
        class: u32,
        dims: &[i32],
        data_type: u32,
        real: &[u8],
        imag: Option<&[u8]>,
    ) -> Self {
        let mut payload = Vec::new();
        let complex_flag = if imag.is_some() { 0x0800 } else { 0 };
        let mut flags = Vec::new();
        flags.extend_from_slice(&self.order.u32(class | complex_flag));
        flags.extend_from_slice(&self.order.u32(0));
        self.sub_element(&mut payload, MI_UINT32, &flags);
        let dims: Vec<u8> = dims.iter().flat_map(|&d| self.order.i32(d)).collect();
        self.sub_element(&mut payload, MI_INT32, &dims);
        self.sub_element(&mut payload, MI_INT8, name.as_bytes());
        self.sub_element(&mut payload, data_type, real);
        if let Some(imag) = imag {
            self.sub_element(&mut payload, data_type, imag);
        }
        let mut element = Vec::new();
        self.tag(&mut element, MI_MATRIX, payload.len());
        element.extend_from_slice(&payload);
        if self.compress {
            let compressed = zlib_stored(&element);
            let mut wrapper = Vec::new();
            self.tag(&mut wrapper, MI_COMPRESSED, compressed.len());
            wrapper.extend_from_slice(&compressed);
            self.body.extend_from_slice(&wrapper);
        } else {
            self.body.extend_from_slice(&element);
        }
        self
    }
}

/// The 128-byte MAT v5 header with the given version field.
pub fn header(order: ByteOrder, version: u16, text: &str) -> Vec<u8> {
    let mut out = text.as_bytes().to_vec();
    out.resize(116, b' ');
    out.extend_from_slice(&[0; 8]);
    out.extend_from_slice(&order.u16(version));
    out.extend_from_slice(&order.u16(u16::from_be_bytes(*b"MI")));
    out
}

/// What a MAT v7.3 file starts with: a v5-style header with version 0x0200, then HDF5.
pub fn mat73_start() -> Vec<u8> {
    let mut out = header(
        ByteOrder::Little,
        0x0200,
        "MATLAB 7.3 MAT-file, Platform: GLNXA64, HDF5 schema 1.00 .",
    );
    out.resize(512, 0);
    out.extend_from_slice(b"\x89HDF\r\n\x1a\n");
    out.resize(1024, 0);
    out
}

/// A zlib stream holding `data` in stored (uncompressed) deflate blocks: valid input
/// for any inflater, no compressor needed.
fn zlib_stored(data: &[u8]) -> Vec<u8> {
    let mut out = vec![0x78, 0x01];
    let chunks: Vec<&[u8]> = data.chunks(0xffff).collect();
    if chunks.is_empty() {
        out.extend_from_slice(&[1, 0, 0, 0xff, 0xff]);
    }
    for (index, chunk) in chunks.iter().enumerate() {
        out.push(u8::from(index + 1 == chunks.len()));
        let length = chunk.len() as u16;
        out.extend_from_slice(&length.to_le_bytes());
        out.extend_from_slice(&(!length).to_le_bytes());
        out.extend_from_slice(chunk);
    }
    let (mut a, mut b) = (1u32, 0u32);
    for &byte in data {
        a = (a + u32::from(byte)) % 65521;
        b = (b + a) % 65521;
    }
    out.extend_from_slice(&((b << 16) | a).to_be_bytes());
    out
}

/// Deterministic pseudo-random numbers for the mangling tests.
pub struct Xorshift(u64);

impl Xorshift {
    pub fn new(seed: u64) -> Self {
        Xorshift(seed.max(1))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        self.0
    }

    pub fn below(&mut self, bound: usize) -> usize {
        (self.next_u64() % bound.max(1) as u64) as usize
    }
}

/// Variants of `valid` for robustness tests: every truncation, and copies with a few
/// bytes overwritten (biased towards headers, where the lengths live).
pub fn mangled(valid: &[u8], seed: u64, count: usize) -> Vec<Vec<u8>> {
    let mut random = Xorshift::new(seed);
    let mut variants: Vec<Vec<u8>> = (0..valid.len()).map(|cut| valid[..cut].to_vec()).collect();
    for _ in 0..count {
        let mut bytes = valid.to_vec();
        for _ in 0..=random.below(3) {
            let span = if random.below(2) == 0 {
                200
            } else {
                bytes.len()
            };
            let index = random.below(span.min(bytes.len()));
            bytes[index] = match random.below(4) {
                0 => 0xff,
                1 => 0,
                _ => random.next_u64() as u8,
            };
        }
        variants.push(bytes);
    }
    variants
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zlib_stored_stream_has_a_valid_header_and_checksum() {
        let stream = zlib_stored(b"Wikipedia");
        assert_eq!((u16::from(stream[0]) << 8 | u16::from(stream[1])) % 31, 0);
        // Adler-32 of "Wikipedia" is 0x11E60398.
        assert_eq!(&stream[stream.len() - 4..], &[0x11, 0xE6, 0x03, 0x98]);
    }

    #[test]
    fn v5_header_marks_the_byte_order() {
        assert_eq!(
            &header(ByteOrder::Little, 0x0100, "x")[124..],
            b"\x00\x01IM"
        );
        assert_eq!(&header(ByteOrder::Big, 0x0100, "x")[124..], b"\x01\x00MI");
    }
}
