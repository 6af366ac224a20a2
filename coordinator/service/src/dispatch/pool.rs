//! The workers a coordinator knows, their health and their free slots.
//!
//! A worker enters as `Joining` and serves only once a probe (health check, then its
//! capacity) succeeds. A worker that fails a request is marked `Down` and probed back in
//! by the pool's maintenance task; one that speaks another protocol is set aside for good.
//! Slots are leased to dispatchers in chunks sized by what is pending (see
//! [`WorkerPool::acquire`]): a batch fills every worker's idle slots first, large batches go
//! in few requests, and the tail of a batch in chunks of one point per slot. How large a
//! chunk may be follows how long the worker takes per point: about [`CHUNK_SECONDS`] of
//! work per slot, so that a fast model travels in large requests and a slow one in small.

use super::client::WorkerClient;
use super::DispatchConfig;
use std::sync::{Arc, Mutex, Weak};
use std::time::Instant;
use tokio::sync::Notify;

/// How the pool learned of a worker.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Origin {
    /// Named on the command line or in the configuration.
    Static,
    /// One of the addresses a DNS name resolved to (the name is kept).
    Dns(String),
    /// Registered itself; dropped when its registration expires.
    Registered { expires: Instant },
}

impl Origin {
    /// A word for logs.
    pub fn kind(&self) -> &'static str {
        match self {
            Origin::Static => "static",
            Origin::Dns(_) => "dns",
            Origin::Registered { .. } => "registered",
        }
    }
}

#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Health {
    Joining,
    Up,
    Down {
        reason: String,
    },
    /// Speaks another protocol: never used.
    Incompatible {
        reason: String,
    },
    /// Refused this coordinator's token, or its certificate is not trusted: never used.
    Untrusted {
        reason: String,
    },
}

impl Health {
    /// Set aside for good: no probe brings it back.
    pub fn is_set_aside(&self) -> bool {
        matches!(self, Health::Incompatible { .. } | Health::Untrusted { .. })
    }
}

impl std::fmt::Display for Health {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Health::Joining => write!(f, "joining"),
            Health::Up => write!(f, "up"),
            Health::Down { reason } => write!(f, "down: {reason}"),
            Health::Incompatible { reason } => write!(f, "incompatible: {reason}"),
            Health::Untrusted { reason } => write!(f, "untrusted: {reason}"),
        }
    }
}

struct Worker {
    id: u64,
    client: WorkerClient,
    origin: Origin,
    health: Health,
    slots: usize,
    /// Points the worker queues beyond its slots before it refuses a request.
    queue_bound: usize,
    /// Seconds of one point on one slot, as the worker's answers have taken (a running
    /// average; `None` until the first answer).
    point_seconds: Option<f64>,
    /// Points leased and not yet returned.
    busy: usize,
    /// Chunks leased and not yet returned.
    chunks: usize,
    evaluated: u64,
    probing: bool,
    /// Has been up at least once.
    ever_up: bool,
    /// Its last probe found nothing listening at its address.
    refused: bool,
    /// Failures since the worker last answered: each doubles the wait before the next probe,
    /// so that a worker that passes health checks but fails its work is rarely sent work.
    failures: u32,
    next_probe: Instant,
}

impl Worker {
    /// Points this worker can take in a chunk now: into its idle slots, or (`queued`) into
    /// its queue behind what runs, up to `depth` chunks and what it queues before it
    /// refuses. 0 when it is not up.
    fn free(&self, queued: bool, depth: usize) -> usize {
        if self.health != Health::Up {
            0
        } else if !queued {
            self.slots.saturating_sub(self.busy)
        } else if self.chunks >= depth {
            0
        } else {
            (self.slots + self.queue_bound).saturating_sub(self.busy)
        }
    }

    fn failed(&mut self, reason: String, probe_interval: std::time::Duration) {
        self.failures = self.failures.saturating_add(1);
        let backoff = probe_interval
            .saturating_mul(1 << (self.failures - 1).min(8))
            .min(MAX_BACKOFF);
        self.next_probe = Instant::now() + backoff;
        self.health = Health::Down { reason };
    }
}

/// Most points per slot of its worker one chunk holds (while many points are pending), as
/// long as the worker's speed is not known.
pub const MAX_POINTS_PER_SLOT: usize = 8;

/// Work per slot a chunk holds at most once the worker's speed is known: long enough that a
/// request's cost (a few hundred microseconds of both processes' CPU) is a small part of
/// it, short enough that a batch's tail and a failed worker's retries stay small.
pub const CHUNK_SECONDS: f64 = 0.05;

/// Most points per slot of a chunk however fast the model.
pub const MAX_POINTS_PER_SLOT_FAST: usize = 64;

