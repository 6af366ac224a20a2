//! Measurement files uploaded to a coordinator, kept in a folder by the hash of their bytes.
//!
//! `<folder>/<id>.<ext>` holds the file as uploaded, `<folder>/<id>.json` what was learned
//! parsing it (its name, time column, columns, samples). A campaign names a dataset by id
//! and reads the file through the same loader as a campaign file's `[measurement]`.

use calib_engine::error::{Error, Result};
use calib_engine::measurement::Measurement;
use calib_model::content_hash::ContentHasher;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

use calib_engine::limits::MAX_DATASET_BYTES;

/// What a dataset holds.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DatasetInfo {
    /// [`dataset_id`], hex.
    pub id: String,
    pub file_name: String,
    pub time_column: String,
    /// Columns besides the time column, in file order.
    pub columns: Vec<String>,
    pub samples: usize,
    pub start_time: f64,
    pub stop_time: f64,
}

/// Most columns tried as the time axis when guessing it by its values.
pub const MAX_GUESS_COLUMNS: usize = 64;

/// Whether a column's name says it holds time: "time" or "t" in any case, or "time" followed
/// by a unit or a separator ("time_s", "Time [s]", "time (s)").
fn named_time(name: &str) -> bool {
    let lower = name.trim().to_ascii_lowercase();
    if lower == "time" || lower == "t" {
        return true;
    }
    lower
        .strip_prefix("time")
        .and_then(|rest| rest.chars().next())
        .is_some_and(|c| !c.is_ascii_alphanumeric())
}

