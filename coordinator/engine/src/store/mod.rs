//! Persistent state of the coordinator: every evaluation ever simulated, the campaigns and
//! the measurements they were fitted to.
//!
//! A [`Store`] has three collections (sled trees in [`SledStore`], maps in [`MemoryStore`]):
//!
//! * `evaluations`: [`EvaluationKey`] → [`Evaluation`]. The key hashes the objective's
//!   fingerprint (model id and version, fixed parameters, which parameters are free, time
//!   grid, measurement hash, output mapping, weights, solver settings) with the exact bits
//!   of the point, so anything that changes the answer changes the key; a new model version
//!   misses every entry of the old one.
//! * `campaigns`: [`CampaignId`] → [`CampaignRecord`] (the campaign file's text and path,
//!   status, per-run best, result when finished).
//! * `datasets`: measurement content hash → the measured columns, so an unfinished campaign
//!   resumes even when its data file has moved.
//!
//! [`Store::put_evaluations`] returns only once the entries are durable: the evaluator that
//! answers the optimisers calls it before it answers, so a process killed at any moment
//! has lost at most the evaluations it had not yet reported. The byte layouts are in
//! [`encoding`]; [`export`] writes and reads a versioned, line-oriented copy of a store.

mod batch_log;
mod damage;
mod dataset_files;
mod dispatcher;
pub mod encoding;
pub mod engine;
pub mod evaluator;
pub mod export;
mod key_filter;
mod memory;
mod sled;

pub use self::evaluator::{SharedDispatcher, Stored, StoredEvaluator};
pub use self::memory::MemoryStore;
pub use self::sled::SledStore;

use crate::objective::{Evaluation, Objective};
use calib_model::content_hash::ContentHasher;
use std::fmt;
use std::path::PathBuf;

/// Identifies an evaluation: blake3 of the objective's fingerprint and the point's bits.
pub type EvaluationKey = [u8; 32];

/// Identifies a campaign: blake3 of the resolved campaign (see `Campaign::identity`).
pub type CampaignId = [u8; 32];

/// Content hash of a measurement (`Measurement::content_hash`).
pub type DatasetHash = [u8; 32];

/// The key of `objective` evaluated at `point` (values of the free parameters).
///
/// Layout hashed: the tag `calib.evaluation.v1\0`, the 32-byte objective fingerprint, the
/// number of values as little-endian `u64`, then each value's IEEE-754 bits, little-endian.
pub fn evaluation_key(objective: &Objective, point: &[f64]) -> EvaluationKey {
    evaluation_key_from(&objective.fingerprint(), point)
}

/// [`evaluation_key`] from a fingerprint.
pub fn evaluation_key_from(fingerprint: &[u8; 32], point: &[f64]) -> EvaluationKey {
    ContentHasher::new(EVALUATION_KEY_TAG)
        .bytes(fingerprint)
        .series(point)
        .finish()
}

const EVALUATION_KEY_TAG: &[u8] = b"calib.evaluation.v1\0";

/// Where a campaign stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CampaignStatus {
    /// Started and not finished: resumed at the coordinator's next start.
    Running,
    Finished,
    /// Could not be resumed (its spec no longer resolves, its data is gone): never retried.
    Failed,
    /// Stopped on request: never resumed.
    Cancelled,
}

/// The best point one run (one method from one start) reached.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RunBest {
    pub method: String,
    pub start: usize,
    pub point: Vec<f64>,
    pub objective: f64,
    pub evaluations: usize,
    /// Batches it sent and waited for (0 in records written before rounds were counted).
    #[serde(default)]
    pub rounds: usize,
}

