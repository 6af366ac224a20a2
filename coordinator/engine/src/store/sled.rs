//! The store on disk, in a sled database (sled 0.34: beta, its on-disk format will change
//! before 1.0, hence `calib store export`/`import`).
//!
//! One tree per collection plus `meta` (layout version, lookup counters); the layouts are
//! in [`super::encoding`]. Evaluations the campaigns simulate are written a batch per value
//! ([`super::batch_log`]); those imported, and those of stores written before layout 2, are
//! one value per key in `evaluations`. Both are read by every lookup. sled allows one open
//! database per path per process: open it once and share the [`SledStore`].
//!
//! Durability: each write is flushed (fsynced) before it returns. `flush` blocks, so it runs
//! on the calling thread, never on an async runtime. Writes do not need grouping here: a
//! process has one writer of evaluations, its dispatcher's (one per coordinator, one per
//! command; see [`super::evaluator`]), which writes a whole round per value and per flush;
//! campaign records are written only as a campaign starts and ends. `flush_async` is not
//! used (it can deadlock in 0.34).

use super::batch_log::BatchLog;
use super::damage::{self, guarded};
use super::dataset_files::DatasetFiles;
use super::encoding::{self, LAYOUT_VERSION};
use super::key_filter::KeyFilter;
use super::{
    CampaignId, CampaignRecord, Collection, DatasetHash, EvaluationKey, RawEntry, Store,
    StoreError, StoreStats,
};
use crate::objective::Evaluation;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

const LAYOUT_KEY: &[u8] = b"layout";
/// Layouts this version opens: 1 (no evaluation batches) is taken as it is and marked 2.
const READABLE_LAYOUTS: [u32; 2] = [1, LAYOUT_VERSION];
const BATCHES_TREE: &str = "evaluation-batches";
const HITS_KEY: &[u8] = b"hits";
const MISSES_KEY: &[u8] = b"misses";

/// A [`Store`] in a sled database.
pub struct SledStore {
    path: PathBuf,
    db: sled::Db,
    evaluations: sled::Tree,
    batches: BatchLog,
    campaigns: sled::Tree,
    /// Datasets of stores written before they were files: read, never written.
    datasets: sled::Tree,
    dataset_files: DatasetFiles,
    meta: sled::Tree,
    /// Which keys `evaluations` may hold: new points skip the lookup in sled.
    evaluation_keys: KeyFilter,
    /// Lookup counts not yet added to `meta`.
    pending_hits: AtomicU64,
    pending_misses: AtomicU64,
    flushes: AtomicU64,
    /// Evaluation lookups that reached sled.
    sled_lookups: AtomicU64,
}

impl SledStore {
    /// Open (or create) the store in `path`. Fails when another process has it open, and
    /// with [`StoreError::Damaged`] when its files cannot be read.
    pub fn open(path: &Path) -> Result<Self, StoreError> {
        guarded(path, || Self::open_unguarded(path)).map_err(|e| match e {
            StoreError::Corrupt(detail) => damage::damaged(path, &detail),
            e => e,
        })
    }

