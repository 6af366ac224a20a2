//! Measured time series that a model is calibrated against.
//!
//! [`Measurement::load`] reads one file and keeps only the time axis and the requested
//! signals. Supported formats:
//!
//! * **CSV** (`.csv`, `.txt`): a header row naming the columns, comma separated (or `;`
//!   or tab when the header uses them), `#` comments before the header, quoted cells.
//! * **MAT v4** (`.mat`): plain vector variables, or Modelica result files
//!   (`Aclass`/`name`/`dataInfo`/`data_1`/`data_2`), little- or big-endian.
//! * **MAT v5** (`.mat`): numeric vector variables, compressed or not. MAT v7.3 (HDF5)
//!   is not supported.
//!
//! Other extensions are recognised by their first bytes. Whatever the format, the result
//! obeys the same rules: a strictly increasing, finite time axis with at least one
//! sample, and finite values of the same length; any violation is an error that names
//! the file and the line or sample.

mod csv;
mod error;
mod mat;
/// The bytes of the measurement file `path`; a missing file and an unreadable one are told
/// apart.
fn read_file(path: &Path) -> Result<Vec<u8>, MeasurementError> {
    std::fs::read(path).map_err(|source| {
        if source.kind() == std::io::ErrorKind::NotFound {
            MeasurementError::NotFound {
                path: path.to_owned(),
            }
        } else {
            MeasurementError::Unreadable {
                path: path.to_owned(),
                source,
            }
        }
    })
}

#[cfg(test)]
mod robustness;
#[cfg(test)]
mod testdata;

use std::path::{Path, PathBuf};

use calib_model::content_hash::ContentHasher;

pub use error::{Location, MeasurementError};

/// A measured record: a time axis and the signals sampled on it.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// The file it came from.
    pub source: PathBuf,
    /// Sample times, strictly increasing and finite.
    pub time: Vec<f64>,
    /// The requested columns, in the requested order, each as long as `time`.
    pub columns: Vec<(String, Vec<f64>)>,
}

impl Measurement {
    /// Loads `path`, taking the time from `time_column` and the listed `columns`.
    ///
    /// The format follows the extension: `.csv`/`.txt` are CSV, `.mat` is MAT (v4 or
    /// v5, told apart by the header); any other extension is recognised by the file's
    /// first bytes. Only the time column and the requested columns are parsed and
    /// validated; others are ignored.
    pub fn load(
        path: &Path,
        time_column: &str,
        columns: &[&str],
    ) -> Result<Measurement, MeasurementError> {
        let bytes = read_file(path)?;
        Measurement::from_bytes(path, &bytes, time_column, columns)
    }

    /// Reads the content `bytes` of the file `path` as [`Measurement::load`] does, without
    /// touching the file system: `path` decides the format and names the file in errors.
    pub fn from_bytes(
        path: &Path,
        bytes: &[u8],
        time_column: &str,
        columns: &[&str],
    ) -> Result<Measurement, MeasurementError> {
        match FileFormat::of(path, bytes) {
            Some(FileFormat::Csv) => csv::read(path, bytes, time_column, columns),
            Some(FileFormat::Mat) => mat::read(path, bytes, time_column, columns),
            None => Err(MeasurementError::UnrecognizedFormat {
                path: path.to_owned(),
            }),
        }
    }

    /// The names of the columns (CSV) or variables (MAT) of `path` besides `time_column`, in
    /// file order, as the loader finds them: it is asked for a column no file can hold and
    /// lists the ones there are. The time column is checked on the way.
    pub fn column_names(path: &Path, time_column: &str) -> Result<Vec<String>, MeasurementError> {
        let bytes = read_file(path)?;
        Self::column_names_of_bytes(path, &bytes, time_column)
    }

    /// [`Measurement::column_names`] of the content `bytes` of the file `path`, as
    /// [`Measurement::from_bytes`] reads it.
    pub fn column_names_of_bytes(
        path: &Path,
        bytes: &[u8],
        time_column: &str,
    ) -> Result<Vec<String>, MeasurementError> {
        const NONE: &str = "\u{0}no such column\u{0}";
        match Self::from_bytes(path, bytes, time_column, &[NONE]) {
            Err(MeasurementError::MissingColumn {
                available, column, ..
            })
            | Err(MeasurementError::MissingVariable {
                available,
                variable: column,
                ..
            }) if column == NONE => Ok(available
                .into_iter()
                .filter(|name| name != time_column)
                .collect()),
            Err(e) => Err(e),
            Ok(_) => Ok(Vec::new()),
        }
    }

