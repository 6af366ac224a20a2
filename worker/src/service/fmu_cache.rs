//! FMUs a worker keeps for later requests: `<hash>.fmu` files in one folder, bounded in
//! total size; the least recently used go first.

use calib_model::fmu::archive;
use std::path::{Path, PathBuf};
use std::sync::Mutex;
use std::time::SystemTime;

/// The on-disk FMU cache of a worker started with `--allow-fmu`.
pub struct FmuCache {
    dir: PathBuf,
    bound: u64,
    /// Serialises writes and evictions within this process.
    lock: Mutex<()>,
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

impl FmuCache {
    /// A cache in `dir` (created when absent) of at most `bound` bytes.
    pub fn new(dir: PathBuf, bound: u64) -> std::io::Result<Self> {
        std::fs::create_dir_all(&dir)?;
        Ok(Self {
            dir,
            bound,
            lock: Mutex::new(()),
        })
    }

    /// Where the archive named `hash` is kept.
    pub fn path(&self, hash: &[u8; 32]) -> PathBuf {
        self.dir.join(format!("{}.fmu", hex(hash)))
    }

    /// The folder FMUs of this cache are unpacked into.
    pub fn unpacked(&self) -> PathBuf {
        self.dir.join("unpacked")
    }

    /// What an archive kept here may be and inflate to: the bound of the cache applies to
    /// the inflated bytes too.
    pub fn limits(&self) -> archive::Limits {
        archive::Limits::default().within_cache(self.bound)
    }

    /// The archive named `hash`, if kept (and mark it used).
    pub fn get(&self, hash: &[u8; 32]) -> Option<Vec<u8>> {
        let path = self.path(hash);
        let bytes = std::fs::read(&path).ok()?;
        // A file whose content no longer matches its name is not served.
        if calib_model::fmu::content_hash(&bytes) != *hash {
            let _ = std::fs::remove_file(&path);
            return None;
        }
        if let Ok(file) = std::fs::File::options().append(true).open(&path) {
            let _ = file.set_modified(SystemTime::now());
        }
        Some(bytes)
    }

    /// Keep `bytes` under `hash`, then evict the least recently used others while the
    /// cache holds more than its bound.
    pub fn put(&self, hash: &[u8; 32], bytes: &[u8]) -> std::io::Result<()> {
        let _guard = self.lock.lock().unwrap_or_else(|e| e.into_inner());
        let path = self.path(hash);
        if !path.is_file() {
            let staging = self
                .dir
                .join(format!(".{}.{}", hex(hash), std::process::id()));
            let written =
                std::fs::write(&staging, bytes).and_then(|()| std::fs::rename(&staging, &path));
            if written.is_err() {
                let _ = std::fs::remove_file(&staging);
            }
            written?;
        }
        self.evict(&path)
    }

    fn evict(&self, keep: &Path) -> std::io::Result<()> {
        let mut files: Vec<(SystemTime, u64, PathBuf)> = std::fs::read_dir(&self.dir)?
            .filter_map(|e| e.ok())
            .filter(|e| e.path().extension().is_some_and(|x| x == "fmu"))
            .filter_map(|e| {
                let m = e.metadata().ok()?;
                Some((m.modified().ok()?, m.len(), e.path()))
            })
            .collect();
        let mut total: u64 = files.iter().map(|f| f.1).sum();
        files.sort();
        for (_, len, path) in files {
            if total <= self.bound {
                break;
            }
            if path != keep {
                let _ = std::fs::remove_file(&path);
                total -= len;
            }
        }
        Ok(())
    }

    /// Archives kept now.
    pub fn len(&self) -> usize {
        std::fs::read_dir(&self.dir).map_or(0, |d| {
            d.filter_map(|e| e.ok())
                .filter(|e| e.path().extension().is_some_and(|x| x == "fmu"))
                .count()
        })
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_least_recently_used_archives_go_first_when_the_bound_is_passed() {
        let dir = std::env::temp_dir().join(format!("calib-fmu-cache-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let cache = FmuCache::new(dir.clone(), 250).unwrap();
        let (a, b, c) = (vec![1u8; 100], vec![2u8; 100], vec![3u8; 100]);
        let hash = |x: &[u8]| calib_model::fmu::content_hash(x);
        // Ages set on the files themselves, not waited for: the order holds on any clock
        // and file system (a used archive is stamped now).
        let aged = |x: &[u8], seconds: u64| {
            let file = std::fs::File::options()
                .append(true)
                .open(cache.path(&hash(x)))
                .unwrap();
            file.set_modified(SystemTime::now() - std::time::Duration::from_secs(seconds))
                .unwrap();
        };
        cache.put(&hash(&a), &a).unwrap();
        aged(&a, 30);
        cache.put(&hash(&b), &b).unwrap();
        aged(&b, 20);
        assert_eq!(
            cache.get(&hash(&a)),
            Some(a.clone()),
            "a used again, after b"
        );
        cache.put(&hash(&c), &c).unwrap();
        assert_eq!(cache.len(), 2);
        assert_eq!(cache.get(&hash(&b)), None, "b was the least recently used");
        assert_eq!(cache.get(&hash(&a)), Some(a));
        assert_eq!(cache.get(&hash(&c)), Some(c));
        let _ = std::fs::remove_dir_all(&dir);
    }
}