    fn open_unguarded(path: &Path) -> Result<Self, StoreError> {
        let open_error = |message: String| StoreError::Open {
            path: path.to_path_buf(),
            message,
        };
        let db = open_db(path, || {
            sled::Config::new().path(path).cache_capacity(64 << 20)
        })
        .map_err(|e| match e {
            e if is_locked(&e) => open_error(
                "it is in use by another process (one calib process per store at a time)".into(),
            ),
            e @ sled::Error::Corruption { .. } => damage::damaged(path, &e.to_string()),
            e => open_error(e.to_string()),
        })?;
        let tree = |name: &str| db.open_tree(name).map_err(|e| open_error(e.to_string()));
        let evaluations = tree(Collection::Evaluations.name())?;
        let evaluation_keys = KeyFilter::build(evaluations.clone());
        let store = Self {
            evaluations,
            batches: BatchLog::open(tree(BATCHES_TREE)?)?,
            evaluation_keys,
            campaigns: tree(Collection::Campaigns.name())?,
            datasets: tree(Collection::Datasets.name())?,
            dataset_files: DatasetFiles::open(path)?,
            meta: tree("meta")?,
            path: path.to_path_buf(),
            db,
            pending_hits: AtomicU64::new(0),
            pending_misses: AtomicU64::new(0),
            flushes: AtomicU64::new(0),
            sled_lookups: AtomicU64::new(0),
        };
        let layout = store.meta.get(LAYOUT_KEY)?;
        let readable = |v: &[u8]| READABLE_LAYOUTS.iter().any(|l| v == l.to_le_bytes());
        match layout {
            Some(v) if v.as_ref() == LAYOUT_VERSION.to_le_bytes() => {}
            None => store.mark_layout()?,
            Some(v) if readable(&v) => store.mark_layout()?,
            Some(v) => {
                return Err(open_error(format!(
                    "its layout version is {:?}, this calib reads {LAYOUT_VERSION}: \
                     export it with the calib that wrote it and import it here",
                    v.as_ref()
                )))
            }
        }
        Ok(store)
    }

    /// Mark the store as of this version's layout (what older versions refuse to open).
    fn mark_layout(&self) -> Result<(), StoreError> {
        self.meta
            .insert(LAYOUT_KEY, &LAYOUT_VERSION.to_le_bytes())?;
        self.db.flush()?;
        Ok(())
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Dataset files whose dataset the `datasets` tree does not also hold.
    fn file_only_datasets(&self) -> Result<u64, StoreError> {
        let mut n = 0;
        for hash in self.dataset_files.hashes()? {
            n += u64::from(!self.datasets.contains_key(hash)?);
        }
        Ok(n)
    }

    /// Flushes (fsyncs) made so far by this process.
    pub fn flushes(&self) -> u64 {
        self.flushes.load(Ordering::Relaxed)
    }

    /// Wait until the filter of evaluation keys has read the keys on disk.
    #[cfg(test)]
    pub(crate) fn wait_for_key_filter(&self) {
        self.evaluation_keys.wait();
        assert!(self.evaluation_keys.is_ready(), "the key filter was built");
    }

    /// Evaluation lookups made in sled so far (the others were known misses).
    pub fn sled_lookups(&self) -> u64 {
        self.sled_lookups.load(Ordering::Relaxed)
    }

    /// Run `call` on sled, a panic on damaged files being an error.
    fn guard<T>(&self, call: impl FnOnce() -> Result<T, StoreError>) -> Result<T, StoreError> {
        guarded(&self.path, call)
    }

    fn tree(&self, collection: Collection) -> &sled::Tree {
        match collection {
            Collection::Evaluations => &self.evaluations,
            Collection::Campaigns => &self.campaigns,
            Collection::Datasets => &self.datasets,
        }
    }

    /// Return once everything written before the call is on disk.
    fn make_durable(&self) -> Result<(), StoreError> {
        self.guard(|| self.flush_now())
    }

    /// Add the pending lookup counts to `meta` and fsync.
    fn flush_now(&self) -> Result<(), StoreError> {
        self.persist_counter(HITS_KEY, self.pending_hits.swap(0, Ordering::Relaxed))?;
        self.persist_counter(MISSES_KEY, self.pending_misses.swap(0, Ordering::Relaxed))?;
        self.db.flush()?;
        self.flushes.fetch_add(1, Ordering::Relaxed);
        Ok(())
    }

    fn persist_counter(&self, key: &[u8], add: u64) -> Result<(), StoreError> {
        if add > 0 {
            self.meta.fetch_and_update(key, |old| {
                let n = old.map_or(0, encoding::decode_counter) + add;
                Some(encoding::encode_counter(n).to_vec())
            })?;
        }
        Ok(())
    }

    /// Evaluations the batches hold that `evaluations` does not.
    fn batched_only(&self) -> Result<u64, StoreError> {
        let keys = self.batches.keys();
        let maybe = self.evaluation_keys.may_hold(keys.iter().map(|k| &k[..]));
        let mut only = 0;
        for (k, maybe) in keys.iter().zip(maybe) {
            if !maybe || !self.evaluations.contains_key(k)? {
                only += 1;
            }
        }
        Ok(only)
    }

    fn counter(&self, key: &[u8]) -> Result<u64, StoreError> {
        Ok(self
            .meta
            .get(key)?
            .map_or(0, |v| encoding::decode_counter(&v)))
    }
}

/// Whether sled could not open because its file is locked.
fn is_locked(error: &sled::Error) -> bool {
    matches!(error, sled::Error::Io(io)
        if io.kind() == std::io::ErrorKind::WouldBlock || io.to_string().contains("acquire lock"))
}

/// How long an opening waits for the lock of a store closed a moment ago.
const LOCK_RELEASE: std::time::Duration = std::time::Duration::from_secs(2);

/// Open the database `config` describes. sled's background writes hold its file, and so its
/// lock, for a moment after the last handle is dropped: a store closed and opened again in
/// one process (a coordinator restarted in place) waits for that, up to [`LOCK_RELEASE`],
/// before it is taken as held by another process.
pub(crate) fn open_db(
    path: &Path,
    config: impl Fn() -> sled::Config,
) -> Result<sled::Db, sled::Error> {
    let deadline = std::time::Instant::now() + LOCK_RELEASE;
    loop {
        match config().open() {
            Err(e) if is_locked(&e) && std::time::Instant::now() < deadline => {
                tracing::debug!(store = %path.display(), "waiting for the store's lock");
                std::thread::sleep(std::time::Duration::from_millis(20));
            }
            opened => return opened,
        }
    }
}

impl Drop for SledStore {
    fn drop(&mut self) {
        if let Err(e) = self.guard(|| self.flush_now()) {
            tracing::warn!(store = %self.path.display(), error = %e, "final flush failed");
        }
    }
}

impl Store for SledStore {
    fn get_evaluations(
        &self,
        keys: &[EvaluationKey],
    ) -> Result<Vec<Option<Evaluation>>, StoreError> {
        self.guard(|| {
            let batched = self.batches.get(keys)?;
            let maybe = self.evaluation_keys.may_hold(keys.iter().map(|k| &k[..]));
            keys.iter()
                .zip(maybe)
                .zip(batched)
                .map(|((k, maybe), batched)| {
                    if batched.is_some() || !maybe {
                        return Ok(batched);
                    }
                    self.sled_lookups.fetch_add(1, Ordering::Relaxed);
                    self.evaluations
                        .get(k)?
                        .map(|v| encoding::decode_evaluation(&v))
                        .transpose()
                })
                .collect()
        })
    }