    /// The values of the column called `name`, if it was loaded.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.columns
            .iter()
            .find(|(column_name, _)| column_name == name)
            .map(|(_, values)| values.as_slice())
    }

    /// blake3 hash of the content, independent of the file it came from.
    ///
    /// The hashed encoding is, all integers as little-endian `u64`: a format tag, the
    /// number of samples, the number of columns, the time values, then for each column
    /// the byte length of its name, the UTF-8 name and its values. Values are hashed as
    /// their little-endian IEEE-754 bits, so `0.0` and `-0.0` differ.
    pub fn content_hash(&self) -> [u8; 32] {
        let mut hasher = ContentHasher::new(CONTENT_HASH_TAG);
        hasher
            .count(self.time.len())
            .count(self.columns.len())
            .values(&self.time);
        for (name, values) in &self.columns {
            hasher.text(name).values(values);
        }
        hasher.finish()
    }
}

/// Versions the encoding behind [`Measurement::content_hash`]: bump it whenever the
/// encoding changes so that stale content addresses cannot collide with new ones.
const CONTENT_HASH_TAG: &[u8] = b"calib.measurement.v1\0";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum FileFormat {
    Csv,
    Mat,
}

impl FileFormat {
    fn of(path: &Path, bytes: &[u8]) -> Option<FileFormat> {
        let extension = path
            .extension()
            .and_then(|extension| extension.to_str())
            .map(str::to_ascii_lowercase);
        match extension.as_deref() {
            Some("csv" | "txt") => Some(FileFormat::Csv),
            Some("mat") => Some(FileFormat::Mat),
            _ if mat::looks_like_mat(bytes) => Some(FileFormat::Mat),
            _ if looks_like_text(bytes) => Some(FileFormat::Csv),
            _ => None,
        }
    }
}

/// How much of a file is inspected to decide whether it is text.
const SNIFFED_BYTES: usize = 4096;

fn looks_like_text(bytes: &[u8]) -> bool {
    let start = &bytes[..bytes.len().min(SNIFFED_BYTES)];
    if start.contains(&0) {
        return false;
    }
    match std::str::from_utf8(start) {
        Ok(_) => true,
        // A multi-byte character cut by the sniffing window is still text.
        Err(error) => error.error_len().is_none(),
    }
}

/// Whether equal consecutive times are an error or events to be collapsed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum TimeOrder {
    /// Every time must exceed the one before (measured records).
    Strict,
    /// Simulation results repeat the time at events (the values before and after the
    /// event): equal times are allowed, decreasing ones are not.
    RepeatsAtEvents,
}

/// Rejects NaN and infinities.
fn check_finite(
    path: &Path,
    location: Location,
    column: &str,
    value: f64,
) -> Result<(), MeasurementError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(MeasurementError::NonFinite {
            path: path.to_owned(),
            location,
            column: column.to_owned(),
            value,
        })
    }
}

