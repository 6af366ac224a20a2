//! Where simulations run: `slots` threads of their own, never the async runtime.
//!
//! `slots` simulations run at once (one per core by default); up to `queue_bound` more
//! wait for a slot. A request arriving while the queue is full is refused whole
//! (`RESOURCE_EXHAUSTED`) before anything runs, so a flood costs the worker nothing and the
//! client learns at once to go elsewhere. A request arriving while there is room is admitted
//! whole, however many points it holds (up to [`calib_model::limits::MAX_POINTS`]): a batch larger
//! than the queue is never refused by an idle worker, it fills the queue past its bound
//! and the requests after it are refused until it drains.
//!
//! A request's points go into one first-in first-out queue all at once, and each slot
//! thread takes the next point itself as soon as it finishes one: between two points of a
//! busy worker no thread has to be woken, and a request queued behind another starts when
//! that one's last point does (its answer travels while the next request runs). The request
//! is woken once, when its last point is done.

use super::error::{Error, Result};
use std::collections::VecDeque;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Condvar, Mutex};

/// One point of a request, as a slot thread runs it.
type Job = Box<dyn FnOnce() + Send>;

/// What the pool and its slot threads share.
struct Shared {
    queue: Mutex<Queue>,
    ready: Condvar,
    running: AtomicUsize,
    completed: AtomicU64,
}

#[derive(Default)]
struct Queue {
    jobs: VecDeque<Job>,
    /// The pool was dropped: the slot threads end.
    closed: bool,
}

