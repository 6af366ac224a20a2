//! Byte layouts of the stored values. Every value starts with a one-byte layout version;
//! a reader meeting an unknown version reports the entry as corrupt rather than guessing.
//! Integers are little-endian; floats are their IEEE-754 bits, little-endian, so values
//! come back bit for bit (NaN payloads and `-0.0` included).
//!
//! | collection | key | value (version 1) |
//! |---|---|---|
//! | `evaluations` | 32-byte [`EvaluationKey`](super::EvaluationKey) | `1u8`, objective `f64`, output count `u32`, per-output SSE `f64`s, failure flag `u8` (0 or 1), then if 1: byte length `u32` and UTF-8 message; an evaluation that carries weighted residuals starts with `2u8` instead and ends with the residual count `u32` and the residual `f64`s |
//! | `campaigns` | 32-byte [`CampaignId`](super::CampaignId) | `1u8`, UTF-8 JSON of [`CampaignRecord`] |
//! | `datasets` | 32-byte content hash | `1u8`, sample count `u64`, column count `u64`, time `f64`s, then per column: name byte length `u64`, UTF-8 name, values `f64`s |
//! | `meta` (sled only) | `b"layout"` / `b"hits"` / `b"misses"` | `u32` layout version / `u64` counters |
//!
//! The dataset layout is the one `Measurement::content_hash` hashes, so a decoded dataset
//! is checked against its key.

use super::{CampaignRecord, StoreError};
use crate::measurement::Measurement;
use crate::objective::Evaluation;
use std::path::PathBuf;

/// Version of the layouts above; stored in the `meta` tree of a sled store. 2: evaluations
/// are also written a batch per value (`store::batch_log`), which version 1 does not read.
pub const LAYOUT_VERSION: u32 = 2;

const V1: u8 = 1;

/// The evaluation layout with weighted residuals after the version-1 fields. Evaluations
/// without residuals keep version 1, byte for byte.
const V2_RESIDUALS: u8 = 2;

pub fn encode_evaluation(e: &Evaluation) -> Vec<u8> {
    let failure = e.failure.as_deref().map(str::as_bytes);
    let residuals = if e.residuals.is_empty() {
        0
    } else {
        4 + 8 * e.residuals.len()
    };
    let mut out = Vec::with_capacity(
        1 + 8 + 4 + 8 * e.sse.len() + 1 + failure.map_or(0, |f| 4 + f.len()) + residuals,
    );
    out.push(if e.residuals.is_empty() {
        V1
    } else {
        V2_RESIDUALS
    });
    out.extend_from_slice(&e.objective.to_bits().to_le_bytes());
    out.extend_from_slice(&(e.sse.len() as u32).to_le_bytes());
    for s in &e.sse {
        out.extend_from_slice(&s.to_bits().to_le_bytes());
    }
    match failure {
        None => out.push(0),
        Some(f) => {
            out.push(1);
            out.extend_from_slice(&(f.len() as u32).to_le_bytes());
            out.extend_from_slice(f);
        }
    }
    if !e.residuals.is_empty() {
        out.extend_from_slice(&(e.residuals.len() as u32).to_le_bytes());
        for r in &e.residuals {
            out.extend_from_slice(&r.to_bits().to_le_bytes());
        }
    }
    out
}

pub fn decode_evaluation(bytes: &[u8]) -> Result<Evaluation, StoreError> {
    let mut r = Reader::new(bytes, "evaluation");
    let with_residuals = match r.u8()? {
        V1 => false,
        V2_RESIDUALS => true,
        v => return Err(r.corrupt(format!("unknown layout version {v}"))),
    };
    let objective = r.f64()?;
    let outputs = r.u32()? as usize;
    let sse = (0..outputs).map(|_| r.f64()).collect::<Result<_, _>>()?;
    let failure = match r.u8()? {
        0 => None,
        1 => {
            let len = r.u32()? as usize;
            Some(r.utf8(len)?)
        }
        flag => return Err(r.corrupt(format!("failure flag {flag}"))),
    };
    let residuals = if with_residuals {
        let count = r.u32()? as usize;
        r.f64s(count)?
    } else {
        Vec::new()
    };
    r.end()?;
    Ok(Evaluation {
        objective,
        sse,
        failure,
        residuals,
    })
}

