//! A store as text: one JSON object per line, independent of sled's on-disk format (which
//! changes before sled 1.0) and of this crate's byte layouts.
//!
//! ```text
//! {"format":"calib-store","version":1}
//! {"evaluation":"<key, 64 hex>","objective":"<f64 bits, 16 hex>","sse":["<f64 bits>",…],"failure":null}
//! {"evaluation":…,"failure":null,"residuals":["<f64 bits>",…]}   (evaluations with residuals)
//! {"campaign":"<id, 64 hex>","record":{…CampaignRecord…}}
//! {"dataset":"<content hash, 64 hex>","time":["<f64 bits>",…],"columns":[{"name":"…","values":["<f64 bits>",…]}]}
//! {"end":{"evaluations":N,"campaigns":N,"datasets":N}}
//! ```
//!
//! Floats are written as the hex of their IEEE-754 bits so that they come back bit for bit
//! (NaN included). The closing `end` line lets an import tell a complete export from a
//! truncated one. Entries are content-addressed, so importing into a store that already
//! holds some of them is harmless.

use super::encoding;
use super::{hex, unhex, unhex32, Collection, RawEntry, Store, StoreError};
use crate::measurement::Measurement;
use crate::objective::Evaluation;
use serde_json::{json, Value};
use std::io::{BufRead, Write};
use std::path::PathBuf;

pub const FORMAT: &str = "calib-store";
pub const VERSION: u64 = 1;

/// Entries written per durable batch when importing.
const IMPORT_BATCH: usize = 1024;

/// How many entries of each collection an export or import carried.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Counts {
    pub evaluations: u64,
    pub campaigns: u64,
    pub datasets: u64,
}

impl Counts {
    fn add(&mut self, collection: Collection, n: u64) {
        match collection {
            Collection::Evaluations => self.evaluations += n,
            Collection::Campaigns => self.campaigns += n,
            Collection::Datasets => self.datasets += n,
        }
    }
}

fn bits(v: f64) -> String {
    format!("{:016x}", v.to_bits())
}

fn bits_list(values: &[f64]) -> Vec<String> {
    values.iter().map(|v| bits(*v)).collect()
}

/// Write every entry of `store` to `out`.
pub fn export(store: &dyn Store, out: &mut dyn Write) -> Result<Counts, StoreError> {
    let io = |e: std::io::Error| StoreError::Io(format!("writing the export: {e}"));
    let mut line = |value: Value| -> Result<(), StoreError> {
        serde_json::to_writer(&mut *out, &value).map_err(|e| io(e.into()))?;
        out.write_all(b"\n").map_err(io)
    };
    line(json!({ "format": FORMAT, "version": VERSION }))?;
    let mut counts = Counts::default();
    for collection in Collection::ALL {
        for (key, value) in store.raw_entries(collection)? {
            line(record(collection, &key, &value)?)?;
            counts.add(collection, 1);
        }
    }
    line(json!({ "end": counts }))?;
    out.flush().map_err(io)?;
    Ok(counts)
}

fn record(collection: Collection, key: &[u8], value: &[u8]) -> Result<Value, StoreError> {
    Ok(match collection {
        Collection::Evaluations => {
            let e = encoding::decode_evaluation(value)?;
            let mut record = json!({
                "evaluation": hex(key),
                "objective": bits(e.objective),
                "sse": bits_list(&e.sse),
                "failure": e.failure,
            });
            if !e.residuals.is_empty() {
                record["residuals"] = bits_list(&e.residuals).into();
            }
            record
        }
        Collection::Campaigns => json!({
            "campaign": hex(key),
            "record": encoding::decode_campaign(value)?,
        }),
        Collection::Datasets => {
            let m = encoding::decode_measurement(value, PathBuf::new())?;
            let columns: Vec<Value> = m
                .columns
                .iter()
                .map(|(name, values)| json!({ "name": name, "values": bits_list(values) }))
                .collect();
            json!({
                "dataset": hex(key),
                "time": bits_list(&m.time),
                "columns": columns,
            })
        }
    })
}