/// The time column of the file `file_name` (its content `bytes`) when its upload names none:
/// the first column named as time ([`named_time`]) that reads as a time axis, else the first
/// of its first [`MAX_GUESS_COLUMNS`] columns that does (its values finite and strictly
/// increasing). An error when the file does not parse or no column qualifies.
pub fn guess_time_column(file_name: &str, bytes: &[u8]) -> Result<String> {
    const NONE: &str = "\u{0}no such column\u{0}";
    let path = Path::new(file_name);
    let names = match Measurement::from_bytes(path, bytes, NONE, &[]) {
        Err(calib_engine::measurement::MeasurementError::MissingColumn {
            available,
            column,
            ..
        })
        | Err(calib_engine::measurement::MeasurementError::MissingVariable {
            available,
            variable: column,
            ..
        }) if column == NONE => available,
        Err(e) => return Err(e.into()),
        Ok(_) => Vec::new(),
    };
    let reads_as_time = |name: &str| Measurement::from_bytes(path, bytes, name, &[]).is_ok();
    let named = names.iter().filter(|n| named_time(n));
    let rest = names.iter().take(MAX_GUESS_COLUMNS);
    for name in named.chain(rest) {
        if reads_as_time(name) {
            return Ok(name.clone());
        }
    }
    Err(Error::InvalidRequest(format!(
        "time_column: no column of {file_name} reads as time (named \"time\" or \"t\", or \
         increasing from sample to sample); its columns are: {}",
        names
            .iter()
            .take(20)
            .map(|n| format!("{n:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    )))
}

/// The folder of uploaded datasets.
#[derive(Debug, Clone)]
pub struct Datasets {
    folder: PathBuf,
}

impl Datasets {
    pub fn open(folder: &Path) -> Result<Self> {
        std::fs::create_dir_all(folder).map_err(|source| Error::Write {
            path: folder.to_path_buf(),
            source,
        })?;
        // Absolute, so that campaign files naming a dataset resolve it wherever they are
        // parsed (a relative `--db` or `--api-dir` must not be joined twice).
        let folder = std::fs::canonicalize(folder).map_err(|source| Error::Write {
            path: folder.to_path_buf(),
            source,
        })?;
        Ok(Self { folder })
    }

    /// Parse `bytes` as the file `file_name` with its time in `time_column` (empty: the
    /// column [`guess_time_column`] finds) and keep it. The same bytes on the same time
    /// column give the same id; storing them again changes nothing.
    pub fn put(&self, file_name: &str, time_column: &str, bytes: &[u8]) -> Result<DatasetInfo> {
        let extension = Path::new(file_name)
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .filter(|e| matches!(e.as_str(), "csv" | "txt" | "mat"))
            .ok_or_else(|| {
                Error::InvalidRequest(format!(
                    "file_name: `{file_name}` must end in .csv, .txt or .mat (the extension \
                     picks the parser)"
                ))
            })?;
        if bytes.len() > MAX_DATASET_BYTES {
            return Err(Error::InvalidRequest(format!(
                "data: {} bytes is more than the {} accepted",
                bytes.len(),
                MAX_DATASET_BYTES
            )));
        }
        let guessed;
        let time_column = if time_column.is_empty() {
            guessed = guess_time_column(file_name, bytes)?;
            guessed.as_str()
        } else {
            time_column
        };
        let id = dataset_id(time_column, bytes);
        // A record whose file does not match it (a crash between the two renames of an
        // older version, a file edited by hand) is written again below.
        if let Stored::Intact(info) = self.stored(&id)? {
            return Ok(info);
        }
        // Parsed under the name it was uploaded as, so that an error names the user's file
        // (`rig.csv: line 7: …`), not the folder it would be kept in.
        let uploaded = Path::new(file_name);
        let columns = Measurement::column_names_of_bytes(uploaded, bytes, time_column)?;
        let names: Vec<&str> = columns.iter().map(String::as_str).collect();
        let m = Measurement::from_bytes(uploaded, bytes, time_column, &names)?;
        let path = self.folder.join(format!("{id}.{extension}"));
        write_atomically(&path, bytes)?;
        let info = DatasetInfo {
            id: id.clone(),
            file_name: file_name.to_string(),
            time_column: time_column.to_string(),
            columns,
            samples: m.time.len(),
            start_time: m.time.first().copied().unwrap_or(0.0),
            stop_time: m.time.last().copied().unwrap_or(0.0),
        };
        let json = serde_json::to_vec_pretty(&info).expect("plain data");
        write_atomically(&self.folder.join(format!("{id}.json")), &json)?;
        Ok(info)
    }

    /// The dataset `id`, if it was uploaded. A record whose file is missing or holds other
    /// bytes than the ones it was made from is an error, never read as the dataset.
    pub fn get(&self, id: &str) -> Result<Option<DatasetInfo>> {
        match self.stored(id)? {
            Stored::Intact(info) => Ok(Some(info)),
            Stored::Absent => Ok(None),
            Stored::Damaged(reason) => Err(Error::InvalidRequest(format!(
                "dataset {id}: {reason}; upload the file again"
            ))),
        }
    }

    /// The record of `id` checked against its file: the file's bytes must hash to `id`.
    fn stored(&self, id: &str) -> Result<Stored> {
        if id.len() != 64 || !id.bytes().all(|b| b.is_ascii_hexdigit()) {
            return Ok(Stored::Absent);
        }
        let path = self.folder.join(format!("{id}.json"));
        let record = match std::fs::read(&path) {
            Ok(bytes) => bytes,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(Stored::Absent),
            Err(e) => return Err(Error::InvalidRequest(format!("dataset {id}: {e}"))),
        };
        let info: DatasetInfo = match serde_json::from_slice(&record) {
            Ok(info) => info,
            Err(e) => return Ok(Stored::Damaged(format!("its record is unreadable: {e}"))),
        };
        if info.id != id {
            return Ok(Stored::Damaged(format!(
                "its record names another dataset ({})",
                info.id
            )));
        }
        let data = match std::fs::read(self.file(&info)) {
            Ok(data) => data,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Ok(Stored::Damaged("its file is missing".into()))
            }
            Err(e) => return Err(Error::InvalidRequest(format!("dataset {id}: {e}"))),
        };
        if dataset_id(&info.time_column, &data) != id {
            return Ok(Stored::Damaged(
                "its file does not hold the bytes it was uploaded with".into(),
            ));
        }
        Ok(Stored::Intact(info))
    }

    /// Where the file of dataset `info` is.
    pub fn file(&self, info: &DatasetInfo) -> PathBuf {
        let extension = Path::new(&info.file_name)
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase)
            .unwrap_or_default();
        self.folder.join(format!("{}.{extension}", info.id))
    }

    pub fn folder(&self) -> &Path {
        &self.folder
    }
}

/// A dataset's id, in calib's content-hash encoding: the tag `calib.dataset.v1\0`, the time
/// column's name (as text), the file's bytes (as a series of bytes: length, then bytes). The
/// same file read on another time axis is another dataset.
pub fn dataset_id(time_column: &str, bytes: &[u8]) -> String {
    let hash = ContentHasher::new(DATASET_TAG)
        .text(time_column)
        .count(bytes.len())
        .bytes(bytes)
        .finish();
    calib_engine::store::hex(&hash)
}

const DATASET_TAG: &[u8] = b"calib.dataset.v1\0";

/// What the folder holds for an id.
enum Stored {
    Intact(DatasetInfo),
    Absent,
    /// A record without its file, or with a file of other bytes: why.
    Damaged(String),
}

/// Write `bytes` to a temporary file of its own beside `path` (a unique name for every
/// call, so that concurrent writers of one dataset, or of a dataset's file and its record,
/// never share one), flush it to disk, then rename it into place: a reader never sees half
/// a file, and the last rename of identical bytes changes nothing.
fn write_atomically(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let error = |source| Error::Write {
        path: path.to_path_buf(),
        source,
    };
    let folder = path.parent().unwrap_or(Path::new("."));
    let mut partial = tempfile::Builder::new()
        .prefix(".upload-")
        .suffix(".partial")
        .tempfile_in(folder)
        .map_err(error)?;
    partial.write_all(bytes).map_err(error)?;
    partial.as_file().sync_all().map_err(error)?;
    partial.persist(path).map_err(|e| error(e.error))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_same_bytes_are_one_dataset_and_bad_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let d = Datasets::open(dir.path()).unwrap();
        let csv = b"time,a,b\n0,1,2\n1,3,4\n2,5,6\n";
        let one = d.put("rig.csv", "time", csv).unwrap();
        assert_eq!(one.columns, vec!["a", "b"]);
        assert_eq!((one.samples, one.start_time, one.stop_time), (3, 0.0, 2.0));
        let again = d.put("other-name.csv", "time", csv).unwrap();
        assert_eq!(again, one);
        assert_eq!(d.get(&one.id).unwrap(), Some(one.clone()));
        assert!(d.file(&one).exists());

        let err = d.put("rig.csv", "t", csv).unwrap_err().to_string();
        assert!(err.contains("t"), "{err}");
        let err = d.put("rig.xlsx", "time", csv).unwrap_err().to_string();
        assert!(err.starts_with("file_name:"), "{err}");
        // A file that does not parse is named as it was uploaded, and nothing is kept.
        let err = d
            .put("rig.csv", "time", b"time,a\n0,1\n1,one\n")
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("rig.csv line 3"), "{err}");
        let kept = std::fs::read_dir(dir.path()).unwrap().count();
        assert_eq!(kept, 2, "only the good dataset and its record");
        assert_eq!(d.get("not-an-id").unwrap(), None);
        assert_eq!(d.get(&"0".repeat(64)).unwrap(), None);
    }

    /// An upload naming no time column gets the column named as time, else the first one
    /// increasing from sample to sample; a file with neither is refused, naming its columns.
    #[test]
    fn the_time_column_is_guessed_by_its_name_then_by_its_values() {
        let named = b"arm,Time [s],pendulum\n0.3,0,1\n0.2,0.5,2\n0.1,1,3\n";
        assert_eq!(guess_time_column("rig.csv", named).unwrap(), "Time [s]");
        for header in ["t", "TIME", "time_s", "Time (s)"] {
            let csv = format!("x,{header}\n5,0\n4,1\n");
            assert_eq!(guess_time_column("r.csv", csv.as_bytes()).unwrap(), header);
        }
        // "timer" and "timestamp_id" are not named as time; the first increasing column is.
        let by_values = b"timer,angle,stamp\n3,0.5,10\n2,0.4,11\n1,0.3,12\n";
        assert_eq!(guess_time_column("r.csv", by_values).unwrap(), "stamp");
        // A column named time that does not increase is passed over.
        let bad_name = b"time,s\n0,0\n0,1\n";
        assert_eq!(guess_time_column("r.csv", bad_name).unwrap(), "s");
        let none = b"a,b\n1,2\n0,2\n";
        let err = guess_time_column("flat.csv", none).unwrap_err().to_string();
        assert!(
            err.starts_with("time_column:") && err.contains("\"a\", \"b\""),
            "{err}"
        );

        // Kept under the guessed column: the same dataset as an upload naming it.
        let dir = tempfile::tempdir().unwrap();
        let d = Datasets::open(dir.path()).unwrap();
        let guessed = d.put("rig.csv", "", named).unwrap();
        assert_eq!(guessed.time_column, "Time [s]");
        assert_eq!(guessed.columns, ["arm", "pendulum"]);
        assert_eq!((guessed.start_time, guessed.stop_time), (0.0, 1.0));
        assert_eq!(d.put("rig.csv", "Time [s]", named).unwrap(), guessed);
        // Another time column is another dataset, the guessed one among its columns.
        let other = d.put("rig.csv", "pendulum", named).unwrap();
        assert_ne!(other.id, guessed.id);
        assert_eq!(other.columns, ["arm", "Time [s]"]);
    }

    #[test]
    fn concurrent_uploads_of_one_file_all_succeed_with_one_intact_dataset() {
        let csv: Vec<u8> = std::iter::once("time,a,b\n".to_string())
            .chain((0..40_000).map(|i| format!("{i},{},{}\n", i * 3, i % 7)))
            .collect::<String>()
            .into_bytes();
        for round in 0..10 {
            let dir = tempfile::tempdir().unwrap();
            let d = Datasets::open(dir.path()).unwrap();
            let together = std::sync::Barrier::new(16);
            let answers: Vec<_> = std::thread::scope(|scope| {
                let uploads: Vec<_> = (0..16)
                    .map(|_| {
                        scope.spawn(|| {
                            together.wait();
                            d.put("rig.csv", "time", &csv)
                        })
                    })
                    .collect();
                uploads.into_iter().map(|u| u.join().unwrap()).collect()
            });
            let infos: Vec<DatasetInfo> = answers
                .into_iter()
                .map(|a| a.unwrap_or_else(|e| panic!("round {round}: {e}")))
                .collect();
            assert!(infos.iter().all(|i| *i == infos[0]), "round {round}");
            let info = &infos[0];
            assert_eq!(std::fs::read(d.file(info)).unwrap(), csv, "round {round}");
            assert_eq!(d.get(&info.id).unwrap().as_ref(), Some(info));
            let mut kept: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            kept.sort();
            let expected = vec![format!("{}.csv", info.id), format!("{}.json", info.id)];
            assert_eq!(kept, expected, "round {round}: no temporary file is left");
        }
    }

    #[test]
    fn a_record_whose_file_holds_other_bytes_is_not_the_dataset_and_heals_on_upload() {
        let dir = tempfile::tempdir().unwrap();
        let d = Datasets::open(dir.path()).unwrap();
        let csv = b"time,a\n0,1\n1,2\n";
        let info = d.put("rig.csv", "time", csv).unwrap();
        // The file holding its own record, as a shared temporary name once made it.
        let record = std::fs::read(dir.path().join(format!("{}.json", info.id))).unwrap();
        std::fs::write(d.file(&info), &record).unwrap();
        let err = d.get(&info.id).unwrap_err().to_string();
        assert!(
            err.contains(&info.id) && err.contains("upload the file again"),
            "{err}"
        );
        std::fs::remove_file(d.file(&info)).unwrap();
        let err = d.get(&info.id).unwrap_err().to_string();
        assert!(err.contains("missing"), "{err}");
        assert_eq!(d.put("rig.csv", "time", csv).unwrap(), info);
        assert_eq!(std::fs::read(d.file(&info)).unwrap(), csv);
        assert_eq!(d.get(&info.id).unwrap(), Some(info));
    }
}