pub fn encode_campaign(record: &CampaignRecord) -> Vec<u8> {
    let mut out = vec![V1];
    serde_json::to_writer(&mut out, record).expect("a campaign record is plain data");
    out
}

pub fn decode_campaign(bytes: &[u8]) -> Result<CampaignRecord, StoreError> {
    let mut r = Reader::new(bytes, "campaign");
    r.version()?;
    serde_json::from_slice(r.rest())
        .map_err(|e| StoreError::Corrupt(format!("campaign record: {e}")))
}

pub fn encode_measurement(m: &Measurement) -> Vec<u8> {
    let values = m.time.len() * (1 + m.columns.len());
    let names: usize = m.columns.iter().map(|(n, _)| 8 + n.len()).sum();
    let mut out = Vec::with_capacity(1 + 16 + 8 * values + names);
    out.push(V1);
    out.extend_from_slice(&(m.time.len() as u64).to_le_bytes());
    out.extend_from_slice(&(m.columns.len() as u64).to_le_bytes());
    let f64s = |out: &mut Vec<u8>, values: &[f64]| {
        for v in values {
            out.extend_from_slice(&v.to_bits().to_le_bytes());
        }
    };
    f64s(&mut out, &m.time);
    for (name, values) in &m.columns {
        out.extend_from_slice(&(name.len() as u64).to_le_bytes());
        out.extend_from_slice(name.as_bytes());
        f64s(&mut out, values);
    }
    out
}

/// Rebuild a measurement stored by [`encode_measurement`]; `source` names where it came from.
pub fn decode_measurement(bytes: &[u8], source: PathBuf) -> Result<Measurement, StoreError> {
    let mut r = Reader::new(bytes, "dataset");
    r.version()?;
    let samples = r.count()?;
    let columns = r.count()?;
    let time = r.f64s(samples)?;
    let columns = (0..columns)
        .map(|_| {
            let len = r.count()?;
            let name = r.utf8(len)?;
            Ok((name, r.f64s(samples)?))
        })
        .collect::<Result<_, StoreError>>()?;
    r.end()?;
    Ok(Measurement {
        source,
        time,
        columns,
    })
}

pub fn encode_counter(n: u64) -> [u8; 8] {
    n.to_le_bytes()
}

pub fn decode_counter(bytes: &[u8]) -> u64 {
    bytes.try_into().map(u64::from_le_bytes).unwrap_or(0)
}

/// Reads a value front to back, naming what it reads in its errors.
struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    what: &'static str,
}

impl<'a> Reader<'a> {
    fn new(bytes: &'a [u8], what: &'static str) -> Self {
        Self { bytes, at: 0, what }
    }

