//! What reading a measurement file may allocate. An allocator of this test counts the
//! bytes each thread holds while it reads a file and refuses (the process then aborts)
//! any allocation past [`CAP`], so a reader that trusts a size it was told, or inflates
//! without a bound, fails here without ever taking the memory it asks for.
//!
//! * A MAT v5 zlib bomb (1 MB inflating to 512 MiB) and a compressed element that inflates
//!   far past the size it declares are refused, holding little more than the file.
//! * Arbitrary bytes and mutated valid files (CSV, MAT v4, MAT v5 plain and compressed,
//!   Modelica result files) never make a reader hold more than a small multiple of the
//!   file's size.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::io::Write;
use std::path::Path;

use calib_engine::measurement::{Measurement, MeasurementError};
use proptest::prelude::*;
use proptest::sample::Index;

#[path = "../src/measurement/testdata.rs"]
#[allow(dead_code)]
mod testdata;

use testdata::{ByteOrder, ResultFile, V5Writer, V4};

/// Most bytes a thread may hold while it reads a file under [`held_while`]: far above
/// what the reads here need, far below what an unbounded reader asks for.
const CAP: usize = 64 << 20;

thread_local! {
    /// Bytes this thread holds while measured, and the most it held.
    static HELD: Cell<usize> = const { Cell::new(0) };
    static PEAK: Cell<usize> = const { Cell::new(0) };
    static MEASURED: Cell<bool> = const { Cell::new(false) };
}

struct Counting;

impl Counting {
    /// Count `size` more bytes held; false when that passes the cap.
    fn take(size: usize) -> bool {
        if !MEASURED.with(Cell::get) {
            return true;
        }
        let held = HELD.with(Cell::get).saturating_add(size);
        if held > CAP {
            return false;
        }
        HELD.with(|h| h.set(held));
        PEAK.with(|p| p.set(p.get().max(held)));
        true
    }

    fn give_back(size: usize) {
        if MEASURED.with(Cell::get) {
            HELD.with(|h| h.set(h.get().saturating_sub(size)));
        }
    }
}

// SAFETY: every call is passed on to the system allocator; only counting is added.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if !Self::take(layout.size()) {
            return std::ptr::null_mut();
        }
        System.alloc(layout)
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        if !Self::take(layout.size()) {
            return std::ptr::null_mut();
        }
        System.alloc_zeroed(layout)
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        Self::give_back(layout.size());
        System.dealloc(ptr, layout)
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        if new_size > layout.size() && !Self::take(new_size - layout.size()) {
            return std::ptr::null_mut();
        }
        let moved = System.realloc(ptr, layout, new_size);
        if moved.is_null() {
            if new_size > layout.size() {
                Self::give_back(new_size - layout.size());
            }
        } else if new_size < layout.size() {
            Self::give_back(layout.size() - new_size);
        }
        moved
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// What `read` returns and the most bytes this thread held while it ran (what it
/// allocated and had not yet freed).
fn held_while<T>(read: impl FnOnce() -> T) -> (T, usize) {
    HELD.with(|h| h.set(0));
    PEAK.with(|p| p.set(0));
    MEASURED.with(|m| m.set(true));
    let value = read();
    MEASURED.with(|m| m.set(false));
    (value, PEAK.with(Cell::get))
}

const TIME: &str = "time";
const COLUMNS: [&str; 2] = ["x", "y"];

fn read(name: &str, bytes: &[u8]) -> (Result<Measurement, MeasurementError>, usize) {
    held_while(|| Measurement::from_bytes(Path::new(name), bytes, TIME, &COLUMNS))
}

/// The zlib stream of `prefix` then `zeros` zero bytes, compressed as hard as deflate can.
fn zlib(prefix: &[u8], zeros: usize) -> Vec<u8> {
    let mut encoder = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::best());
    encoder.write_all(prefix).unwrap();
    let chunk = vec![0u8; 1 << 20];
    let mut left = zeros;
    while left > 0 {
        let n = left.min(chunk.len());
        encoder.write_all(&chunk[..n]).unwrap();
        left -= n;
    }
    encoder.finish().unwrap()
}

/// A miMATRIX element of class double, `rows`×1, named `name`, little-endian: its tag
/// and sub-elements up to the tag of its values; `rows * 8` bytes of values follow.
fn double_matrix_start(name: &str, rows: u32) -> Vec<u8> {
    let tag = |out: &mut Vec<u8>, data_type: u32, size: u32| {
        out.extend_from_slice(&data_type.to_le_bytes());
        out.extend_from_slice(&size.to_le_bytes());
    };
    let mut sub = Vec::new();
    tag(&mut sub, 6, 8); // miUINT32 array flags
    sub.extend_from_slice(&6u32.to_le_bytes()); // class double
    sub.extend_from_slice(&0u32.to_le_bytes());
    tag(&mut sub, 5, 8); // miINT32 dimensions
    sub.extend_from_slice(&rows.to_le_bytes());
    sub.extend_from_slice(&1u32.to_le_bytes());
    let mut padded_name = name.as_bytes().to_vec();
    tag(&mut sub, 1, padded_name.len() as u32); // miINT8 name
    padded_name.resize(padded_name.len().next_multiple_of(8), 0);
    sub.extend_from_slice(&padded_name);
    let values = rows * 8;
    tag(&mut sub, 9, values); // miDOUBLE values
    let mut element = Vec::new();
    tag(&mut element, 14, sub.len() as u32 + values);
    element.extend_from_slice(&sub);
    element
}

