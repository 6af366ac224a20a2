//! Property tests of the measurement readers: whatever the bytes, a reader returns
//! either a measurement that obeys the rules of [`Measurement`] or an error that names
//! the file and says what is wrong. It never panics, and never allocates beyond what
//! the file's size justifies.
//!
//! Inputs are arbitrary bytes under every file name the formats are chosen by, and
//! valid files of every format (CSV, MAT v4 in both byte orders, MAT v5 plain and
//! compressed, Modelica result files in both layouts) mutated where their lengths and
//! types live: bytes overwritten, 32-bit fields replaced by extreme values, bytes cut,
//! inserted and removed.

use std::path::{Path, PathBuf};

use proptest::prelude::*;
use proptest::sample::Index;

use super::testdata::{self, ByteOrder, ResultFile, V5Writer, V4};
use super::{Measurement, MeasurementError};

/// Few cases: the tests run in debug builds too, and every case parses a whole file.
const CASES: u32 = 256;

/// The columns every valid fixture holds: `time`, `x`, `y`.
const TIME: &str = "time";
const COLUMNS: [&str; 2] = ["x", "y"];

/// The fixtures, each with the name it is read under.
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
        let x32: Vec<f32> = x.iter().map(|&v| v as f32).collect();
        let file = writer
            .double(TIME, &[4, 1], &time)
            .single("x", &[1, 4], &x32)
            .double("y", &[4, 1], &y)
            .chars("note", "ab")
            .finish();
        files.push((name, file));
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
        let file = result.write();
        files.push((name, file));
    }
    files
}

/// A change to a file's bytes.
#[derive(Debug, Clone)]
enum Mutation {
    Overwrite(Index, u8),
    /// A 32-bit field (length, dimension, type) set to `value` in either byte order.
    Field(Index, u32, bool),
    Truncate(Index),
    Insert(Index, Vec<u8>),
    Remove(Index, usize),
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
            Mutation::Remove(index, count) => {
                let start = at(index, bytes.len());
                let end = (start + count).min(bytes.len());
                bytes.drain(start..end);
            }
        }
    }
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let extreme = prop_oneof![
        Just(0u32),
        Just(1),
        Just(8),
        Just(0x7fff_ffff),
        Just(0x8000_0000),
        Just(u32::MAX),
        Just(0xffff_fff8),
        Just(1 << 20),
        any::<u32>(),
    ];
    prop_oneof![
        3 => (any::<Index>(), any::<u8>()).prop_map(|(i, b)| Mutation::Overwrite(i, b)),
        3 => (any::<Index>(), extreme, any::<bool>()).prop_map(|(i, v, big)| Mutation::Field(i, v, big)),
        1 => any::<Index>().prop_map(Mutation::Truncate),
        1 => (any::<Index>(), prop::collection::vec(any::<u8>(), 1..16))
            .prop_map(|(i, bytes)| Mutation::Insert(i, bytes)),
        1 => (any::<Index>(), 1usize..16).prop_map(|(i, n)| Mutation::Remove(i, n)),
    ]
}

/// What every read must satisfy, whatever the bytes.
fn check_outcome(
    path: &Path,
    result: Result<Measurement, MeasurementError>,
    columns: &[&str],
) -> Result<(), TestCaseError> {
    match result {
        Ok(measurement) => {
            prop_assert_eq!(&measurement.source, path);
            prop_assert!(!measurement.time.is_empty());
            prop_assert!(measurement.time.iter().all(|t| t.is_finite()));
            prop_assert!(
                measurement.time.windows(2).all(|w| w[0] < w[1]),
                "time not strictly increasing: {:?}",
                measurement.time
            );
            prop_assert_eq!(measurement.columns.len(), columns.len());
            for ((name, values), expected) in measurement.columns.iter().zip(columns) {
                prop_assert_eq!(name, expected);
                prop_assert_eq!(values.len(), measurement.time.len());
                prop_assert!(values.iter().all(|v| v.is_finite()));
            }
        }
        Err(error) => {
            prop_assert_eq!(error.path(), path);
            let message = error.to_string();
            let name = path.display().to_string();
            prop_assert!(message.starts_with(&name), "{}", message);
            // The file's name, then what is wrong with it.
            prop_assert!(
                message.len() > name.len() + 8,
                "message says nothing: {}",
                message
            );
        }
    }
    Ok(())
}

fn read(path: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let columns = COLUMNS.as_slice();
    check_outcome(
        path,
        Measurement::from_bytes(path, bytes, TIME, columns),
        columns,
    )
}

proptest! {
    #![proptest_config(ProptestConfig { cases: CASES, ..ProptestConfig::default() })]

    #[test]
    fn arbitrary_bytes_give_a_measurement_or_a_clear_error(
        bytes in prop::collection::vec(any::<u8>(), 0..512),
        name in prop::sample::select(vec!["a.csv", "a.txt", "a.mat", "a.dat", "a"]),
    ) {
        read(&PathBuf::from("data").join(name), &bytes)?;
    }

    #[test]
    fn arbitrary_bytes_after_a_mat_header_give_a_clear_error(
        version in prop::sample::select(vec![0x0100u16, 0x0200, 0x0101]),
        big in any::<bool>(),
        body in prop::collection::vec(any::<u8>(), 0..512),
    ) {
        let order = if big { ByteOrder::Big } else { ByteOrder::Little };
        let mut bytes = testdata::header(order, version, "MATLAB 5.0 MAT-file");
        bytes.extend_from_slice(&body);
        read(Path::new("body.mat"), &bytes)?;
    }

    #[test]
    fn mutated_valid_files_give_a_measurement_or_a_clear_error(
        file in any::<Index>(),
        mutations in prop::collection::vec(mutation(), 1..4),
    ) {
        let files = valid_files();
        let (name, valid) = &files[file.index(files.len())];
        let mut bytes = valid.clone();
        for mutation in &mutations {
            mutation.apply(&mut bytes);
        }
        read(Path::new(name), &bytes)?;
    }
}

#[test]
fn the_fixtures_are_valid() {
    for (name, bytes) in valid_files() {
        let loaded = Measurement::from_bytes(Path::new(name), &bytes, TIME, &COLUMNS)
            .unwrap_or_else(|error| panic!("{name}: {error}"));
        assert_eq!(loaded.time, vec![0.0, 0.25, 0.5, 1.0], "{name}");
        assert_eq!(
            loaded.column("x"),
            Some(&[1.0, -2.0, 3.5, 4.0][..]),
            "{name}"
        );
        assert_eq!(
            loaded.column("y"),
            Some(&[0.0, 0.5, 0.25, -1.0][..]),
            "{name}"
        );
    }
}