/// Longest wait between two probes of a failing worker.
const MAX_BACKOFF: std::time::Duration = std::time::Duration::from_secs(30);

/// A worker as reported by [`WorkerPool::workers`].
#[derive(Debug, Clone, PartialEq)]
pub struct WorkerView {
    pub url: String,
    pub origin: Origin,
    pub health: Health,
    pub slots: usize,
    pub busy: usize,
    /// Points this worker answered.
    pub evaluated: u64,
    /// Has been up at least once.
    pub ever_up: bool,
    /// Its last probe found nothing listening at its address.
    pub refused: bool,
}

/// Slots of one worker granted to one dispatcher.
pub struct Lease {
    pub worker: u64,
    pub client: WorkerClient,
    pub points: usize,
}

#[derive(Default)]
struct State {
    workers: Vec<Worker>,
    next_id: u64,
    /// Rotates the worker a lease starts from, so small batches spread over workers.
    cursor: usize,
}

pub struct WorkerPool {
    config: DispatchConfig,
    state: Mutex<State>,
    changed: Notify,
}

impl WorkerPool {
    /// A pool with no worker yet and its maintenance task (probes, expiry) on the current
    /// tokio runtime.
    pub fn start(config: DispatchConfig) -> Arc<Self> {
        let pool = Arc::new(Self {
            config,
            state: Mutex::new(State::default()),
            changed: Notify::new(),
        });
        tokio::spawn(maintain(Arc::downgrade(&pool)));
        pool
    }

    pub fn config(&self) -> &DispatchConfig {
        &self.config
    }

    /// Add the worker at `url` unless present; a registered worker's expiry is renewed.
    pub fn add(self: &Arc<Self>, url: &str, origin: Origin) -> Result<(), String> {
        let mut state = self.state.lock().expect("pool lock");
        if let Some(w) = state.workers.iter_mut().find(|w| w.client.url() == url) {
            if let Origin::Registered { .. } = origin {
                w.origin = origin;
            }
            return Ok(());
        }
        let server_name = match &origin {
            // Verified as the name it was found by, which its certificate is made out to.
            Origin::Dns(name) => name.rsplit_once(':').map(|(host, _)| host.to_string()),
            _ => None,
        };
        let client = WorkerClient::new(url, &self.config.security, server_name.as_deref())?;
        let id = state.next_id;
        state.next_id += 1;
        tracing::info!(worker = %url, origin = origin.kind(), "worker added");
        state.workers.push(Worker {
            id,
            client,
            origin,
            health: Health::Joining,
            slots: 0,
            queue_bound: 0,
            point_seconds: None,
            busy: 0,
            chunks: 0,
            evaluated: 0,
            probing: false,
            ever_up: false,
            refused: false,
            failures: 0,
            next_probe: Instant::now(),
        });
        drop(state);
        self.probe_soon(id);
        Ok(())
    }

    /// Forget the worker at `url` (its leases in flight finish or fail on their own).
    pub fn remove(&self, url: &str) {
        let mut state = self.state.lock().expect("pool lock");
        state.workers.retain(|w| {
            let keep = w.client.url() != url;
            if !keep {
                tracing::info!(worker = %url, "worker removed");
            }
            keep
        });
    }

    /// URLs of the workers that came from the DNS name `name`.
    pub fn urls_from(&self, name: &str) -> Vec<String> {
        let state = self.state.lock().expect("pool lock");
        state
            .workers
            .iter()
            .filter(|w| matches!(&w.origin, Origin::Dns(n) if n == name))
            .map(|w| w.client.url().to_string())
            .collect()
    }

    pub fn workers(&self) -> Vec<WorkerView> {
        let state = self.state.lock().expect("pool lock");
        state
            .workers
            .iter()
            .map(|w| WorkerView {
                url: w.client.url().to_string(),
                origin: w.origin.clone(),
                health: w.health.clone(),
                slots: w.slots,
                busy: w.busy,
                evaluated: w.evaluated,
                ever_up: w.ever_up,
                refused: w.refused,
            })
            .collect()
    }