/// A MAT v5 file whose one variable is the compressed `stream`.
fn compressed_file(stream: &[u8]) -> Vec<u8> {
    let mut file = testdata::header(ByteOrder::Little, 0x0100, "MATLAB 5.0 MAT-file");
    file.extend_from_slice(&15u32.to_le_bytes());
    file.extend_from_slice(&(stream.len() as u32).to_le_bytes());
    file.extend_from_slice(stream);
    file
}

#[test]
fn a_zlib_bomb_is_refused_holding_little_more_than_the_file() {
    // 2^26 doubles of zeros: a 512 MiB variable, honestly declared, in about 512 KB.
    let rows = 1u32 << 26;
    let bomb = compressed_file(&zlib(&double_matrix_start(TIME, rows), rows as usize * 8));
    assert!(bomb.len() < 2 << 20, "{} bytes", bomb.len());
    let (outcome, held) = read("bomb.mat", &bomb);
    let message = outcome.expect_err("refused").to_string();
    assert!(
        message.starts_with("bomb.mat: MAT file is too large"),
        "{message}"
    );
    assert!(message.contains("MAX_MAT_INFLATED_BYTES"), "{message}");
    assert!(held < 1 << 20, "held {held} bytes");
}

#[test]
fn an_element_inflating_past_what_it_declares_is_read_no_further() {
    // A 4-sample time vector, then 256 MiB of zeros the element does not declare.
    let mut element = double_matrix_start(TIME, 4);
    for t in [0.0f64, 1.0, 2.0, 3.0] {
        element.extend_from_slice(&t.to_le_bytes());
    }
    let liar = compressed_file(&zlib(&element, 256 << 20));
    let (outcome, held) =
        held_while(|| Measurement::from_bytes(Path::new("liar.mat"), &liar, TIME, &[]));
    let measurement = outcome.expect("the declared element is read");
    assert_eq!(measurement.time, vec![0.0, 1.0, 2.0, 3.0]);
    assert!(held < 1 << 20, "held {held} bytes");
}

#[test]
fn a_declared_size_under_the_limit_is_not_allocated_before_it_is_inflated() {
    // Declares 2^24 doubles (128 MiB, under every limit) but holds 64 bytes of them.
    let element = double_matrix_start(TIME, 1 << 24);
    let mut stream = zlib(&element, 64);
    stream.truncate(stream.len() - 4); // no checksum: the stream just ends
    let (outcome, held) = read("short.mat", &compressed_file(&stream));
    let error = outcome.expect_err("refused");
    assert!(
        matches!(
            error,
            MeasurementError::MatTruncated { .. } | MeasurementError::MalformedMat { .. }
        ),
        "{error}"
    );
    assert!(held < 1 << 20, "held {held} bytes");
}

/// The fixtures, each with the name it is read under: every format, and a compressed
/// variable of zeros that inflates 1,000-fold.
fn valid_files() -> Vec<(&'static str, Vec<u8>)> {
    let time = [0.0, 0.25, 0.5, 1.0];
    let x = [1.0, -2.0, 3.5, 4.0];
    let y = [0.0, 0.5, 0.25, -1.0];
    let mut files = vec![(
        "rig.csv",
        b"# rig 3\ntime,x,\"y\"\n0,1,0\n0.25,-2,0.5\n0.5,3.5,0.25\n1,4,-1\n".to_vec(),
    )];
    for (name, order) in [("le4.mat", ByteOrder::Little), ("be4.mat", ByteOrder::Big)] {
        let writer = V4::new(order);
        let mut file = Vec::new();
        writer.double(&mut file, TIME, 4, 1, &time);
        writer.matrix(&mut file, "x", testdata::precision::SINGLE, 1, 4, &x);
        writer.matrix(&mut file, "y", testdata::precision::DOUBLE, 4, 1, &y);
        files.push((name, file));
    }
    for (name, compressed) in [("plain5.mat", false), ("zipped5.mat", true)] {
        let writer = V5Writer::new(ByteOrder::Little);
        let writer = if compressed {
            writer.compressed()
        } else {
            writer
        };
        let file = writer
            .double(TIME, &[4, 1], &time)
            .double("x", &[1, 4], &x)
            .double("y", &[4, 1], &y)
            .finish();
        files.push((name, file));
    }
    {
        let mut file = V5Writer::new(ByteOrder::Little)
            .double(TIME, &[4, 1], &time)
            .double("x", &[1, 4], &x)
            .double("y", &[4, 1], &y)
            .finish();
        let zeros = 1 << 16;
        let stream = zlib(&double_matrix_start("zeros", zeros), zeros as usize * 8);
        file.extend_from_slice(&15u32.to_le_bytes());
        file.extend_from_slice(&(stream.len() as u32).to_le_bytes());
        file.extend_from_slice(&stream);
        files.push(("zeros5.mat", file));
    }
    for (name, transposed) in [("normal.mat", false), ("trans.mat", true)] {
        let rows: Vec<[f64; 3]> = (0..4).map(|i| [time[i], x[i], y[i]]).collect();
        let mut result = ResultFile::example(ByteOrder::Big, transposed, &rows);
        result.variables = vec![
            (TIME.to_owned(), [0, 1, 0, -1]),
            ("m".to_owned(), [1, 2, 0, 0]),
            ("x".to_owned(), [2, 2, 0, -1]),
            ("y".to_owned(), [2, 3, 0, -1]),
        ];
        files.push((name, result.write()));
    }
    files
}