    /// One value for all of `entries` ([`BatchLog`]), not a `sled::Batch` of one insert
    /// each: sled's cost is per insert, and its atomic batch also writes and syncs the log
    /// twice more (it rolls the log buffer before its manifest and seals the manifest's
    /// buffer after).
    fn put_evaluations(&self, entries: &[(EvaluationKey, Evaluation)]) -> Result<(), StoreError> {
        self.guard(|| {
            self.batches.append(entries)?;
            self.make_durable()
        })
    }

    fn count_lookups(&self, hits: u64, misses: u64) {
        self.pending_hits.fetch_add(hits, Ordering::Relaxed);
        self.pending_misses.fetch_add(misses, Ordering::Relaxed);
    }

    fn put_campaign(&self, id: &CampaignId, record: &CampaignRecord) -> Result<(), StoreError> {
        self.guard(|| {
            self.campaigns
                .insert(&id[..], encoding::encode_campaign(record))?;
            self.make_durable()
        })
    }

    fn campaign(&self, id: &CampaignId) -> Result<Option<CampaignRecord>, StoreError> {
        self.guard(|| {
            self.campaigns
                .get(id)?
                .map(|v| encoding::decode_campaign(&v))
                .transpose()
        })
    }

    fn campaigns(&self) -> Result<Vec<(CampaignId, CampaignRecord)>, StoreError> {
        self.guard(|| {
            self.campaigns
                .iter()
                .map(|entry| {
                    let (k, v) = entry?;
                    let id = k
                        .as_ref()
                        .try_into()
                        .map_err(|_| StoreError::Corrupt("campaign id is not 32 bytes".into()))?;
                    Ok((id, encoding::decode_campaign(&v)?))
                })
                .collect()
        })
    }