    /// Lease up to `wanted` points of capacity over the workers that are up, in chunks sized
    /// by what is left (guided self-scheduling): a chunk takes an even share per slot of what
    /// is pending over every slot up, so a batch that fits the idle slots goes in one request
    /// per worker (a request costs both processes more than a cheap point); while much is
    /// pending a chunk holds about
    /// [`CHUNK_SECONDS`] of work per slot of its worker (up to [`MAX_POINTS_PER_SLOT_FAST`]
    /// points; [`MAX_POINTS_PER_SLOT`] until the worker has answered once), so that a large
    /// batch travels in few requests; as the batch drains chunks shrink to one point per
    /// slot, so that the last points spread over every worker instead of waiting behind one.
    ///
    /// Workers with an idle slot are served first; only when points are left over does a
    /// worker take a chunk queued behind its running one (up to `depth` chunks at once, and
    /// never more points than the worker queues before it refuses), so that no point waits
    /// in one worker's queue while another worker idles.
    ///
    /// `most_per_slot` bounds a chunk for work whose answers are large (whole trajectories).
    pub fn acquire(&self, wanted: usize, most_per_slot: usize) -> Vec<Lease> {
        let mut state = self.state.lock().expect("pool lock");
        let n = state.workers.len();
        if n == 0 || wanted == 0 {
            return Vec::new();
        }
        let depth = self.config.depth.max(1);
        let start = state.cursor % n;
        state.cursor = state.cursor.wrapping_add(1);
        let total_slots: usize = state
            .workers
            .iter()
            .filter(|w| w.health == Health::Up)
            .map(|w| w.slots)
            .sum();
        if total_slots == 0 {
            return Vec::new();
        }
        // A chunk's points per slot: an even share of what is pending over the slots the
        // pass fills, within what the worker's speed allows.
        let per_slot = |share: usize, w: &Worker| {
            let most = match w.point_seconds {
                Some(t) if t > 0.0 => {
                    ((CHUNK_SECONDS / t) as usize).clamp(1, MAX_POINTS_PER_SLOT_FAST)
                }
                _ => MAX_POINTS_PER_SLOT,
            };
            share.clamp(1, most.min(most_per_slot.max(1)))
        };
        let mut remaining = wanted;
        let mut leases = Vec::new();
        // First one chunk to each worker with an idle slot, then chunks queued behind.
        for queued in [false, true] {
            loop {
                // Shared by the idle slots in the first pass, by every slot behind.
                let slots = if queued {
                    total_slots
                } else {
                    state.workers.iter().map(|w| w.free(false, depth)).sum()
                };
                let share = remaining.div_ceil(slots.max(1));
                let mut gave = false;
                for k in 0..n {
                    if remaining == 0 {
                        break;
                    }
                    let w = &mut state.workers[(start + k) % n];
                    let free = w.free(queued, depth);
                    if free == 0 {
                        continue;
                    }
                    let room = if queued {
                        // Queued behind what runs: as large as what is pending allows, within
                        // what the worker queues before it refuses.
                        (w.slots * per_slot(share, w)).min(free)
                    } else {
                        free * per_slot(share, w)
                    };
                    let points = room.min(remaining);
                    remaining -= points;
                    w.busy += points;
                    w.chunks += 1;
                    leases.push(Lease {
                        worker: w.id,
                        client: w.client.clone(),
                        points,
                    });
                    gave = true;
                }
                if !gave || remaining == 0 || !queued {
                    break;
                }
            }
        }
        leases
    }

    /// Return a lease's slots; `answered` points were evaluated by the worker, in `took`
    /// from request to answer.
    pub fn release(&self, lease: &Lease, answered: usize, took: std::time::Duration) {
        let mut state = self.state.lock().expect("pool lock");
        if let Some(w) = state.workers.iter_mut().find(|w| w.id == lease.worker) {
            w.busy -= lease.points;
            w.chunks -= 1;
            w.evaluated += answered as u64;
            if answered > 0 {
                w.failures = 0;
                // The chunk's points ran side by side on up to `slots` slots; a chunk that
                // waited behind another counts its wait too, which errs towards small chunks.
                let parallel = answered.min(w.slots.max(1)) as f64;
                let seconds = took.as_secs_f64() * parallel / answered as f64;
                w.point_seconds = Some(match w.point_seconds {
                    Some(before) => 0.7 * before + 0.3 * seconds,
                    None => seconds,
                });
            }
        }
        drop(state);
        self.changed.notify_waiters();
    }

    /// Take a worker out of service until a probe brings it back.
    pub fn mark_down(&self, worker: u64, reason: String) {
        let mut state = self.state.lock().expect("pool lock");
        if let Some(w) = state.workers.iter_mut().find(|w| w.id == worker) {
            if w.health == Health::Up {
                tracing::warn!(worker = %w.client.url(), %reason, "worker taken out");
            }
            if !w.health.is_set_aside() {
                w.failed(reason, self.config.probe_interval);
            }
        }
    }

    /// Set a worker aside for good: it speaks another protocol.
    pub fn mark_incompatible(&self, worker: u64, reason: String) {
        let mut state = self.state.lock().expect("pool lock");
        if let Some(w) = state.workers.iter_mut().find(|w| w.id == worker) {
            tracing::error!(worker = %w.client.url(), %reason, "incompatible worker set aside");
            w.health = Health::Incompatible { reason };
        }
    }

