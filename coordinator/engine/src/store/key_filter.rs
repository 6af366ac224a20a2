//! Which evaluation keys a store on disk holds one value per key (its `evaluations` tree:
//! imported evaluations and those of layout 1), as a Bloom filter: a key the filter lacks is
//! not in that tree, so the lookup of a new point skips sled, where a miss walks the tree
//! (about a sixth of the coordinator's CPU per new point in batches of 256). Evaluations
//! written a round per value are found through their own index (`batch_log.rs`).
//!
//! The filter is built from the keys on disk by a thread of its own (about 1 µs per stored
//! key), so that opening a large store does not wait for it; until it is ready every lookup
//! goes to sled. Keys enter the filter (or, while it is built, a list it takes in when
//! ready) before they enter sled, so the filter never lacks a key that sled holds.

use growable_bloom_filter::GrowableBloom;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError, RwLock, RwLockWriteGuard};
use std::thread::JoinHandle;

/// False positives the filter starts at; as it grows with the store (growable-bloom-filter's
/// default tightening) they stay under about 7%, each one lookup in sled.
const ERROR_RATE: f64 = 0.01;
const INITIAL_CAPACITY: usize = 1 << 16;

pub struct KeyFilter {
    keys: Arc<RwLock<State>>,
    cancel: Arc<AtomicBool>,
    builder: Mutex<Option<JoinHandle<()>>>,
}

enum State {
    /// The keys on disk are being read; the keys written meanwhile.
    Reading(Vec<Vec<u8>>),
    Ready(GrowableBloom),
    /// Reading them failed: every lookup goes to sled.
    Unavailable,
}

impl KeyFilter {
    /// Start reading the keys of `tree`.
    pub fn build(tree: sled::Tree) -> Self {
        Self::build_after(tree, None)
    }

    /// [`KeyFilter::build`], the reading held back until `gate` receives (or closes).
    fn build_after(tree: sled::Tree, gate: Option<std::sync::mpsc::Receiver<()>>) -> Self {
        let keys = Arc::new(RwLock::new(State::Reading(Vec::new())));
        let cancel = Arc::new(AtomicBool::new(false));
        let builder = {
            let (keys, cancel) = (keys.clone(), cancel.clone());
            std::thread::Builder::new()
                .name("calib-store-keys".into())
                .spawn(move || {
                    // Unless the filter is made ready, the state ends `Unavailable`, also
                    // when this thread unwinds: lookups keep going to sled, slower, never
                    // wrong.
                    let mut guard = Unavailable(Some(&keys));
                    if let Some(gate) = gate {
                        let _ = gate.recv();
                    }
                    // sled panics on some damaged files: the store's calls say so, this
                    // thread stops without a word.
                    let read = super::damage::quietly(|| {
                        let mut filter = GrowableBloom::new(ERROR_RATE, INITIAL_CAPACITY);
                        for key in tree.iter().keys() {
                            if cancel.load(Ordering::Relaxed) {
                                return None;
                            }
                            match key {
                                Ok(key) => {
                                    filter.insert(&key[..]);
                                }
                                Err(e) => {
                                    tracing::warn!(error = %e, "cannot read the store's keys");
                                    return None;
                                }
                            }
                        }
                        Some(filter)
                    });
                    let Ok(Some(mut filter)) = read else {
                        return;
                    };
                    let mut state = write(&keys);
                    if let State::Reading(pending) = &*state {
                        for key in pending {
                            filter.insert(&key[..]);
                        }
                    }
                    *state = State::Ready(filter);
                    guard.0 = None;
                })
        };
        let builder = match builder {
            Ok(handle) => Some(handle),
            Err(e) => {
                tracing::warn!(error = %e, "cannot start the thread reading the store's keys");
                *write(&keys) = State::Unavailable;
                None
            }
        };
        Self {
            keys,
            cancel,
            builder: Mutex::new(builder),
        }
    }

    /// For each key, whether the store may hold it (always, until the filter is ready).
    pub fn may_hold<'k>(&self, keys: impl Iterator<Item = &'k [u8]>) -> Vec<bool> {
        match &*self.keys.read().unwrap_or_else(PoisonError::into_inner) {
            State::Ready(filter) => keys.map(|k| filter.contains(k)).collect(),
            State::Reading(_) | State::Unavailable => keys.map(|_| true).collect(),
        }
    }

    /// Note keys about to be written.
    pub fn note<'k>(&self, keys: impl Iterator<Item = &'k [u8]>) {
        match &mut *write(&self.keys) {
            State::Ready(filter) => keys.for_each(|k| {
                filter.insert(k);
            }),
            State::Reading(pending) => pending.extend(keys.map(<[u8]>::to_vec)),
            State::Unavailable => {}
        }
    }

    /// Whether the keys on disk have all been read.
    #[cfg(test)]
    pub fn is_ready(&self) -> bool {
        matches!(
            *self.keys.read().unwrap_or_else(PoisonError::into_inner),
            State::Ready(_)
        )
    }

    /// Wait until the keys on disk have been read (or reading them stopped).
    pub fn wait(&self) {
        if let Some(handle) = self.builder.lock().expect("builder lock").take() {
            let _ = handle.join();
        }
    }
}

/// The state, locked for writing (a panic elsewhere does not make it unusable: every
/// write leaves it whole).
fn write(keys: &RwLock<State>) -> RwLockWriteGuard<'_, State> {
    keys.write().unwrap_or_else(PoisonError::into_inner)
}

/// Sets the state `Unavailable` when dropped armed.
struct Unavailable<'a>(Option<&'a RwLock<State>>);

impl Drop for Unavailable<'_> {
    fn drop(&mut self) {
        if let Some(keys) = self.0 {
            *write(keys) = State::Unavailable;
        }
    }
}

impl Drop for KeyFilter {
    /// The reading thread holds the database open: stop it before the store closes.
    fn drop(&mut self) {
        self.cancel.store(true, Ordering::Relaxed);
        self.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_written_while_the_filter_reads_the_disk_are_kept() {
        let dir = tempfile::tempdir().unwrap();
        let db = sled::Config::new().path(dir.path()).open().unwrap();
        let tree = db.open_tree("evaluations").unwrap();
        let key = |i: u32| {
            let mut k = [0u8; 32];
            k[..4].copy_from_slice(&i.to_le_bytes());
            k[4] = 0xa5;
            k
        };
        for i in 0..5_000 {
            tree.insert(key(i), &[1u8][..]).unwrap();
        }
        let (start, gate) = std::sync::mpsc::channel();
        let filter = KeyFilter::build_after(tree.clone(), Some(gate));
        // Not yet reading: the keys noted now go to the pending list.
        assert!(!filter.is_ready());
        assert_eq!(filter.may_hold(std::iter::once(&key(60_000)[..])), [true]);
        let late: Vec<[u8; 32]> = (60_000..60_100).map(key).collect();
        filter.note(late.iter().map(|k| &k[..]));
        start.send(()).unwrap();
        filter.wait();
        assert!(filter.is_ready());
        let on_disk: Vec<[u8; 32]> = (0..5_000).map(key).collect();
        assert!(filter
            .may_hold(on_disk.iter().map(|k| &k[..]))
            .iter()
            .all(|&m| m));
        assert!(filter
            .may_hold(late.iter().map(|k| &k[..]))
            .iter()
            .all(|&m| m));
        let never: Vec<[u8; 32]> = (100_000..110_000).map(key).collect();
        let false_positives = filter
            .may_hold(never.iter().map(|k| &k[..]))
            .iter()
            .filter(|&&m| m)
            .count();
        assert!(false_positives < 300, "{false_positives} of 10,000");
    }
}
