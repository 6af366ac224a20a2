//! Reading and unpacking FMU archives within [`Limits`].
//!
//! A zip archive's headers say how large each file is and how many there are; none of it
//! is believed. The archive's own size is bounded before it is read, the number of entries
//! its end records claim before the zip reader sets aside room for them, and every file is
//! inflated through a bounded reader straight to disk, counting the bytes actually written:
//! an entry past its limit, or past the total, stops the unpacking there. An entry whose
//! header does not tell its true size is refused too. A refused archive leaves nothing
//! behind: the staging folder it was unpacked into is removed on every way out.

use super::FmuError;
use crate::limits;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// How large an FMU archive may be, and what it may inflate to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Limits {
    /// The archive itself [bytes].
    pub archive_bytes: u64,
    /// Entries (files and folders).
    pub entries: u64,
    /// One inflated file [bytes].
    pub entry_bytes: u64,
    /// All inflated files together [bytes].
    pub inflated_bytes: u64,
    /// What bounds `inflated_bytes`, named in a refusal.
    pub inflated_by: &'static str,
}

impl Default for Limits {
    fn default() -> Self {
        Self {
            archive_bytes: limits::MAX_FMU_ARCHIVE_BYTES,
            entries: limits::MAX_FMU_ENTRIES,
            entry_bytes: limits::MAX_FMU_ENTRY_BYTES,
            inflated_bytes: limits::MAX_FMU_INFLATED_BYTES,
            inflated_by: "the limit on an FMU's inflated size",
        }
    }
}

impl Limits {
    /// These limits, with everything inflated bounded by `bound` bytes too (a worker's FMU
    /// cache, `--fmu-cache-mib`).
    pub fn within_cache(self, bound: u64) -> Self {
        if bound >= self.inflated_bytes {
            return self;
        }
        Self {
            inflated_bytes: bound,
            entry_bytes: self.entry_bytes.min(bound),
            inflated_by: "the bound of this worker's FMU cache (--fmu-cache-mib)",
            ..self
        }
    }
}

/// `n` bytes, in MiB when whole.
fn amount(n: u64) -> String {
    if n >= 1 << 20 && n.is_multiple_of(1 << 20) {
        format!("{} MiB", n >> 20)
    } else {
        format!("{n} bytes")
    }
}

fn refused(what: String) -> FmuError {
    FmuError::Refused(what)
}

/// Refuse an archive of more than `limits.archive_bytes`.
pub fn check_size(len: u64, limits: &Limits) -> Result<(), FmuError> {
    if len > limits.archive_bytes {
        return Err(refused(format!(
            "the archive has more than {} (the limit on an FMU archive's size)",
            amount(limits.archive_bytes)
        )));
    }
    Ok(())
}

/// The archive at `path`, read through a bounded reader (its size as the file system says
/// it is not trusted either).
pub fn read(path: &Path, limits: &Limits) -> Result<Vec<u8>, FmuError> {
    let io = |e: std::io::Error| FmuError::Archive(format!("{}: {e}", path.display()));
    let file = std::fs::File::open(path).map_err(io)?;
    if let Ok(meta) = file.metadata() {
        check_size(meta.len(), limits)?;
    }
    let mut bytes = Vec::new();
    file.take(limits.archive_bytes + 1)
        .read_to_end(&mut bytes)
        .map_err(io)?;
    check_size(bytes.len() as u64, limits)?;
    Ok(bytes)
}

/// Refuse an archive whose end records claim more than `limits.entries` entries: the zip
/// reader sets aside room for as many as a record claims before it reads any. The 32-bit
/// record's counts are 16 bits (at most 65,535 entries, a few MiB of room); the zip64
/// record's are 64 bits, so each zip64 record anywhere in the archive is looked at (the
/// reader searches for them).
fn check_claimed_entries(bytes: &[u8], limits: &Limits) -> Result<(), FmuError> {
    const ZIP64_END: [u8; 4] = [0x50, 0x4b, 0x06, 0x06];
    let field = |record: &[u8], at: usize| -> Option<u64> {
        Some(u64::from_le_bytes(record.get(at..at + 8)?.try_into().ok()?))
    };
    let mut from = 0;
    while let Some(found) = bytes[from..].windows(4).position(|w| w == ZIP64_END) {
        let record = &bytes[from + found..];
        for at in [24, 32] {
            if let Some(claimed) = field(record, at).filter(|&n| n > limits.entries) {
                return Err(refused(format!(
                    "its zip64 end record claims {claimed} entries; the limit is {}",
                    limits.entries
                )));
            }
        }
        from += found + 1;
    }
    Ok(())
}

/// A folder that is removed when dropped, unless kept.
struct Staging {
    path: PathBuf,
    keep: bool,
}

impl Drop for Staging {
    fn drop(&mut self) {
        if !self.keep {
            let _ = std::fs::remove_dir_all(&self.path);
        }
    }
}