    fn put_dataset(&self, hash: &DatasetHash, bytes: &[u8]) -> Result<(), StoreError> {
        if self.guard(|| Ok(self.datasets.contains_key(hash)?))? {
            return Ok(());
        }
        self.dataset_files.put(hash, bytes)
    }

    fn dataset(&self, hash: &DatasetHash) -> Result<Option<Vec<u8>>, StoreError> {
        if let Some(bytes) = self.dataset_files.get(hash)? {
            return Ok(Some(bytes));
        }
        self.guard(|| Ok(self.datasets.get(hash)?.map(|v| v.to_vec())))
    }

    /// Evaluations in key order whether batched or not, as each was one value per key.
    fn raw_entries(&self, collection: Collection) -> Result<Vec<RawEntry>, StoreError> {
        self.guard(|| {
            let mut entries = self
                .tree(collection)
                .iter()
                .map(|entry| {
                    let (k, v) = entry?;
                    Ok((k.to_vec(), v.to_vec()))
                })
                .collect::<Result<Vec<RawEntry>, StoreError>>()?;
            if collection == Collection::Evaluations {
                let keyed: std::collections::HashSet<Vec<u8>> =
                    entries.iter().map(|(k, _)| k.clone()).collect();
                let batched = self.batches.raw_entries()?.into_iter();
                entries.extend(
                    batched
                        .map(|(k, v)| (k.to_vec(), v))
                        .filter(|(k, _)| !keyed.contains(k)),
                );
                entries.sort_unstable_by(|a, b| a.0.cmp(&b.0));
            }
            if collection == Collection::Datasets {
                let kept: std::collections::HashSet<Vec<u8>> =
                    entries.iter().map(|(k, _)| k.clone()).collect();
                let files = self.dataset_files.entries()?.into_iter();
                entries.extend(files.filter(|(k, _)| !kept.contains(k)));
                entries.sort_unstable_by(|a, b| a.0.cmp(&b.0));
            }
            Ok(entries)
        })
    }

    fn put_raw(&self, collection: Collection, entries: &[RawEntry]) -> Result<(), StoreError> {
        if collection == Collection::Datasets {
            for (k, v) in entries {
                let hash: DatasetHash = k[..]
                    .try_into()
                    .map_err(|_| StoreError::Corrupt("dataset hash is not 32 bytes".into()))?;
                self.put_dataset(&hash, v)?;
            }
            return Ok(());
        }
        self.guard(|| {
            if collection == Collection::Evaluations {
                self.evaluation_keys
                    .note(entries.iter().map(|(k, _)| &k[..]));
            }
            let mut batch = sled::Batch::default();
            for (k, v) in entries {
                batch.insert(&k[..], &v[..]);
            }
            self.tree(collection).apply_batch(batch)?;
            self.make_durable()
        })
    }

    fn stats(&self) -> Result<StoreStats, StoreError> {
        self.guard(|| {
            Ok(StoreStats {
                evaluations: self.evaluations.len() as u64 + self.batched_only()?,
                campaigns: self.campaigns.len() as u64,
                datasets: self.datasets.len() as u64 + self.file_only_datasets()?,
                bytes: self.db.size_on_disk()?,
                hits: self.counter(HITS_KEY)? + self.pending_hits.load(Ordering::Relaxed),
                misses: self.counter(MISSES_KEY)? + self.pending_misses.load(Ordering::Relaxed),
            })
        })
    }
}
