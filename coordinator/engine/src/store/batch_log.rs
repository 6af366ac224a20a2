//! Evaluations as sled writes them cheaply: each batch [`super::Store::put_evaluations`]
//! receives (a round of simulated points) is one value of its own tree, keyed by a sequence
//! number, and an index in memory says which batch holds which key.
//!
//! Why: sled's cost is per insert, not per byte. A round of ≈ 41 points inserted key by key
//! cost the coordinator about as much CPU as everything else it does for those points
//! (leaf copies, log reservations, page-table updates for each); one insert of the whole
//! round costs about a quarter of that, flush included (docs/performance.md). A round is
//! also durable or absent as a whole, never half written.
//!
//! The index holds, per key, the batch and the byte range of its evaluation (48 bytes and a
//! hash-map slot per stored point, ≈ 15 MB for 200,000 points); it is read from disk when the
//! store opens (the values' keys only). A lookup that the index answers reads the batch
//! from sled once for every key of it asked at the same time.
//!
//! Value layout: the version byte [`BATCH_V1`], then per evaluation its 32-byte key, the
//! length of its encoding (`u32`, little-endian) and the encoding of
//! [`super::encoding::encode_evaluation`].

use super::encoding;
use super::{EvaluationKey, StoreError};
use crate::objective::Evaluation;
use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{PoisonError, RwLock};

const BATCH_V1: u8 = 1;

/// Where an evaluation lies: its batch and the byte range of its encoding there.
#[derive(Debug, Clone, Copy)]
struct Slot {
    batch: u64,
    start: u32,
    len: u32,
}

pub(super) struct BatchLog {
    tree: sled::Tree,
    index: RwLock<HashMap<EvaluationKey, Slot>>,
    next: AtomicU64,
}

impl BatchLog {
    /// Read the keys of every batch in `tree`.
    pub(super) fn open(tree: sled::Tree) -> Result<Self, StoreError> {
        let mut index = HashMap::new();
        let mut next = 0;
        for entry in tree.iter() {
            let (key, value) = entry?;
            let batch = batch_number(&key)?;
            for (k, start, len) in entries(&value)? {
                index.insert(k, Slot { batch, start, len });
            }
            next = batch + 1;
        }
        Ok(Self {
            tree,
            index: RwLock::new(index),
            next: AtomicU64::new(next),
        })
    }

    /// Write `entries` as one batch (not yet flushed).
    pub(super) fn append(&self, entries: &[(EvaluationKey, Evaluation)]) -> Result<(), StoreError> {
        if entries.is_empty() {
            return Ok(());
        }
        let mut value = vec![BATCH_V1];
        let mut slots = Vec::with_capacity(entries.len());
        for (key, evaluation) in entries {
            let encoded = encoding::encode_evaluation(evaluation);
            value.extend_from_slice(key);
            value.extend_from_slice(&(encoded.len() as u32).to_le_bytes());
            slots.push((*key, value.len() as u32, encoded.len() as u32));
            value.extend_from_slice(&encoded);
        }
        let batch = self.next.fetch_add(1, Ordering::Relaxed);
        self.tree.insert(batch.to_be_bytes(), value)?;
        // Indexed once in sled, so that a lookup the index answers finds the batch.
        let mut index = self.index.write().unwrap_or_else(PoisonError::into_inner);
        for (key, start, len) in slots {
            index.insert(key, Slot { batch, start, len });
        }
        Ok(())
    }

    /// The evaluations of `keys` that the batches hold, `None` for the others.
    pub(super) fn get(
        &self,
        keys: &[EvaluationKey],
    ) -> Result<Vec<Option<Evaluation>>, StoreError> {
        let slots: Vec<Option<Slot>> = {
            let index = self.index.read().unwrap_or_else(PoisonError::into_inner);
            keys.iter().map(|k| index.get(k).copied()).collect()
        };
        let mut batches: HashMap<u64, sled::IVec> = HashMap::new();
        slots
            .into_iter()
            .map(|slot| {
                let Some(slot) = slot else { return Ok(None) };
                let value = match batches.get(&slot.batch) {
                    Some(value) => value,
                    None => {
                        let value = self.tree.get(slot.batch.to_be_bytes())?.ok_or_else(|| {
                            StoreError::Corrupt(format!(
                                "evaluation batch {} is missing",
                                slot.batch
                            ))
                        })?;
                        batches.entry(slot.batch).or_insert(value)
                    }
                };
                let (start, end) = (slot.start as usize, (slot.start + slot.len) as usize);
                let bytes = value.get(start..end).ok_or_else(|| {
                    StoreError::Corrupt(format!("evaluation batch {} is too short", slot.batch))
                })?;
                encoding::decode_evaluation(bytes).map(Some)
            })
            .collect()
    }

    /// Every evaluation the batches hold, by key (the latest where a key was written twice),
    /// encoded as [`encoding::encode_evaluation`] does.
    pub(super) fn raw_entries(&self) -> Result<Vec<(EvaluationKey, Vec<u8>)>, StoreError> {
        let mut latest: HashMap<EvaluationKey, Vec<u8>> = HashMap::new();
        for entry in self.tree.iter() {
            let (_, value) = entry?;
            for (k, start, len) in entries(&value)? {
                let (start, end) = (start as usize, (start + len) as usize);
                latest.insert(k, value[start..end].to_vec());
            }
        }
        Ok(latest.into_iter().collect())
    }

    /// The keys the batches hold.
    pub(super) fn keys(&self) -> Vec<EvaluationKey> {
        let index = self.index.read().unwrap_or_else(PoisonError::into_inner);
        index.keys().copied().collect()
    }
}

fn batch_number(key: &[u8]) -> Result<u64, StoreError> {
    key.try_into()
        .map(u64::from_be_bytes)
        .map_err(|_| StoreError::Corrupt(format!("evaluation batch key of {} bytes", key.len())))
}

/// The (key, start, length) of each evaluation in a batch's value.
fn entries(value: &[u8]) -> Result<Vec<(EvaluationKey, u32, u32)>, StoreError> {
    let corrupt = |what: &str| StoreError::Corrupt(format!("evaluation batch: {what}"));
    match value.first() {
        Some(&BATCH_V1) => {}
        Some(v) => return Err(corrupt(&format!("unknown layout version {v}"))),
        None => return Err(corrupt("empty")),
    }
    let mut out = Vec::new();
    let mut at = 1;
    while at < value.len() {
        let head = value
            .get(at..at + 36)
            .ok_or_else(|| corrupt("an entry is cut short"))?;
        let key: EvaluationKey = head[..32].try_into().expect("32 bytes");
        let len = u32::from_le_bytes(head[32..].try_into().expect("4 bytes"));
        let start = at + 36;
        let end = start
            .checked_add(len as usize)
            .filter(|&end| end <= value.len())
            .ok_or_else(|| corrupt("an evaluation is cut short"))?;
        out.push((key, start as u32, len));
        at = end;
    }
    Ok(out)
}