    fn corrupt(&self, message: String) -> StoreError {
        StoreError::Corrupt(format!("{} at byte {}: {message}", self.what, self.at))
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], StoreError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(self.corrupt(format!("truncated ({} bytes)", self.bytes.len())));
        };
        let slice = &self.bytes[self.at..end];
        self.at = end;
        Ok(slice)
    }

    fn version(&mut self) -> Result<(), StoreError> {
        match self.u8()? {
            V1 => Ok(()),
            v => Err(self.corrupt(format!("unknown layout version {v}"))),
        }
    }

    fn u8(&mut self) -> Result<u8, StoreError> {
        Ok(self.take(1)?[0])
    }

    fn u32(&mut self) -> Result<u32, StoreError> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }

    fn u64(&mut self) -> Result<u64, StoreError> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }

    /// A count that must fit in what is left (so a corrupt count cannot allocate wildly).
    fn count(&mut self) -> Result<usize, StoreError> {
        let n = self.u64()?;
        if n > (self.bytes.len() - self.at) as u64 {
            return Err(self.corrupt(format!("count {n} exceeds the value")));
        }
        Ok(n as usize)
    }

    fn f64(&mut self) -> Result<f64, StoreError> {
        Ok(f64::from_bits(self.u64()?))
    }

    fn f64s(&mut self, n: usize) -> Result<Vec<f64>, StoreError> {
        let bytes = self.take(n.saturating_mul(8))?;
        Ok(bytes
            .chunks_exact(8)
            .map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes")))
            .collect())
    }

    fn utf8(&mut self, len: usize) -> Result<String, StoreError> {
        let bytes = self.take(len)?;
        String::from_utf8(bytes.to_vec()).map_err(|e| self.corrupt(e.to_string()))
    }

    fn rest(&mut self) -> &'a [u8] {
        let rest = &self.bytes[self.at..];
        self.at = self.bytes.len();
        rest
    }

    fn end(&self) -> Result<(), StoreError> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(self.corrupt(format!("{} trailing bytes", self.bytes.len() - self.at)))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{CampaignStatus, RunBest};

    #[test]
    fn evaluations_round_trip_bit_for_bit() {
        let cases = [
            Evaluation {
                objective: 0.1 + 0.2,
                sse: vec![1e-300, -0.0, 3.5],
                failure: None,
                residuals: Vec::new(),
            },
            Evaluation {
                objective: 0.5,
                sse: vec![0.25, 0.25],
                failure: None,
                residuals: vec![0.5, -0.0, f64::MIN_POSITIVE, -0.5],
            },
            Evaluation::failed(2, "step limit (200000) reached at t = 3.2 s".into()),
            Evaluation {
                objective: 0.0,
                sse: vec![],
                failure: Some("é".into()),
                residuals: Vec::new(),
            },
        ];
        for e in cases {
            let back = decode_evaluation(&encode_evaluation(&e)).unwrap();
            assert_eq!(back.objective.to_bits(), e.objective.to_bits());
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&back.sse), bits(&e.sse));
            assert_eq!(back.failure, e.failure);
            assert_eq!(bits(&back.residuals), bits(&e.residuals));
        }
    }

    #[test]
    fn the_evaluation_layout_is_pinned() {
        let e = Evaluation {
            objective: 1.0,
            sse: vec![2.0],
            failure: Some("x".into()),
            residuals: Vec::new(),
        };
        let mut expected = vec![1u8];
        expected.extend_from_slice(&1.0f64.to_le_bytes());
        expected.extend_from_slice(&1u32.to_le_bytes());
        expected.extend_from_slice(&2.0f64.to_le_bytes());
        expected.extend_from_slice(&[1, 1, 0, 0, 0, b'x']);
        assert_eq!(encode_evaluation(&e), expected);
        // With residuals: version 2, the same fields, then the residuals.
        let e = Evaluation {
            objective: 1.0,
            sse: vec![2.0],
            failure: None,
            residuals: vec![3.0],
        };
        let mut expected = vec![2u8];
        expected.extend_from_slice(&1.0f64.to_le_bytes());
        expected.extend_from_slice(&1u32.to_le_bytes());
        expected.extend_from_slice(&2.0f64.to_le_bytes());
        expected.push(0);
        expected.extend_from_slice(&1u32.to_le_bytes());
        expected.extend_from_slice(&3.0f64.to_le_bytes());
        assert_eq!(encode_evaluation(&e), expected);
    }

    #[test]
    fn damaged_values_are_reported_not_guessed() {
        let good = encode_evaluation(&Evaluation::failed(1, "diverged".into()));
        let mut unknown = good.clone();
        unknown[0] = 2;
        let truncated = &good[..good.len() - 1];
        let mut trailing = good.clone();
        trailing.push(0);
        for bad in [&unknown[..], truncated, &trailing[..], &[][..]] {
            assert!(matches!(
                decode_evaluation(bad),
                Err(StoreError::Corrupt(_))
            ));
        }
    }

    #[test]
    fn measurements_round_trip_and_keep_their_hash() {
        let m = Measurement {
            source: PathBuf::from("a.csv"),
            time: vec![0.0, 0.5, 1.0],
            columns: vec![
                ("x".into(), vec![1.0, 2.0, 3.0]),
                ("yy".into(), vec![-0.0; 3]),
            ],
        };
        let bytes = encode_measurement(&m);
        let back = decode_measurement(&bytes, PathBuf::from("b.mat")).unwrap();
        assert_eq!(back.time, m.time);
        assert_eq!(back.columns, m.columns);
        assert_eq!(back.content_hash(), m.content_hash());
        // A count larger than the value is caught before allocating.
        let mut bad = bytes.clone();
        bad[1..9].copy_from_slice(&u64::MAX.to_le_bytes());
        assert!(decode_measurement(&bad, PathBuf::new()).is_err());
    }

    #[test]
    fn campaign_records_round_trip() {
        let record = CampaignRecord {
            name: "c".into(),
            spec: "name = \"c\"\n".into(),
            source: PathBuf::from("/campaigns/c.toml"),
            dataset: "00".repeat(32),
            status: CampaignStatus::Running,
            runs: vec![],
            result: None,
            failure: None,
            message: None,
            free: Vec::new(),
            history: Vec::new(),
        };
        let bytes = encode_campaign(&record);
        assert_eq!(bytes[0], 1);
        assert_eq!(decode_campaign(&bytes).unwrap(), record);
    }

    #[test]
    fn a_result_that_does_not_read_as_an_outcome_leaves_the_record_readable() {
        let record = CampaignRecord {
            name: "c".into(),
            spec: String::new(),
            source: PathBuf::new(),
            dataset: "00".repeat(32),
            status: CampaignStatus::Finished,
            runs: vec![],
            result: None,
            failure: None,
            message: None,
            free: Vec::new(),
            history: Vec::new(),
        };
        let mut value = serde_json::to_value(&record).unwrap();
        value["result"] = serde_json::json!({ "runs": "not a list" });
        let mut bytes = vec![1];
        serde_json::to_writer(&mut bytes, &value).unwrap();
        assert_eq!(decode_campaign(&bytes).unwrap(), record);
    }

    #[test]
    fn campaign_records_keep_every_number_bit_for_bit() {
        // Values a result holds (a run's best point and objective) whose shortest decimal
        // text a fast but inexact float parser reads back one ulp off: a campaign resumed
        // from the store reported them so, unlike the one that never stopped.
        let values = [
            f64::from_bits(0x3fed_bb10_e952_1f72),
            f64::from_bits(0x405d_522e_7e12_48c8),
            0.1 + 0.2,
            1e-300,
            f64::MAX,
        ];
        let record = CampaignRecord {
            name: "c".into(),
            spec: String::new(),
            source: PathBuf::new(),
            dataset: "00".repeat(32),
            status: CampaignStatus::Finished,
            runs: vec![RunBest {
                method: "nelder-mead".into(),
                start: 0,
                point: values.to_vec(),
                objective: values[1],
                evaluations: 1,
                rounds: 1,
            }],
            result: Some(crate::outcome::CalibrationOutcome {
                best: crate::outcome::Best {
                    parameters: values
                        .iter()
                        .enumerate()
                        .map(|(i, v)| (format!("p{i}"), *v))
                        .collect(),
                    objective: values[1],
                    ..Default::default()
                },
                ..Default::default()
            }),
            failure: None,
            message: None,
            free: Vec::new(),
            history: Vec::new(),
        };
        let back = decode_campaign(&encode_campaign(&record)).unwrap();
        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&back.runs[0].point), bits(&values));
        assert_eq!(back.runs[0].objective.to_bits(), values[1].to_bits());
        let best = back.result.unwrap().best;
        let result: Vec<f64> = best.parameters.iter().map(|(_, v)| *v).collect();
        assert_eq!(bits(&result), bits(&values));
        assert_eq!(best.objective.to_bits(), values[1].to_bits());
    }
}