/// Read an export from `input` into `store`.
pub fn import(store: &dyn Store, input: &mut dyn BufRead) -> Result<Counts, StoreError> {
    let mut lines = input.lines().enumerate();
    let mut next = || -> Result<Option<(usize, Value)>, StoreError> {
        let Some((i, line)) = lines.next() else {
            return Ok(None);
        };
        let line = line.map_err(|e| StoreError::Import(format!("reading line {}: {e}", i + 1)))?;
        let value = serde_json::from_str(&line)
            .map_err(|e| StoreError::Import(format!("line {}: {e}", i + 1)))?;
        Ok(Some((i + 1, value)))
    };
    match next()? {
        Some((_, header)) if header["format"] == FORMAT => {
            if header["version"] != VERSION {
                return Err(StoreError::Import(format!(
                    "export version {} (this calib reads version {VERSION})",
                    header["version"]
                )));
            }
        }
        _ => {
            return Err(StoreError::Import(format!(
                "not a calib store export (the first line must be {{\"format\":\"{FORMAT}\",…}})"
            )))
        }
    }
    let mut pending: Vec<(Collection, RawEntry)> = Vec::new();
    let mut counts = Counts::default();
    let flush = |pending: &mut Vec<(Collection, RawEntry)>,
                 counts: &mut Counts|
     -> Result<(), StoreError> {
        for collection in Collection::ALL {
            let entries: Vec<RawEntry> = pending
                .iter()
                .filter(|(c, _)| *c == collection)
                .map(|(_, e)| e.clone())
                .collect();
            if !entries.is_empty() {
                store.put_raw(collection, &entries)?;
                counts.add(collection, entries.len() as u64);
            }
        }
        pending.clear();
        Ok(())
    };
    while let Some((line, value)) = next()? {
        if let Some(end) = value.get("end") {
            flush(&mut pending, &mut counts)?;
            let expected: Counts = serde_json::from_value(end.clone())
                .map_err(|e| StoreError::Import(format!("line {line}: {e}")))?;
            if expected != counts {
                return Err(StoreError::Import(format!(
                    "line {line}: the export announces {expected:?} but holds {counts:?}"
                )));
            }
            return Ok(counts);
        }
        let entry = entry(&value).map_err(|e| StoreError::Import(format!("line {line}: {e}")))?;
        pending.push(entry);
        if pending.len() >= IMPORT_BATCH {
            flush(&mut pending, &mut counts)?;
        }
    }
    flush(&mut pending, &mut counts)?;
    Err(StoreError::Import(format!(
        "the export is truncated (no closing `end` line); {counts:?} were imported"
    )))
}

fn entry(value: &Value) -> Result<(Collection, RawEntry), String> {
    let hash = |field: &str| {
        value[field]
            .as_str()
            .and_then(unhex32)
            .ok_or_else(|| format!("`{field}` must be 64 hex digits"))
    };
    let float = |v: &Value| -> Result<f64, String> {
        v.as_str()
            .and_then(unhex)
            .and_then(|b| <[u8; 8]>::try_from(b).ok())
            .map(|b| f64::from_bits(u64::from_be_bytes(b)))
            .ok_or_else(|| format!("{v} is not 16 hex digits of f64 bits"))
    };
    let floats = |v: &Value| -> Result<Vec<f64>, String> {
        v.as_array()
            .ok_or_else(|| "expected a list of f64 bits".to_string())?
            .iter()
            .map(float)
            .collect()
    };
    if value.get("evaluation").is_some() {
        let key = hash("evaluation")?;
        let failure = match &value["failure"] {
            Value::Null => None,
            Value::String(s) => Some(s.clone()),
            other => return Err(format!("`failure` must be a string or null, not {other}")),
        };
        let e = Evaluation {
            objective: float(&value["objective"])?,
            sse: floats(&value["sse"])?,
            failure,
            residuals: match value.get("residuals") {
                Some(list) => floats(list)?,
                None => Vec::new(),
            },
        };
        Ok((
            Collection::Evaluations,
            (key.to_vec(), encoding::encode_evaluation(&e)),
        ))
    } else if value.get("campaign").is_some() {
        let id = hash("campaign")?;
        let record = serde_json::from_value(value["record"].clone()).map_err(|e| e.to_string())?;
        Ok((
            Collection::Campaigns,
            (id.to_vec(), encoding::encode_campaign(&record)),
        ))
    } else if value.get("dataset").is_some() {
        let key = hash("dataset")?;
        let columns = value["columns"]
            .as_array()
            .ok_or("`columns` must be a list")?
            .iter()
            .map(|c| {
                let name = c["name"].as_str().ok_or("a column has no `name`")?;
                Ok((name.to_string(), floats(&c["values"])?))
            })
            .collect::<Result<Vec<_>, String>>()?;
        let m = Measurement {
            source: PathBuf::new(),
            time: floats(&value["time"])?,
            columns,
        };
        if m.content_hash() != key {
            return Err("the dataset does not match its content hash".into());
        }
        Ok((
            Collection::Datasets,
            (key.to_vec(), encoding::encode_measurement(&m)),
        ))
    } else {
        Err("expected an `evaluation`, `campaign`, `dataset` or `end` record".into())
    }
}