/// A campaign as the store keeps it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CampaignRecord {
    pub name: String,
    /// The campaign file's text, as written.
    pub spec: String,
    /// The campaign file's path: relative measurement paths resolve against its folder.
    pub source: PathBuf,
    /// Content hash of the measurement (hex), a key of the datasets collection.
    pub dataset: String,
    pub status: CampaignStatus,
    /// Per-run best, in run order (filled when the campaign finishes).
    #[serde(default)]
    pub runs: Vec<RunBest>,
    /// What the finished campaign found (its `result.json`). A result this version cannot
    /// read (written by a much older one) reads as none, with a warning, rather than making
    /// the whole record unreadable.
    #[serde(default, deserialize_with = "readable_result")]
    pub result: Option<crate::outcome::CalibrationOutcome>,
    /// Why it failed, when it did.
    #[serde(default)]
    pub failure: Option<String>,
    /// The Calibration API's `Campaign` message it was submitted with (JSON, the proto's
    /// field names), when it came through the API: what a client edits to run it again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<serde_json::Value>,
    /// Names of the free parameters, in the order of each run's point.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub free: Vec<String>,
    /// Its progress over time (thinned to a bounded number of points), for plots of a
    /// campaign reopened after the fact.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub history: Vec<ProgressPoint>,
}

/// A stored result as [`CampaignRecord::result`] keeps it: none when it does not read as
/// an outcome.
fn readable_result<'de, D: serde::Deserializer<'de>>(
    d: D,
) -> Result<Option<crate::outcome::CalibrationOutcome>, D::Error> {
    let Some(value) = <Option<serde_json::Value> as serde::Deserialize>::deserialize(d)? else {
        return Ok(None);
    };
    match serde_json::from_value(value) {
        Ok(outcome) => Ok(Some(outcome)),
        Err(e) => {
            tracing::warn!(error = %e, "a stored campaign's result cannot be read: left out");
            Ok(None)
        }
    }
}

/// One moment of a campaign's progress: evaluations so far and each run's best objective.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ProgressPoint {
    pub evaluations: u64,
    /// Best objective per run, in plan order; `None` before a run's first point.
    pub run_best: Vec<Option<f64>>,
}

/// What a store holds and how it has been used.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct StoreStats {
    pub evaluations: u64,
    pub campaigns: u64,
    pub datasets: u64,
    /// Bytes the store takes (on disk for sled, encoded entries in memory).
    pub bytes: u64,
    /// Evaluations served from the store, over the store's life.
    pub hits: u64,
    /// Evaluations that had to be simulated, over the store's life.
    pub misses: u64,
}

/// A failure of the store itself (disk, corruption): never the user's input.
#[derive(Debug, Clone, thiserror::Error)]
pub enum StoreError {
    #[error("cannot open the store at {path}: {message}")]
    Open { path: PathBuf, message: String },
    #[error("store I/O failed: {0}")]
    Io(String),
    #[error("store entry is corrupt: {0}")]
    Corrupt(String),
    #[error("cannot import: {0}")]
    Import(String),
    /// sled cannot read the store's files (it panicked or reported corruption).
    #[error(
        "the store at {} is damaged and cannot be read ({detail}): restore that folder from a \
         backup, or move it aside and import an export made earlier (`calib store import --db \
         {} < EXPORT`); without either, moving it aside starts an empty store and every point \
         is simulated again",
        .path.display(), .path.display()
    )]
    Damaged { path: PathBuf, detail: String },
}

impl From<::sled::Error> for StoreError {
    fn from(e: ::sled::Error) -> Self {
        match e {
            ::sled::Error::Corruption { .. } => StoreError::Corrupt(e.to_string()),
            _ => StoreError::Io(e.to_string()),
        }
    }
}

/// The coordinator's persistent state. Shared by every run thread of every campaign.
pub trait Store: Send + Sync {
    /// The stored evaluation of each key, in order.
    fn get_evaluations(
        &self,
        keys: &[EvaluationKey],
    ) -> Result<Vec<Option<Evaluation>>, StoreError>;

    /// Store `entries` and return once they are durable. Concurrent calls share flushes.
    fn put_evaluations(&self, entries: &[(EvaluationKey, Evaluation)]) -> Result<(), StoreError>;

    /// Count evaluations served from the store (`hits`) and simulated (`misses`); the
    /// counts become durable with the next write.
    fn count_lookups(&self, hits: u64, misses: u64);