/// Checks that a time value follows its predecessor as `order` demands.
fn check_time_step(
    path: &Path,
    column: &str,
    previous: Option<(Location, f64)>,
    location: Location,
    value: f64,
    order: TimeOrder,
) -> Result<(), MeasurementError> {
    let Some((previous_location, previous_value)) = previous else {
        return Ok(());
    };
    let in_order = match order {
        TimeOrder::Strict => value > previous_value,
        TimeOrder::RepeatsAtEvents => value >= previous_value,
    };
    if in_order {
        Ok(())
    } else {
        Err(MeasurementError::TimeNotIncreasing {
            path: path.to_owned(),
            column: column.to_owned(),
            previous_location,
            previous: previous_value,
            location,
            value,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::testdata::{self, V5Writer, V4};
    use super::*;

    fn fixture(dir: &tempfile::TempDir, name: &str, bytes: &[u8]) -> PathBuf {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).expect("write fixture");
        path
    }

    fn furuta_v4(order: testdata::ByteOrder) -> Vec<u8> {
        let time: Vec<f64> = (0..5).map(|i| i as f64 * 0.05).collect();
        let mut file = Vec::new();
        V4::new(order).double(&mut file, "time", 5, 1, &time);
        V4::new(order).double(&mut file, "phi", 1, 5, &[0.0, 0.1, 0.2, 0.3, 0.4]);
        file
    }

    #[test]
    fn format_follows_the_extension_case_insensitively() {
        let dir = tempfile::tempdir().expect("temp dir");
        let csv_text = b"t,x\n0,1\n1,2\n";
        for name in ["a.csv", "a.TXT", "a.Csv"] {
            let path = fixture(&dir, name, csv_text);
            let loaded = Measurement::load(&path, "t", &["x"]).expect(name);
            assert_eq!(loaded.time, vec![0.0, 1.0]);
        }
        let path = fixture(&dir, "a.MAT", &furuta_v4(testdata::ByteOrder::Little));
        let loaded = Measurement::load(&path, "time", &["phi"]).expect("MAT v4");
        assert_eq!(loaded.column("phi").map(<[f64]>::len), Some(5));
    }

    #[test]
    fn unknown_extensions_are_sniffed() {
        let dir = tempfile::tempdir().expect("temp dir");
        let cases: Vec<(&str, Vec<u8>)> = vec![
            ("record.dat", b"t;x\n0;1\n1;2\n".to_vec()),
            ("record", furuta_v4(testdata::ByteOrder::Little)),
            ("record.bin", furuta_v4(testdata::ByteOrder::Big)),
            (
                "record.v5",
                V5Writer::new(testdata::ByteOrder::Little)
                    .double("time", &[2, 1], &[0.0, 1.0])
                    .double("phi", &[1, 2], &[5.0, 6.0])
                    .finish(),
            ),
        ];
        for (name, bytes) in cases {
            let path = fixture(&dir, name, &bytes);
            let (time_column, column) = if bytes.starts_with(b"t;") {
                ("t", "x")
            } else {
                ("time", "phi")
            };
            let loaded = Measurement::load(&path, time_column, &[column]).expect(name);
            assert!(loaded.time.len() >= 2, "{name}");
        }
    }

    #[test]
    fn binary_garbage_with_unknown_extension_is_unrecognised() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = fixture(&dir, "noise.bin", &[0xff, 0x00, 0x13, 0x37, 0xfe, 0x00]);
        let error = Measurement::load(&path, "t", &[]).expect_err("garbage");
        assert!(matches!(error, MeasurementError::UnrecognizedFormat { .. }));
        assert!(error.to_string().contains("noise.bin"), "{error}");
    }

    #[test]
    fn missing_file_is_named() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("absent.csv");
        let error = Measurement::load(&path, "t", &["x"]).expect_err("missing");
        assert!(matches!(error, MeasurementError::NotFound { .. }));
        assert_eq!(
            error.to_string(),
            format!("measurement file {} does not exist", path.display())
        );
        assert_eq!(error.path(), path);
    }

    #[test]
    fn unreadable_file_is_named_with_the_reason() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("a_directory.csv");
        std::fs::create_dir(&path).expect("create dir");
        let error = Measurement::load(&path, "t", &["x"]).expect_err("directory");
        assert!(matches!(error, MeasurementError::Unreadable { .. }));
        let message = error.to_string();
        assert!(
            message.starts_with(&format!(
                "cannot read measurement file {}: ",
                path.display()
            )),
            "{message}"
        );
    }

    fn measurement(columns: Vec<(&str, Vec<f64>)>) -> Measurement {
        Measurement {
            source: PathBuf::from("a.csv"),
            time: vec![0.0, 0.5, 1.0],
            columns: columns
                .into_iter()
                .map(|(name, values)| (name.to_owned(), values))
                .collect(),
        }
    }

    #[test]
    fn content_hash_depends_on_content_only() {
        let base = measurement(vec![("x", vec![1.0, 2.0, 3.0]), ("y", vec![0.0; 3])]);
        let mut moved = base.clone();
        moved.source = PathBuf::from("/elsewhere/b.mat");
        assert_eq!(base.content_hash(), moved.content_hash());

        let renamed = measurement(vec![("x2", vec![1.0, 2.0, 3.0]), ("y", vec![0.0; 3])]);
        let reordered = measurement(vec![("y", vec![0.0; 3]), ("x", vec![1.0, 2.0, 3.0])]);
        let changed = measurement(vec![("x", vec![1.0, 2.0, 3.5]), ("y", vec![0.0; 3])]);
        let negative_zero = measurement(vec![("x", vec![1.0, 2.0, 3.0]), ("y", vec![-0.0; 3])]);
        let mut retimed = base.clone();
        retimed.time[2] = 1.5;
        for other in [renamed, reordered, changed, negative_zero, retimed] {
            assert_ne!(base.content_hash(), other.content_hash(), "{other:?}");
        }
    }

    #[test]
    fn content_hash_separates_names_from_values() {
        // Without length prefixes these two would encode to the same bytes.
        let a = measurement(vec![("ab", vec![1.0; 3]), ("c", vec![2.0; 3])]);
        let b = measurement(vec![("a", vec![1.0; 3]), ("bc", vec![2.0; 3])]);
        assert_ne!(a.content_hash(), b.content_hash());
    }

    #[test]
    fn content_hash_is_stable() {
        // Pins the encoding: a change here invalidates every stored content address,
        // so it must come with a new CONTENT_HASH_TAG.
        let mut hasher = blake3::Hasher::new();
        hasher.update(b"calib.measurement.v1\0");
        hasher.update(&3u64.to_le_bytes());
        hasher.update(&1u64.to_le_bytes());
        for value in [0.0f64, 0.5, 1.0] {
            hasher.update(&value.to_le_bytes());
        }
        hasher.update(&1u64.to_le_bytes());
        hasher.update(b"x");
        for value in [1.0f64, 2.0, 3.0] {
            hasher.update(&value.to_le_bytes());
        }
        let expected = *hasher.finalize().as_bytes();
        assert_eq!(
            measurement(vec![("x", vec![1.0, 2.0, 3.0])]).content_hash(),
            expected
        );
    }

    #[test]
    fn column_finds_loaded_columns_only() {
        let loaded = measurement(vec![("x", vec![1.0, 2.0, 3.0])]);
        assert_eq!(loaded.column("x"), Some(&[1.0, 2.0, 3.0][..]));
        assert_eq!(loaded.column("y"), None);
    }

    const REAL_RECORD: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/real/FurutaData.mat"
    );
    /// The synthetic record ships with the examples.
    const SYNTHETIC_RECORD: &str = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../examples/data/furuta_clean.csv"
    );

    /// The real record lives outside the repository; tests that need it skip, saying why,
    /// where it is absent, except under continuous integration (`calib_model::testing`),
    /// where nothing required may skip.
    fn shared_file(path: &str) -> Option<&Path> {
        let path = Path::new(path);
        if path.exists() {
            Some(path)
        } else {
            calib_model::testing::skip(&format!("{} not present", path.display()));
            None
        }
    }

    #[test]
    fn loads_the_real_furuta_record() {
        let Some(path) = shared_file(REAL_RECORD) else {
            return;
        };
        let loaded = Measurement::load(path, "time", &["phi", "theta"]).expect("real record");
        assert_eq!(loaded.time.len(), 801);
        assert_eq!(loaded.time[0], 0.0);
        assert!((loaded.time[800] - 40.0).abs() < 1e-9);
        let mean_step = (loaded.time[800] - loaded.time[0]) / 800.0;
        assert!(
            (mean_step - 0.05).abs() < 1e-9,
            "20 Hz, got step {mean_step}"
        );
        assert_eq!(
            loaded
                .columns
                .iter()
                .map(|(n, _)| n.as_str())
                .collect::<Vec<_>>(),
            ["phi", "theta"]
        );
        for (name, values) in &loaded.columns {
            assert_eq!(values.len(), 801, "{name}");
        }
        // The pendulum starts near 0.5 rad from upright and ends hanging down (π).
        let theta = loaded.column("theta").expect("theta");
        assert!((theta[0] - 0.57).abs() < 0.01, "{}", theta[0]);
        assert!(
            (theta[800] - std::f64::consts::PI).abs() < 0.05,
            "{}",
            theta[800]
        );
        assert_eq!(loaded.source, path);
    }

    #[test]
    fn real_record_reports_its_variables_when_one_is_missing() {
        let Some(path) = shared_file(REAL_RECORD) else {
            return;
        };
        let error = Measurement::load(path, "time", &["psi"]).expect_err("no psi");
        let message = error.to_string();
        assert!(message.contains("no variable \"psi\""), "{message}");
        assert!(
            message.contains("\"phi\", \"theta\", \"time\""),
            "{message}"
        );
    }

    #[test]
    fn loads_the_synthetic_furuta_record() {
        let path = Path::new(SYNTHETIC_RECORD);
        let loaded = Measurement::load(path, "time_s", &["pendulum_angle_rad", "arm_angle_rad"])
            .expect("synthetic record");
        assert_eq!(loaded.time.len(), 4001);
        assert_eq!(loaded.time[0], 0.0);
        assert!((loaded.time[4000] - 40.0).abs() < 1e-9);
        assert_eq!(loaded.columns[0].0, "pendulum_angle_rad");
        assert_eq!(loaded.columns[1].0, "arm_angle_rad");
        assert_eq!(
            loaded.column("pendulum_angle_rad").map(|v| v[0]),
            Some(0.526155)
        );
        // Same file, same content address.
        let again = Measurement::load(path, "time_s", &["pendulum_angle_rad", "arm_angle_rad"])
            .expect("synthetic record");
        assert_eq!(loaded.content_hash(), again.content_hash());
    }
}