/// Most bytes a read of `len` bytes may hold: a few times the file, what the zeros
/// fixture inflates to, and a constant for the parsers' buffers.
fn bound(len: usize) -> usize {
    8 * len + (1 << 16) * 8 * 3 + (2 << 20)
}

/// A change to a file's bytes: one overwritten, a 32-bit field (length, dimension, type)
/// set to an extreme value, bytes cut or inserted.
#[derive(Debug, Clone)]
enum Mutation {
    Overwrite(Index, u8),
    Field(Index, u32, bool),
    Truncate(Index),
    Insert(Index, Vec<u8>),
}

impl Mutation {
    fn apply(&self, bytes: &mut Vec<u8>) {
        let at = |index: &Index, len: usize| if len == 0 { 0 } else { index.index(len) };
        match self {
            Mutation::Overwrite(index, byte) => {
                if !bytes.is_empty() {
                    let i = at(index, bytes.len());
                    bytes[i] = *byte;
                }
            }
            Mutation::Field(index, value, big) => {
                let encoded = if *big {
                    value.to_be_bytes()
                } else {
                    value.to_le_bytes()
                };
                let start = at(index, bytes.len());
                for (offset, byte) in encoded.into_iter().enumerate() {
                    if let Some(target) = bytes.get_mut(start + offset) {
                        *target = byte;
                    }
                }
            }
            Mutation::Truncate(index) => bytes.truncate(at(index, bytes.len())),
            Mutation::Insert(index, inserted) => {
                let start = at(index, bytes.len() + 1);
                bytes.splice(start..start, inserted.iter().copied());
            }
        }
    }
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let extreme = prop_oneof![
        Just(0u32),
        Just(8),
        Just(0x7fff_ffff),
        Just(u32::MAX),
        Just(1 << 20),
        Just(1 << 24),
        Just(1 << 28),
        any::<u32>(),
    ];
    prop_oneof![
        3 => (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Mutation::Overwrite(i, b)),
        4 => (any::<Index>(), extreme, any::<bool>()).prop_map(|(i, v, big)| Mutation::Field(i, v, big)),
        1 => any::<Index>().prop_map(Mutation::Truncate),
        1 => (any::<Index>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(i, bytes)| Mutation::Insert(i, bytes)),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 192, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_are_read_within_a_bound(
        bytes in prop::collection::vec(any::<u8>(), 0..1024),
        name in prop::sample::select(vec!["a.csv", "a.mat", "a"]),
    ) {
        let (_, held) = read(name, &bytes);
        prop_assert!(held <= bound(bytes.len()), "held {} bytes", held);
    }

    #[test]
    fn mutated_valid_files_are_read_within_a_bound(
        file in any::<Index>(),
        mutations in prop::collection::vec(mutation(), 1..4),
    ) {
        let files = valid_files();
        let (name, valid) = &files[file.index(files.len())];
        let mut bytes = valid.clone();
        for mutation in &mutations {
            mutation.apply(&mut bytes);
        }
        let (outcome, held) = read(name, &bytes);
        prop_assert!(held <= bound(bytes.len()), "{}: held {} bytes", name, held);
        if let Err(error) = outcome {
            prop_assert!(error.to_string().starts_with(*name), "{}", error);
        }
    }
}

#[test]
fn the_fixtures_are_valid() {
    for (name, bytes) in valid_files() {
        let loaded = Measurement::from_bytes(Path::new(name), &bytes, TIME, &COLUMNS)
            .unwrap_or_else(|error| panic!("{name}: {error}"));
        assert_eq!(loaded.time, vec![0.0, 0.25, 0.5, 1.0], "{name}");
    }
}
