//! Measurements the worker was sent, addressed by content hash, bounded in bytes.
//!
//! The least recently used measurement goes first when a new one would overflow the
//! bound. A client that finds its measurement gone simply sends it again.

use super::request::MeasuredData;
use std::collections::HashMap;
use std::sync::{Arc, Mutex};

pub struct MeasurementCache {
    bound: usize,
    state: Mutex<State>,
}

#[derive(Default)]
struct State {
    entries: HashMap<[u8; 32], Entry>,
    bytes: usize,
    clock: u64,
}

struct Entry {
    data: Arc<MeasuredData>,
    last_used: u64,
}

impl MeasurementCache {
    pub fn new(bound_bytes: usize) -> Self {
        Self {
            bound: bound_bytes,
            state: Mutex::new(State::default()),
        }
    }

    pub fn get(&self, hash: &[u8; 32]) -> Option<Arc<MeasuredData>> {
        let mut state = self.state.lock().expect("cache lock");
        state.clock += 1;
        let now = state.clock;
        state.entries.get_mut(hash).map(|e| {
            e.last_used = now;
            e.data.clone()
        })
    }

    /// Keep `data` under `hash` (which the caller checked), evicting the least recently
    /// used entries as needed; a measurement larger than the whole bound is used once and
    /// not kept.
    pub fn insert(&self, hash: [u8; 32], data: MeasuredData) -> Arc<MeasuredData> {
        let data = Arc::new(data);
        let size = data.bytes();
        if size > self.bound {
            return data;
        }
        let mut state = self.state.lock().expect("cache lock");
        state.clock += 1;
        let now = state.clock;
        if let Some(old) = state.entries.remove(&hash) {
            state.bytes -= old.data.bytes();
        }
        while state.bytes + size > self.bound {
            let Some(oldest) = state
                .entries
                .iter()
                .min_by_key(|(_, e)| e.last_used)
                .map(|(h, _)| *h)
            else {
                break;
            };
            let evicted = state.entries.remove(&oldest).expect("present");
            state.bytes -= evicted.data.bytes();
        }
        state.bytes += size;
        state.entries.insert(
            hash,
            Entry {
                data: data.clone(),
                last_used: now,
            },
        );
        data
    }

    /// Measurements held and their size [bytes].
    pub fn usage(&self) -> (usize, usize) {
        let state = self.state.lock().expect("cache lock");
        (state.entries.len(), state.bytes)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn data(n: usize) -> MeasuredData {
        MeasuredData {
            times: vec![0.0; n],
            columns: vec![vec![1.0; n]],
            inputs: vec![],
        }
    }

    #[test]
    fn evicts_the_least_recently_used_first() {
        let cache = MeasurementCache::new(3 * 160);
        cache.insert([1; 32], data(10));
        cache.insert([2; 32], data(10));
        cache.insert([3; 32], data(10));
        assert!(cache.get(&[1; 32]).is_some());
        cache.insert([4; 32], data(10));
        assert!(cache.get(&[2; 32]).is_none(), "least recently used evicted");
        assert!(cache.get(&[1; 32]).is_some());
        assert_eq!(cache.usage(), (3, 3 * 160));
    }

    #[test]
    fn a_measurement_beyond_the_bound_is_not_kept() {
        let cache = MeasurementCache::new(100);
        let kept = cache.insert([1; 32], data(100));
        assert_eq!(kept.times.len(), 100);
        assert_eq!(cache.usage(), (0, 0));
    }
}
