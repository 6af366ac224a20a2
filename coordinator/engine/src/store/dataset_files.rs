//! The datasets of a store on disk, one file each beside the sled database
//! (`<store>/datasets/<content hash, hex>`), rather than values of a sled tree: sled keeps
//! the values it wrote in its page cache, so a record of tens of megabytes stayed in a
//! coordinator's memory for as long as it ran. A file is read when a campaign is resumed
//! and is otherwise not in memory.
//!
//! A file is written whole or not at all: to a temporary name, synced, renamed into place,
//! and the folder synced. Its name is its content hash, so a second write of the same
//! dataset finds it there. Stores written before kept datasets in the `datasets` tree: they
//! are read from there as before.

use super::{hex, unhex32, DatasetHash, RawEntry, StoreError};
use std::fs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The folder of a store's dataset files.
#[derive(Debug)]
pub struct DatasetFiles {
    folder: PathBuf,
}

impl DatasetFiles {
    /// The dataset folder of the store in `store` (created when absent).
    pub fn open(store: &Path) -> Result<Self, StoreError> {
        let folder = store.join("datasets");
        fs::create_dir_all(&folder).map_err(|e| io_error(&folder, e))?;
        Ok(Self { folder })
    }

    fn file(&self, hash: &DatasetHash) -> PathBuf {
        self.folder.join(hex(hash))
    }

    /// Write the dataset `hash`, durably, unless its file is there already.
    pub fn put(&self, hash: &DatasetHash, bytes: &[u8]) -> Result<(), StoreError> {
        let path = self.file(hash);
        if path.is_file() {
            return Ok(());
        }
        // A name of its own per write: two campaigns of one process may write the same
        // dataset at once (with one name, one's rename took the other's file away).
        static WRITES: AtomicU64 = AtomicU64::new(0);
        let temporary = self.folder.join(format!(
            ".{}.{}.{}.partial",
            hex(hash),
            std::process::id(),
            WRITES.fetch_add(1, Ordering::Relaxed)
        ));
        let written = (|| {
            let mut file = fs::File::create(&temporary)?;
            file.write_all(bytes)?;
            file.sync_all()?;
            fs::rename(&temporary, &path)?;
            fs::File::open(&self.folder)?.sync_all()
        })();
        if let Err(e) = written {
            let _ = fs::remove_file(&temporary);
            return Err(io_error(&path, e));
        }
        Ok(())
    }

    /// The dataset `hash`, if it has its file.
    pub fn get(&self, hash: &DatasetHash) -> Result<Option<Vec<u8>>, StoreError> {
        let path = self.file(hash);
        match fs::read(&path) {
            Ok(bytes) => Ok(Some(bytes)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(io_error(&path, e)),
        }
    }

    /// The content hashes of every dataset file (partial writes left by a crash skipped).
    pub fn hashes(&self) -> Result<Vec<DatasetHash>, StoreError> {
        let entries = fs::read_dir(&self.folder).map_err(|e| io_error(&self.folder, e))?;
        let mut hashes = Vec::new();
        for entry in entries {
            let entry = entry.map_err(|e| io_error(&self.folder, e))?;
            if let Some(hash) = entry.file_name().to_str().and_then(unhex32) {
                hashes.push(hash);
            }
        }
        hashes.sort_unstable();
        Ok(hashes)
    }

    /// Every dataset file as a key and its bytes.
    pub fn entries(&self) -> Result<Vec<RawEntry>, StoreError> {
        self.hashes()?
            .into_iter()
            .filter_map(|hash| match self.get(&hash) {
                Ok(Some(bytes)) => Some(Ok((hash.to_vec(), bytes))),
                Ok(None) => None,
                Err(e) => Some(Err(e)),
            })
            .collect()
    }
}

fn io_error(path: &Path, e: std::io::Error) -> StoreError {
    StoreError::Io(format!("{}: {e}", path.display()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Campaigns of one process writing the same dataset at once all succeed, and the file
    /// is whole.
    #[test]
    fn the_same_dataset_written_by_many_threads_at_once_is_written_whole() {
        let dir = tempfile::tempdir().unwrap();
        let files = DatasetFiles::open(dir.path()).unwrap();
        let bytes = vec![7u8; 1 << 20];
        for round in 0..20u8 {
            let hash = [round; 32];
            std::thread::scope(|scope| {
                for _ in 0..8 {
                    scope.spawn(|| files.put(&hash, &bytes).unwrap());
                }
            });
            assert_eq!(files.get(&hash).unwrap().as_deref(), Some(&bytes[..]));
        }
        assert_eq!(files.hashes().unwrap().len(), 20);
    }

    #[test]
    fn a_dataset_is_written_once_whole_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let files = DatasetFiles::open(dir.path()).unwrap();
        let (a, b) = ([1u8; 32], [2u8; 32]);
        assert_eq!(files.get(&a).unwrap(), None);
        files.put(&a, b"first").unwrap();
        files
            .put(&a, b"ignored: the name is the content's hash")
            .unwrap();
        files.put(&b, b"second").unwrap();
        // What a crash mid-write leaves is not a dataset.
        std::fs::write(dir.path().join("datasets/.partial"), b"x").unwrap();
        assert_eq!(files.get(&a).unwrap().as_deref(), Some(&b"first"[..]));
        assert_eq!(files.hashes().unwrap(), [a, b]);
        let entries = files.entries().unwrap();
        assert_eq!(entries[1], (b.to_vec(), b"second".to_vec()));
        assert_eq!(files.get(&[3u8; 32]).unwrap(), None);
    }
}
