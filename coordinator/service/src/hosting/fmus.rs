//! FMUs uploaded to a coordinator, kept in a folder by the hash of their bytes.
//!
//! The folder is a worker's FMU cache ([`FmuCache`]: `<folder>/<hash>.fmu`, unpacked into
//! `<folder>/unpacked/`), never evicted: a campaign submitted on an FMU names its file, and
//! must find it again after a restart. An archive is checked as a worker checks it before
//! it is kept ([`archive::Limits`], the description parsed), and opened here only to
//! describe it: its code runs where campaigns simulate (on workers, which receive it by
//! hash, or in `calib ui`'s host processes).

use calib_engine::error::{Error, Result};
use calib_engine::limits::MAX_FMU_BYTES;
use calib_model::fmu::{self, archive};
use calib_model::Model;
use calib_worker::service::fmu_cache::FmuCache;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What an uploaded FMU is.
#[derive(Clone)]
pub struct FmuInfo {
    /// The BLAKE3 hash of the archive, hex.
    pub id: String,
    pub file_name: String,
    pub size: u64,
    /// A model per interface, the default first.
    pub models: Vec<&'static dyn Model>,
}

impl std::fmt::Debug for FmuInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FmuInfo")
            .field("id", &self.id)
            .field("file_name", &self.file_name)
            .field("size", &self.size)
            .field(
                "models",
                &self
                    .models
                    .iter()
                    .map(|m| m.info().name.as_str())
                    .collect::<Vec<_>>(),
            )
            .finish()
    }
}

/// What is kept beside an archive: the name it was uploaded under.
#[derive(Debug, Serialize, Deserialize)]
struct Record {
    file_name: String,
}

/// The folder of uploaded FMUs.
pub struct Fmus {
    cache: FmuCache,
    folder: PathBuf,
}

impl Fmus {
    pub fn open(folder: &Path) -> Result<Self> {
        let write = |source| Error::Write {
            path: folder.to_path_buf(),
            source,
        };
        std::fs::create_dir_all(folder).map_err(write)?;
        // Absolute, as the datasets' folder: campaign files name the archive by its path.
        let folder = std::fs::canonicalize(folder).map_err(write)?;
        let cache = FmuCache::new(folder.clone(), u64::MAX).map_err(write)?;
        Ok(Self { cache, folder })
    }

    pub fn folder(&self) -> &Path {
        &self.folder
    }

    /// Check the archive `bytes`, uploaded as `file_name`, and keep it. The same bytes give
    /// the same id; storing them again changes nothing.
    pub fn put(&self, file_name: &str, bytes: &[u8]) -> Result<FmuInfo> {
        let refused = |m: String| Error::InvalidRequest(format!("fmu: {m}"));
        if !fmu::is_fmu_path(file_name) {
            return Err(Error::InvalidRequest(format!(
                "file_name: `{file_name}` must end in .fmu"
            )));
        }
        if bytes.len() > MAX_FMU_BYTES {
            return Err(refused(format!(
                "{} bytes is more than the {MAX_FMU_BYTES} accepted (what a worker's \
                 UploadFmu carries)",
                bytes.len()
            )));
        }
        let limits = self.cache.limits();
        archive::check_size(bytes.len() as u64, &limits).map_err(|e| refused(e.to_string()))?;
        let hash = fmu::content_hash(bytes);
        let models = fmu::open_all_in(bytes, &self.cache.unpacked(), &limits)
            .map_err(|e| refused(e.to_string()))?;
        let id = calib_engine::store::hex(&hash);
        let write = |source| Error::Write {
            path: self.cache.path(&hash),
            source,
        };
        self.cache.put(&hash, bytes).map_err(write)?;
        fmu::remember_archive(&hash, &self.cache.path(&hash));
        let record = self.folder.join(format!("{id}.json"));
        let file_name = match std::fs::read(&record)
            .ok()
            .and_then(|r| serde_json::from_slice::<Record>(&r).ok())
        {
            Some(kept) => kept.file_name,
            None => {
                let json = serde_json::to_vec(&Record {
                    file_name: file_name.to_string(),
                })
                .expect("plain data");
                std::fs::write(&record, json).map_err(|source| Error::Write {
                    path: record.clone(),
                    source,
                })?;
                file_name.to_string()
            }
        };
        Ok(FmuInfo {
            id,
            file_name,
            size: bytes.len() as u64,
            models,
        })
    }

    /// The FMU `id`, if it was uploaded (and its archive still holds its bytes).
    pub fn get(&self, id: &str) -> Result<Option<FmuInfo>> {
        let Some(hash) = parse_id(id) else {
            return Ok(None);
        };
        let Some(bytes) = self.cache.get(&hash) else {
            return Ok(None);
        };
        let limits = self.cache.limits();
        let models = fmu::open_all_in(&bytes, &self.cache.unpacked(), &limits)
            .map_err(|e| Error::InvalidRequest(format!("fmu {id}: {e}")))?;
        fmu::remember_archive(&hash, &self.cache.path(&hash));
        let file_name = std::fs::read(self.folder.join(format!("{id}.json")))
            .ok()
            .and_then(|r| serde_json::from_slice::<Record>(&r).ok())
            .map(|r| r.file_name)
            .unwrap_or_else(|| format!("{id}.fmu"));
        Ok(Some(FmuInfo {
            id: id.to_ascii_lowercase(),
            file_name,
            size: bytes.len() as u64,
            models,
        }))
    }

    /// Where the archive of FMU `id` is kept (the path a campaign file names).
    pub fn file(&self, id: &str) -> Option<PathBuf> {
        parse_id(id).map(|hash| self.cache.path(&hash))
    }
}

/// The hash an FMU id names: 64 hex digits.
fn parse_id(id: &str) -> Option<[u8; 32]> {
    if id.len() != 64 {
        return None;
    }
    let mut hash = [0u8; 32];
    for (i, byte) in hash.iter_mut().enumerate() {
        *byte = u8::from_str_radix(id.get(2 * i..2 * i + 2)?, 16).ok()?;
    }
    Some(hash)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_is_not_an_fmu_is_refused_and_nothing_is_kept() {
        let dir = tempfile::tempdir().unwrap();
        let fmus = Fmus::open(dir.path()).unwrap();
        let err = fmus.put("model.zip", b"PK").unwrap_err().to_string();
        assert!(err.starts_with("file_name:"), "{err}");
        let err = fmus.put("model.fmu", b"not a zip").unwrap_err().to_string();
        assert!(err.starts_with("fmu: "), "{err}");
        let big = vec![0u8; MAX_FMU_BYTES + 1];
        let err = fmus.put("big.fmu", &big).unwrap_err().to_string();
        assert!(err.contains("accepted"), "{err}");
        assert_eq!(fmus.get(&"0".repeat(64)).unwrap().map(|f| f.id), None);
        assert!(fmus.get("not-an-id").unwrap().is_none());
        let kept = std::fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| !e.as_ref().unwrap().path().is_dir())
            .count();
        assert_eq!(kept, 0);
    }
}