pub struct SimulationPool {
    slots: usize,
    queue_bound: usize,
    /// Simulations admitted and not yet finished (running or waiting).
    admitted: AtomicUsize,
    shared: Arc<Shared>,
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

/// The points of one request: their outcomes as they come, and who waits for the last.
struct Batch<T> {
    outcomes: Mutex<Vec<Option<Outcome<T>>>>,
    left: AtomicUsize,
    done: Mutex<Option<tokio::sync::oneshot::Sender<()>>>,
}

enum Outcome<T> {
    Done(T),
    /// The request was abandoned before this point began.
    Skipped,
    /// The simulation panicked: its message.
    Panicked(String),
}

impl<T> Batch<T> {
    fn record(&self, i: usize, outcome: Outcome<T>) {
        self.outcomes.lock().expect("batch lock")[i] = Some(outcome);
        if self.left.fetch_sub(1, Ordering::AcqRel) == 1 {
            if let Some(done) = self.done.lock().expect("batch lock").take() {
                let _ = done.send(());
            }
        }
    }
}

impl SimulationPool {
    pub fn new(slots: usize, queue_bound: usize) -> Self {
        let slots = slots.max(1);
        let shared = Arc::new(Shared {
            queue: Mutex::new(Queue::default()),
            ready: Condvar::new(),
            running: AtomicUsize::new(0),
            completed: AtomicU64::new(0),
        });
        for slot in 0..slots {
            let shared = shared.clone();
            std::thread::Builder::new()
                .name(format!("calib-slot-{slot}"))
                .spawn(move || serve_slot(&shared))
                .expect("cannot start a simulation thread");
        }
        Self {
            slots,
            queue_bound,
            admitted: AtomicUsize::new(0),
            shared,
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

    /// Run `simulate(i)` for `i` in `0..count` on the slot threads, behind what is queued
    /// already, and wait for all of them. Points not begun when the admission is dropped
    /// (the client gave up) are skipped.
    pub async fn run<T, F>(
        &self,
        admission: &Admission<'_>,
        count: usize,
        simulate: F,
    ) -> Result<Vec<T>>
    where
        T: Send + 'static,
        F: Fn(usize) -> T + Send + Sync + 'static,
    {
        if count == 0 {
            return Ok(Vec::new());
        }
        let (done, finished) = tokio::sync::oneshot::channel();
        let batch = Arc::new(Batch {
            outcomes: Mutex::new((0..count).map(|_| None).collect()),
            left: AtomicUsize::new(count),
            done: Mutex::new(Some(done)),
        });
        let simulate = Arc::new(simulate);
        {
            let mut queue = self.shared.queue.lock().expect("pool lock");
            for i in 0..count {
                let (batch, simulate) = (batch.clone(), simulate.clone());
                let cancelled = admission.cancelled.clone();
                let shared = self.shared.clone();
                queue.jobs.push_back(Box::new(move || {
                    if cancelled.load(Ordering::Relaxed) {
                        return batch.record(i, Outcome::Skipped);
                    }
                    shared.running.fetch_add(1, Ordering::Relaxed);
                    let outcome = catch_unwind(AssertUnwindSafe(|| simulate(i)));
                    shared.running.fetch_sub(1, Ordering::Relaxed);
                    shared.completed.fetch_add(1, Ordering::Relaxed);
                    batch.record(
                        i,
                        match outcome {
                            Ok(value) => Outcome::Done(value),
                            Err(panic) => Outcome::Panicked(panic_message(&*panic)),
                        },
                    );
                }));
            }
        }
        if count == 1 {
            self.shared.ready.notify_one();
        } else {
            self.shared.ready.notify_all();
        }
        finished
            .await
            .map_err(|_| Error::Internal("the simulation pool is closed".into()))?;
        let outcomes = std::mem::take(&mut *batch.outcomes.lock().expect("batch lock"));
        outcomes
            .into_iter()
            .map(|outcome| match outcome {
                Some(Outcome::Done(value)) => Ok(value),
                Some(Outcome::Panicked(why)) => {
                    Err(Error::Internal(format!("simulation thread failed: {why}")))
                }
                Some(Outcome::Skipped) | None => {
                    Err(Error::Internal("simulation abandoned".into()))
                }
            })
            .collect()
    }

    pub fn load(&self) -> PoolLoad {
        let admitted = self.admitted.load(Ordering::Acquire);
        let running = self.shared.running.load(Ordering::Relaxed);
        PoolLoad {
            slots: self.slots,
            queue_bound: self.queue_bound,
            running,
            queued: admitted.saturating_sub(running),
            completed: self.shared.completed.load(Ordering::Relaxed),
        }
    }
}

impl Drop for SimulationPool {
    fn drop(&mut self) {
        let mut queue = self.shared.queue.lock().expect("pool lock");
        queue.closed = true;
        // What waits is abandoned: dropping a job drops its request's sender.
        queue.jobs.clear();
        drop(queue);
        self.shared.ready.notify_all();
    }
}

/// A slot thread: take the next point, run it, until the pool is dropped.
fn serve_slot(shared: &Shared) {
    loop {
        let job = {
            let mut queue = shared.queue.lock().expect("pool lock");
            loop {
                if queue.closed {
                    return;
                }
                if let Some(job) = queue.jobs.pop_front() {
                    break job;
                }
                queue = shared.ready.wait(queue).expect("pool lock");
            }
        };
        job();
    }
}

fn panic_message(panic: &(dyn std::any::Any + Send)) -> String {
    panic
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| panic.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "panicked".into())
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

    fn block_on<F: std::future::Future>(future: F) -> F::Output {
        tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .enable_all()
            .build()
            .unwrap()
            .block_on(future)
    }

    #[test]
    fn a_request_queued_behind_another_starts_when_that_ones_last_point_has() {
        let pool = Arc::new(SimulationPool::new(2, 128));
        let order = Arc::new(std::sync::Mutex::new(Vec::new()));
        block_on(async {
            let run = |name: char| {
                let (pool, order) = (pool.clone(), order.clone());
                tokio::spawn(async move {
                    let admission = pool.admit(4).unwrap();
                    pool.run(&admission, 4, move |i| {
                        std::thread::sleep(std::time::Duration::from_millis(20));
                        order.lock().unwrap().push(name);
                        i
                    })
                    .await
                    .unwrap()
                })
            };
            let first = run('a');
            // Admitted and queued in one poll: once admitted, its points are in the queue.
            while pool.admitted.load(Ordering::Acquire) < 4 {
                tokio::time::sleep(std::time::Duration::from_millis(1)).await;
            }
            let second = run('b');
            assert_eq!(first.await.unwrap(), vec![0, 1, 2, 3], "answers in order");
            assert_eq!(second.await.unwrap(), vec![0, 1, 2, 3]);
        });
        let order: String = order.lock().unwrap().iter().collect();
        assert_eq!(order, "aaaabbbb", "first in, first out");
        assert_eq!(pool.load().completed, 8);
        assert_eq!(pool.load().queued, 0);
    }

    #[test]
    fn a_panicking_simulation_fails_its_request_and_the_slot_serves_on() {
        let pool = SimulationPool::new(1, 8);
        block_on(async {
            let admission = pool.admit(2).unwrap();
            let failed = pool
                .run(&admission, 2, |i| {
                    if i == 1 {
                        panic!("model broke");
                    }
                    i
                })
                .await;
            assert!(
                matches!(&failed, Err(Error::Internal(why)) if why.contains("model broke")),
                "{:?}",
                failed.err()
            );
            drop(admission);
            let admission = pool.admit(1).unwrap();
            assert_eq!(pool.run(&admission, 1, |_| 7).await.unwrap(), vec![7]);
        });
    }
}