/// Unpack the archive `bytes` into `root/<name>/` once (into a staging folder renamed into
/// place, so a half-written folder is never used, and removed whatever goes wrong).
pub fn unpack(bytes: &[u8], name: &str, root: &Path, limits: &Limits) -> Result<PathBuf, FmuError> {
    let dir = root.join(name);
    if dir.join("modelDescription.xml").is_file() {
        return Ok(dir);
    }
    check_size(bytes.len() as u64, limits)?;
    check_claimed_entries(bytes, limits)?;
    let io = |e: std::io::Error| FmuError::Archive(e.to_string());
    std::fs::create_dir_all(root).map_err(io)?;
    static STAGED: AtomicU64 = AtomicU64::new(0);
    let staging = Staging {
        path: root.join(format!(
            ".{name}-{}-{}",
            std::process::id(),
            STAGED.fetch_add(1, Ordering::Relaxed)
        )),
        keep: false,
    };
    let _ = std::fs::remove_dir_all(&staging.path);
    std::fs::create_dir(&staging.path).map_err(io)?;
    inflate(bytes, &staging.path, limits)?;
    if !staging.path.join("modelDescription.xml").is_file() {
        return Err(FmuError::Archive(
            "no modelDescription.xml in the archive".into(),
        ));
    }
    match std::fs::rename(&staging.path, &dir) {
        Ok(()) => {
            let mut staging = staging;
            staging.keep = true;
            Ok(dir)
        }
        // Unpacked by another process first.
        Err(_) if dir.join("modelDescription.xml").is_file() => Ok(dir),
        Err(e) => Err(io(e)),
    }
}

/// Inflate every entry of the archive `bytes` into `into`, within `limits`.
fn inflate(bytes: &[u8], into: &Path, limits: &Limits) -> Result<(), FmuError> {
    let io = |e: std::io::Error| FmuError::Archive(e.to_string());
    let mut archive = zip::ZipArchive::new(std::io::Cursor::new(bytes))
        .map_err(|e| FmuError::Archive(format!("not a zip archive: {e}")))?;
    if archive.len() as u64 > limits.entries {
        return Err(refused(format!(
            "the archive has {} entries; the limit is {}",
            archive.len(),
            limits.entries
        )));
    }
    let mut inflated: u64 = 0;
    for i in 0..archive.len() {
        let mut entry = archive
            .by_index(i)
            .map_err(|e| FmuError::Archive(e.to_string()))?;
        let Some(relative) = entry.enclosed_name() else {
            return Err(FmuError::Archive(format!(
                "entry `{}` points outside the archive",
                entry.name()
            )));
        };
        let target = into.join(relative);
        if entry.is_dir() {
            std::fs::create_dir_all(&target).map_err(io)?;
            continue;
        }
        if let Some(parent) = target.parent() {
            std::fs::create_dir_all(parent).map_err(io)?;
        }
        let name = entry.name().to_string();
        let claimed = entry.size();
        let left = limits.inflated_bytes - inflated;
        let allowed = limits.entry_bytes.min(left);
        let mut file = std::fs::File::create(&target).map_err(io)?;
        // One byte past what is allowed tells that there was more; the copy goes through
        // a fixed buffer, whatever the entry claims.
        let written = std::io::copy(&mut (&mut entry).take(allowed + 1), &mut file)
            .map_err(|e| FmuError::Archive(format!("{name}: {e}")))?;
        if written > allowed {
            return Err(refused(if allowed == limits.entry_bytes {
                format!(
                    "{name} inflates to more than {} (the limit on one file of an FMU)",
                    amount(limits.entry_bytes)
                )
            } else {
                format!(
                    "the archive inflates to more than {} ({})",
                    amount(limits.inflated_bytes),
                    limits.inflated_by
                )
            }));
        }
        if written != claimed {
            return Err(FmuError::Archive(format!(
                "{name}: its header says {claimed} bytes, it holds {written}"
            )));
        }
        inflated += written;
    }
    Ok(())
}

/// The text of `modelDescription.xml` in the unpacked FMU at `dir`, read within
/// [`limits::MAX_FMU_DESCRIPTION_BYTES`].
pub fn read_description(dir: &Path) -> Result<String, FmuError> {
    let io = |e: std::io::Error| FmuError::Archive(format!("modelDescription.xml: {e}"));
    let file = std::fs::File::open(dir.join("modelDescription.xml")).map_err(io)?;
    let mut text = String::new();
    file.take(limits::MAX_FMU_DESCRIPTION_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(io)?;
    if text.len() as u64 > limits::MAX_FMU_DESCRIPTION_BYTES {
        return Err(refused(format!(
            "modelDescription.xml has more than {} (the limit on a model description)",
            amount(limits::MAX_FMU_DESCRIPTION_BYTES)
        )));
    }
    Ok(text)
}