    /// Create or replace a campaign's record, durably.
    fn put_campaign(&self, id: &CampaignId, record: &CampaignRecord) -> Result<(), StoreError>;

    fn campaign(&self, id: &CampaignId) -> Result<Option<CampaignRecord>, StoreError>;

    /// Every campaign, in key order.
    fn campaigns(&self) -> Result<Vec<(CampaignId, CampaignRecord)>, StoreError>;

    /// Store a measurement's encoding (see [`encoding::encode_measurement`]) under its hash.
    fn put_dataset(&self, hash: &DatasetHash, bytes: &[u8]) -> Result<(), StoreError>;

    fn dataset(&self, hash: &DatasetHash) -> Result<Option<Vec<u8>>, StoreError>;

    /// Every entry of one collection as raw key and value bytes, in key order (export).
    fn raw_entries(&self, collection: Collection) -> Result<Vec<RawEntry>, StoreError>;

    /// Write raw entries into one collection, durably (import).
    fn put_raw(&self, collection: Collection, entries: &[RawEntry]) -> Result<(), StoreError>;

    fn stats(&self) -> Result<StoreStats, StoreError>;
}

/// A key and its encoded value.
pub type RawEntry = (Vec<u8>, Vec<u8>);

/// The collections of a store.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Collection {
    Evaluations,
    Campaigns,
    Datasets,
}

impl Collection {
    pub const ALL: [Collection; 3] = [
        Collection::Evaluations,
        Collection::Campaigns,
        Collection::Datasets,
    ];

    /// The sled tree's name and the export's record kind.
    pub fn name(self) -> &'static str {
        match self {
            Collection::Evaluations => "evaluations",
            Collection::Campaigns => "campaigns",
            Collection::Datasets => "datasets",
        }
    }

    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|c| c.name() == name)
    }
}

impl fmt::Display for Collection {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// Lower-case hex of `bytes`.
pub fn hex(bytes: &[u8]) -> String {
    use std::fmt::Write;
    bytes.iter().fold(String::new(), |mut s, b| {
        let _ = write!(s, "{b:02x}");
        s
    })
}

/// Bytes of lower-case or upper-case hex; `None` when malformed.
pub fn unhex(text: &str) -> Option<Vec<u8>> {
    let pairs = text.as_bytes().chunks_exact(2);
    if !pairs.remainder().is_empty() || !text.bytes().all(|b| b.is_ascii_hexdigit()) {
        return None;
    }
    pairs
        .map(|pair| u8::from_str_radix(std::str::from_utf8(pair).ok()?, 16).ok())
        .collect()
}

/// A 32-byte hash from hex.
pub fn unhex32(text: &str) -> Option<[u8; 32]> {
    unhex(text)?.try_into().ok()
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod hex_tests {
    use super::*;

    #[test]
    fn hex_round_trips() {
        let bytes = [0u8, 1, 0xab, 0xff];
        assert_eq!(hex(&bytes), "0001abff");
        assert_eq!(unhex("0001ABff").unwrap(), bytes);
        assert!(unhex("abc").is_none());
        assert!(unhex("zz").is_none());
        assert!(unhex("+f").is_none());
        assert!(unhex32("00").is_none());
    }

    #[test]
    fn evaluation_keys_follow_every_bit_of_the_point() {
        let f = [7u8; 32];
        let a = evaluation_key_from(&f, &[0.1, 0.2]);
        assert_eq!(a, evaluation_key_from(&f, &[0.1, 0.2]));
        assert_ne!(a, evaluation_key_from(&f, &[0.1, 0.2 + f64::EPSILON]));
        assert_ne!(a, evaluation_key_from(&f, &[0.1, 0.2, 0.0]));
        assert_ne!(a, evaluation_key_from(&[8u8; 32], &[0.1, 0.2]));
        assert_ne!(
            evaluation_key_from(&f, &[0.0]),
            evaluation_key_from(&f, &[-0.0])
        );
    }
}
