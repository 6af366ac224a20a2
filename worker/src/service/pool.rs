//! Where simulations run: a bounded set of blocking threads, never the async runtime.
//!
//! `slots` simulations run at once (one per core by default); up to `queue_bound` more
//! wait for a slot. A request arriving while the queue is full is refused whole
//! (`RESOURCE_EXHAUSTED`) before anything runs, so a flood costs the worker nothing and the
//! client learns at once to go elsewhere. A request arriving while there is room is admitted
//! whole, however many points it holds (up to [`crate::limits::MAX_POINTS`]): a batch larger
//! than the queue is never refused by an idle worker, it fills the queue past its bound
//! and the requests after it are refused until it drains.

use super::error::{Error, Result};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::Arc;
use tokio::sync::Semaphore;
use tokio::task::JoinHandle;

pub struct SimulationPool {
    slots: usize,
    queue_bound: usize,
    permits: Arc<Semaphore>,
    /// Simulations admitted and not yet finished (running or waiting).
    admitted: AtomicUsize,
    running: Arc<AtomicUsize>,
    completed: Arc<AtomicU64>,
}

/// Counts of a pool at one instant.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoolLoad {
    pub slots: usize,
    pub queue_bound: usize,
    pub running: usize,
    pub queued: usize,
    /// Simulations finished since start.
    pub completed: u64,
}

/// Places reserved in the pool for the simulations of one request; released on drop.
/// Dropping it before the simulations start (the client gave up) also cancels them.
pub struct Admission<'a> {
    pool: &'a SimulationPool,
    places: usize,
    cancelled: Arc<AtomicBool>,
}

impl Drop for Admission<'_> {
    fn drop(&mut self) {
        self.cancelled.store(true, Ordering::Relaxed);
        self.pool.admitted.fetch_sub(self.places, Ordering::AcqRel);
    }
}

impl SimulationPool {
    pub fn new(slots: usize, queue_bound: usize) -> Self {
        let slots = slots.max(1);
        Self {
            slots,
            queue_bound,
            permits: Arc::new(Semaphore::new(slots)),
            admitted: AtomicUsize::new(0),
            running: Arc::new(AtomicUsize::new(0)),
            completed: Arc::new(AtomicU64::new(0)),
        }
    }

    /// Reserve places for `n` simulations, or refuse them all when the queue is full already
    /// (every slot busy and `queue_bound` simulations waiting).
    pub fn admit(&self, n: usize) -> Result<Admission<'_>> {
        let capacity = self.slots + self.queue_bound;
        let before = self.admitted.fetch_add(n, Ordering::AcqRel);
        if before >= capacity {
            self.admitted.fetch_sub(n, Ordering::AcqRel);
            return Err(Error::QueueFull {
                queued: before.saturating_sub(self.slots),
                bound: self.queue_bound,
            });
        }
        Ok(Admission {
            pool: self,
            places: n,
            cancelled: Arc::new(AtomicBool::new(false)),
        })
    }

    /// Wait for a free slot, then start `simulate` on a blocking thread; the slot is freed
    /// when it returns. The handle yields `None` when the request was abandoned before the
    /// simulation began (it is then skipped).
    pub async fn start<T, F>(
        &self,
        admission: &Admission<'_>,
        simulate: F,
    ) -> Result<JoinHandle<Option<T>>>
    where
        T: Send + 'static,
        F: FnOnce() -> T + Send + 'static,
    {
        let permit = self
            .permits
            .clone()
            .acquire_owned()
            .await
            .map_err(|_| Error::Internal("the simulation pool is closed".into()))?;
        let cancelled = admission.cancelled.clone();
        let running = self.running.clone();
        let completed = self.completed.clone();
        Ok(tokio::task::spawn_blocking(move || {
            let _permit = permit;
            if cancelled.load(Ordering::Relaxed) {
                return None;
            }
            running.fetch_add(1, Ordering::Relaxed);
            let outcome = simulate();
            running.fetch_sub(1, Ordering::Relaxed);
            completed.fetch_add(1, Ordering::Relaxed);
            Some(outcome)
        }))
    }

    /// The outcome of a started simulation.
    pub async fn finish<T>(handle: JoinHandle<Option<T>>) -> Result<T> {
        handle
            .await
            .map_err(|e| Error::Internal(format!("simulation thread failed: {e}")))?
            .ok_or_else(|| Error::Internal("simulation abandoned".into()))
    }

    pub fn load(&self) -> PoolLoad {
        let admitted = self.admitted.load(Ordering::Acquire);
        let running = self.running.load(Ordering::Relaxed);
        PoolLoad {
            slots: self.slots,
            queue_bound: self.queue_bound,
            running,
            queued: admitted.saturating_sub(running),
            completed: self.completed.load(Ordering::Relaxed),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_batch_larger_than_the_queue_is_admitted_while_there_is_room() {
        let pool = SimulationPool::new(2, 128);
        let big = pool.admit(131).expect("an idle pool admits any batch");
        assert_eq!(pool.load().queued, 131);
        // The queue is full now: the next request is refused, whatever its size.
        assert!(matches!(pool.admit(1), Err(Error::QueueFull { .. })));
        drop(big);
        assert_eq!(pool.load().queued, 0);
        let small = pool.admit(129).unwrap();
        // One place left: a request of any size takes it.
        let last = pool.admit(5).unwrap();
        assert!(pool.admit(1).is_err());
        drop((small, last));
        assert!(pool.admit(1).is_ok());
    }
}