    /// Set a worker aside for good: it refused the token, or its certificate is not trusted.
    pub fn set_aside_untrusted(&self, worker: u64, reason: String) {
        let mut state = self.state.lock().expect("pool lock");
        if let Some(w) = state.workers.iter_mut().find(|w| w.id == worker) {
            tracing::error!(worker = %w.client.url(), %reason, "untrusted worker set aside");
            w.health = Health::Untrusted { reason };
        }
    }

    /// Completes when slots are released or a worker comes up (call `enable` on it before
    /// looking at the pool, so that no change is missed).
    pub fn notified(&self) -> tokio::sync::futures::Notified<'_> {
        self.changed.notified()
    }

    /// Whether a chunk acquired now would find an idle slot on a worker that is up. Room in
    /// a worker's queue does not count: a batch sent there would only wait for the slots,
    /// while a batch held back meanwhile takes more points in one request.
    pub fn has_room(&self) -> bool {
        let state = self.state.lock().expect("pool lock");
        let depth = self.config.depth.max(1);
        state.workers.iter().any(|w| w.free(false, depth) > 0)
    }

    /// False when every known worker is set aside for good (another protocol, a refused
    /// token or certificate); an empty pool may still fill.
    pub fn has_prospects(&self) -> bool {
        let state = self.state.lock().expect("pool lock");
        state.workers.is_empty() || state.workers.iter().any(|w| !w.health.is_set_aside())
    }

    fn probe_soon(self: &Arc<Self>, worker: u64) {
        let client = {
            let mut state = self.state.lock().expect("pool lock");
            let Some(w) = state.workers.iter_mut().find(|w| w.id == worker) else {
                return;
            };
            if w.probing {
                return;
            }
            w.probing = true;
            w.client.clone()
        };
        let pool = Arc::downgrade(self);
        let deadline = self.config.probe_timeout;
        tokio::spawn(async move {
            let outcome = client.probe(deadline).await;
            if let Some(pool) = pool.upgrade() {
                pool.probed(worker, outcome);
            }
        });
    }

    fn probed(
        &self,
        worker: u64,
        outcome: Result<super::client::WorkerStatus, super::error::WorkerError>,
    ) {
        let mut state = self.state.lock().expect("pool lock");
        let Some(w) = state.workers.iter_mut().find(|w| w.id == worker) else {
            return;
        };
        w.probing = false;
        w.refused = matches!(outcome, Err(super::error::WorkerError::Refused(_)));
        match outcome {
            Ok(status) => {
                if w.health != Health::Up {
                    tracing::info!(worker = %w.client.url(), slots = status.slots, "worker up");
                }
                w.health = Health::Up;
                w.ever_up = true;
                w.slots = status.slots;
                w.queue_bound = status.queue_bound;
            }
            Err(super::error::WorkerError::Incompatible(reason)) => {
                tracing::error!(worker = %w.client.url(), %reason, "incompatible worker set aside");
                w.health = Health::Incompatible { reason };
            }
            Err(super::error::WorkerError::Untrusted(reason)) => {
                tracing::error!(worker = %w.client.url(), %reason, "untrusted worker set aside");
                w.health = Health::Untrusted { reason };
            }
            Err(e) => {
                if w.health == Health::Up {
                    tracing::warn!(worker = %w.client.url(), error = %e, "worker failed its probe");
                }
                w.failed(e.to_string(), self.config.probe_interval);
            }
        }
        drop(state);
        self.changed.notify_waiters();
    }

    /// One maintenance round: drop expired registrations, probe workers not up.
    fn maintain_once(self: &Arc<Self>) {
        let now = Instant::now();
        let to_probe: Vec<u64> = {
            let mut state = self.state.lock().expect("pool lock");
            state.workers.retain(|w| match w.origin {
                Origin::Registered { expires } if expires < now => {
                    tracing::info!(worker = %w.client.url(), "registration expired");
                    false
                }
                _ => true,
            });
            state
                .workers
                .iter()
                .filter(|w| match w.health {
                    Health::Joining => true,
                    Health::Down { .. } => w.next_probe <= now,
                    _ => false,
                })
                .map(|w| w.id)
                .collect()
        };
        for id in to_probe {
            self.probe_soon(id);
        }
    }
}

async fn maintain(pool: Weak<WorkerPool>) {
    let interval = match pool.upgrade() {
        Some(p) => p.config.probe_interval,
        None => return,
    };
    let mut ticker = tokio::time::interval(interval);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        ticker.tick().await;
        let Some(pool) = pool.upgrade() else { return };
        pool.maintain_once();
    }
}
