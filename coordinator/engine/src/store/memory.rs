//! A store that lives and dies with the process: for tests, and for calibrations that
//! were given no database.

use super::encoding;
use super::{
    CampaignId, CampaignRecord, Collection, DatasetHash, EvaluationKey, RawEntry, Store,
    StoreError, StoreStats,
};
use crate::objective::Evaluation;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;

/// Keeps encoded entries in ordered maps, exactly as [`super::SledStore`] keeps them on disk.
#[derive(Default)]
pub struct MemoryStore {
    collections: Mutex<[BTreeMap<Vec<u8>, Vec<u8>>; 3]>,
    hits: AtomicU64,
    misses: AtomicU64,
}

impl MemoryStore {
    pub fn new() -> Self {
        Self::default()
    }

    fn slot(collection: Collection) -> usize {
        match collection {
            Collection::Evaluations => 0,
            Collection::Campaigns => 1,
            Collection::Datasets => 2,
        }
    }

    fn with<T>(
        &self,
        collection: Collection,
        f: impl FnOnce(&mut BTreeMap<Vec<u8>, Vec<u8>>) -> T,
    ) -> T {
        let mut collections = self.collections.lock().expect("memory store lock");
        f(&mut collections[Self::slot(collection)])
    }
}

impl Store for MemoryStore {
    fn get_evaluations(
        &self,
        keys: &[EvaluationKey],
    ) -> Result<Vec<Option<Evaluation>>, StoreError> {
        self.with(Collection::Evaluations, |map| {
            keys.iter()
                .map(|k| {
                    map.get(&k[..])
                        .map(|v| encoding::decode_evaluation(v))
                        .transpose()
                })
                .collect()
        })
    }

    fn put_evaluations(&self, entries: &[(EvaluationKey, Evaluation)]) -> Result<(), StoreError> {
        let encoded: Vec<_> = entries
            .iter()
            .map(|(k, e)| (k.to_vec(), encoding::encode_evaluation(e)))
            .collect();
        self.put_raw(Collection::Evaluations, &encoded)
    }

    fn count_lookups(&self, hits: u64, misses: u64) {
        self.hits.fetch_add(hits, Ordering::Relaxed);
        self.misses.fetch_add(misses, Ordering::Relaxed);
    }

    fn put_campaign(&self, id: &CampaignId, record: &CampaignRecord) -> Result<(), StoreError> {
        let entry = (id.to_vec(), encoding::encode_campaign(record));
        self.put_raw(Collection::Campaigns, &[entry])
    }

    fn campaign(&self, id: &CampaignId) -> Result<Option<CampaignRecord>, StoreError> {
        self.with(Collection::Campaigns, |map| {
            map.get(&id[..])
                .map(|v| encoding::decode_campaign(v))
                .transpose()
        })
    }

    fn campaigns(&self) -> Result<Vec<(CampaignId, CampaignRecord)>, StoreError> {
        self.raw_entries(Collection::Campaigns)?
            .into_iter()
            .map(|(k, v)| {
                let id = k
                    .try_into()
                    .map_err(|_| StoreError::Corrupt("campaign id is not 32 bytes".into()))?;
                Ok((id, encoding::decode_campaign(&v)?))
            })
            .collect()
    }

    fn put_dataset(&self, hash: &DatasetHash, bytes: &[u8]) -> Result<(), StoreError> {
        self.put_raw(Collection::Datasets, &[(hash.to_vec(), bytes.to_vec())])
    }

    fn dataset(&self, hash: &DatasetHash) -> Result<Option<Vec<u8>>, StoreError> {
        Ok(self.with(Collection::Datasets, |map| map.get(&hash[..]).cloned()))
    }

    fn raw_entries(&self, collection: Collection) -> Result<Vec<RawEntry>, StoreError> {
        Ok(self.with(collection, |map| {
            map.iter().map(|(k, v)| (k.clone(), v.clone())).collect()
        }))
    }

    fn put_raw(&self, collection: Collection, entries: &[RawEntry]) -> Result<(), StoreError> {
        self.with(collection, |map| {
            for (k, v) in entries {
                map.insert(k.clone(), v.clone());
            }
        });
        Ok(())
    }

    fn stats(&self) -> Result<StoreStats, StoreError> {
        let collections = self.collections.lock().expect("memory store lock");
        let bytes = collections
            .iter()
            .flat_map(|m| m.iter())
            .map(|(k, v)| (k.len() + v.len()) as u64)
            .sum();
        Ok(StoreStats {
            evaluations: collections[0].len() as u64,
            campaigns: collections[1].len() as u64,
            datasets: collections[2].len() as u64,
            bytes,
            hits: self.hits.load(Ordering::Relaxed),
            misses: self.misses.load(Ordering::Relaxed),
        })
    }
}
