//! The store contract, checked on both implementations, and the stored evaluator.

use super::*;
use crate::campaign::Campaign;
use crate::evaluator::{Evaluator, Fault};
use crate::measurement::Measurement;
use std::path::Path;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

fn key(i: u64) -> EvaluationKey {
    evaluation_key_from(&[1; 32], &[i as f64])
}

fn evaluation(i: u64) -> Evaluation {
    if i % 7 == 3 {
        Evaluation::failed(2, format!("diverged at point {i}"))
    } else {
        Evaluation {
            objective: i as f64 * 0.1,
            sse: vec![i as f64, 1.0 / (i as f64 + 1.0)],
            failure: None,
            residuals: Vec::new(),
        }
    }
}

fn same(a: &Evaluation, b: &Evaluation) -> bool {
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    a.objective.to_bits() == b.objective.to_bits()
        && bits(&a.sse) == bits(&b.sse)
        && a.failure == b.failure
}

fn record(name: &str, status: CampaignStatus) -> CampaignRecord {
    CampaignRecord {
        name: name.into(),
        spec: format!("name = \"{name}\"\n"),
        source: PathBuf::from(format!("/campaigns/{name}.toml")),
        dataset: hex(&[9; 32]),
        status,
        runs: vec![],
        result: None,
        failure: None,
        message: None,
        free: Vec::new(),
        history: Vec::new(),
    }
}

/// What every store must do.
fn contract(store: &dyn Store) {
    let entries: Vec<_> = (0..40).map(|i| (key(i), evaluation(i))).collect();
    store.put_evaluations(&entries[..30]).unwrap();
    store.put_evaluations(&entries[20..]).unwrap();
    let keys: Vec<_> = (0..45).map(key).collect();
    let got = store.get_evaluations(&keys).unwrap();
    for (i, g) in got.iter().enumerate() {
        match g {
            Some(e) => assert!(same(e, &evaluation(i as u64)), "entry {i}"),
            None => assert!(i >= 40, "entry {i} missing"),
        }
    }

    store
        .put_campaign(&[2; 32], &record("b", CampaignStatus::Running))
        .unwrap();
    store
        .put_campaign(&[1; 32], &record("a", CampaignStatus::Running))
        .unwrap();
    store
        .put_campaign(&[1; 32], &record("a", CampaignStatus::Finished))
        .unwrap();
    let campaigns = store.campaigns().unwrap();
    assert_eq!(campaigns.len(), 2);
    assert_eq!(campaigns[0].0, [1; 32]);
    assert_eq!(campaigns[0].1.status, CampaignStatus::Finished);
    assert_eq!(
        store.campaign(&[2; 32]).unwrap().unwrap(),
        record("b", CampaignStatus::Running)
    );
    assert!(store.campaign(&[3; 32]).unwrap().is_none());

    let measurement = Measurement {
        source: PathBuf::from("x.csv"),
        time: vec![0.0, 1.0],
        columns: vec![("y".into(), vec![f64::MIN_POSITIVE, -0.0])],
    };
    let hash = measurement.content_hash();
    let bytes = encoding::encode_measurement(&measurement);
    store.put_dataset(&hash, &bytes).unwrap();
    assert_eq!(store.dataset(&hash).unwrap().unwrap(), bytes);
    assert!(store.dataset(&[6; 32]).unwrap().is_none());

    store.count_lookups(3, 2);
    let stats = store.stats().unwrap();
    assert_eq!(stats.evaluations, 40);
    assert_eq!(stats.campaigns, 2);
    assert_eq!(stats.datasets, 1);
    assert_eq!((stats.hits, stats.misses), (3, 2));
    assert!(stats.bytes > 0);
}

/// Many threads putting at once: nothing lost.
fn concurrent_puts(store: &dyn Store) {
    std::thread::scope(|scope| {
        for t in 0..8u64 {
            scope.spawn(move || {
                for b in 0..25u64 {
                    let batch: Vec<_> = (0..10)
                        .map(|j| {
                            let i = 1000 + t * 1000 + b * 10 + j;
                            (key(i), evaluation(i))
                        })
                        .collect();
                    store.put_evaluations(&batch).unwrap();
                    // Whatever was put is readable at once.
                    let back = store.get_evaluations(&[batch[9].0]).unwrap();
                    assert!(back[0].is_some());
                }
            });
        }
    });
    let keys: Vec<_> = (0..8u64)
        .flat_map(|t| (0..250).map(move |j| key(1000 + t * 1000 + j)))
        .collect();
    let got = store.get_evaluations(&keys).unwrap();
    assert!(got.iter().all(Option::is_some));
}

#[test]
fn memory_store_keeps_the_contract() {
    contract(&MemoryStore::new());
    concurrent_puts(&MemoryStore::new());
}

#[test]
fn sled_store_keeps_the_contract() {
    let dir = tempfile::tempdir().unwrap();
    contract(&SledStore::open(dir.path()).unwrap());
    let dir = tempfile::tempdir().unwrap();
    let store = SledStore::open(dir.path()).unwrap();
    concurrent_puts(&store);
    // 200 puts from 8 threads: each is made durable before it returns, one flush per put.
    assert_eq!(store.flushes(), 200, "{} flushes", store.flushes());
}

#[test]
fn sled_store_survives_reopening() {
    let dir = tempfile::tempdir().unwrap();
    {
        let store = SledStore::open(dir.path()).unwrap();
        store.put_evaluations(&[(key(1), evaluation(1))]).unwrap();
        store
            .put_campaign(&[1; 32], &record("a", CampaignStatus::Running))
            .unwrap();
        store.count_lookups(5, 1);
    }
    let store = SledStore::open(dir.path()).unwrap();
    let got = store.get_evaluations(&[key(1), key(2)]).unwrap();
    assert!(same(got[0].as_ref().unwrap(), &evaluation(1)));
    assert!(got[1].is_none());
    assert_eq!(store.campaigns().unwrap().len(), 1);
    let stats = store.stats().unwrap();
    assert_eq!((stats.hits, stats.misses), (5, 1));
}

/// Once its filter of keys has read the store, a key the store never held is answered
/// without a lookup in sled, while every key written (before the filter was ready and
/// after), imported or found on reopening is still found.
#[test]
fn lookups_of_new_points_skip_sled_and_stored_ones_are_found() {
    let dir = tempfile::tempdir().unwrap();
    let written: Vec<(EvaluationKey, Evaluation)> =
        (0..2000).map(|i| (key(i), evaluation(i))).collect();
    let fresh: Vec<EvaluationKey> = (10_000..12_000).map(key).collect();
    let check = |store: &SledStore, keys: &[EvaluationKey]| {
        store.wait_for_key_filter();
        let before = store.sled_lookups();
        let got = store.get_evaluations(&fresh).unwrap();
        assert!(got.iter().all(Option::is_none));
        // The filter is sized for a false positive in a hundred.
        let reached = store.sled_lookups() - before;
        assert!(
            reached < 100,
            "{reached} of 2000 new keys looked up in sled"
        );
        let got = store.get_evaluations(keys).unwrap();
        assert_eq!(got.len(), written.len());
        for ((_, e), g) in written.iter().zip(&got) {
            assert!(same(g.as_ref().expect("a stored key is found"), e));
        }
    };
    let keys: Vec<EvaluationKey> = written.iter().map(|(k, _)| *k).collect();
    {
        let store = SledStore::open(dir.path()).unwrap();
        assert!(store
            .get_evaluations(&keys)
            .unwrap()
            .iter()
            .all(Option::is_none));
        // Written right after opening and once the filter is ready (written while it reads
        // a large store: `key_filter.rs`'s own test).
        store.put_evaluations(&written[..500]).unwrap();
        store.wait_for_key_filter();
        store.put_evaluations(&written[500..1000]).unwrap();
        let raw: Vec<RawEntry> = written[1000..]
            .iter()
            .map(|(k, e)| (k.to_vec(), encoding::encode_evaluation(e)))
            .collect();
        store.put_raw(Collection::Evaluations, &raw).unwrap();
        check(&store, &keys);
    }
    // Reopened, the filter is rebuilt from what is on disk.
    let store = SledStore::open(dir.path()).unwrap();
    check(&store, &keys);
}

/// Evaluations written a batch per value list as one value per key would, in key order, a
/// key written twice once: the same entries as the memory store's.
#[test]
fn batched_evaluations_list_as_the_memory_store_lists_them() {
    let dir = tempfile::tempdir().unwrap();
    let sled = SledStore::open(dir.path()).unwrap();
    contract(&sled);
    let memory = MemoryStore::new();
    contract(&memory);
    let listed = sled.raw_entries(Collection::Evaluations).unwrap();
    assert_eq!(listed.len(), 40);
    assert_eq!(listed, memory.raw_entries(Collection::Evaluations).unwrap());
}

/// Write a sled database as a calib of layout `layout` left it, with `evaluations` one
/// value per key.
fn write_layout(path: &Path, layout: u32, evaluations: &[(EvaluationKey, Evaluation)]) {
    let db = raw_db(path);
    db.open_tree("meta")
        .unwrap()
        .insert("layout", &layout.to_le_bytes())
        .unwrap();
    let tree = db.open_tree("evaluations").unwrap();
    for (k, e) in evaluations {
        tree.insert(k, encoding::encode_evaluation(e)).unwrap();
    }
    db.flush().unwrap();
}

/// A store of layout 1 (every evaluation one value per key) opens as it is: its evaluations
/// are found beside the batched ones written after, counted once each, and it is marked
/// layout 2, which the calib of layout 1 refuses rather than missing the batches.
#[test]
fn a_store_of_layout_1_is_read_and_marked_2() {
    let dir = tempfile::tempdir().unwrap();
    let old: Vec<_> = (0..5).map(|i| (key(i), evaluation(i))).collect();
    write_layout(dir.path(), 1, &old);
    {
        let store = SledStore::open(dir.path()).unwrap();
        store.put_evaluations(&[(key(7), evaluation(7))]).unwrap();
        // Written again by a run that missed it: still one evaluation.
        store.put_evaluations(&[(key(3), evaluation(3))]).unwrap();
        let keys: Vec<_> = (0..8).map(key).collect();
        let got = store.get_evaluations(&keys).unwrap();
        for (i, g) in got.iter().enumerate() {
            match g {
                Some(e) => assert!(same(e, &evaluation(i as u64)), "entry {i}"),
                None => assert!(i == 5 || i == 6, "entry {i} missing"),
            }
        }
        assert_eq!(store.stats().unwrap().evaluations, 6);
        assert_eq!(store.raw_entries(Collection::Evaluations).unwrap().len(), 6);
    }
    let db = raw_db(dir.path());
    let layout = db
        .open_tree("meta")
        .unwrap()
        .get("layout")
        .unwrap()
        .unwrap();
    assert_eq!(layout.as_ref(), 2u32.to_le_bytes());
}

#[test]
fn a_store_of_a_later_layout_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    write_layout(dir.path(), 3, &[]);
    let error = SledStore::open(dir.path()).err().expect("refused");
    assert!(error.to_string().contains("layout version"), "{error}");
}

/// The store's sled database itself, once the store closed a moment ago has let it go.
fn raw_db(path: &Path) -> ::sled::Db {
    super::sled::open_db(path, || ::sled::Config::new().path(path)).unwrap()
}

/// A batch cut short on disk is reported as damage at opening, naming what is wrong, not
/// read as fewer evaluations.
#[test]
fn a_damaged_batch_is_reported_at_opening() {
    let dir = tempfile::tempdir().unwrap();
    {
        let store = SledStore::open(dir.path()).unwrap();
        store
            .put_evaluations(&[(key(1), evaluation(1)), (key(2), evaluation(2))])
            .unwrap();
    }
    {
        let db = raw_db(dir.path());
        let batches = db.open_tree("evaluation-batches").unwrap();
        let (k, v) = batches.first().unwrap().unwrap();
        batches.insert(k, &v[..v.len() - 3]).unwrap();
        db.flush().unwrap();
    }
    let error = SledStore::open(dir.path()).err().expect("damage found");
    assert!(matches!(error, StoreError::Damaged { .. }), "{error:?}");
    assert!(error.to_string().contains("cut short"), "{error}");
}

#[test]
fn a_sled_store_opens_once_at_a_time() {
    let dir = tempfile::tempdir().unwrap();
    let _first = SledStore::open(dir.path()).unwrap();
    let second = SledStore::open(dir.path())
        .err()
        .expect("second open fails");
    assert!(second.to_string().contains("in use"), "{second}");
}

#[test]
fn residuals_survive_the_store_and_its_export() {
    let source = MemoryStore::new();
    let with = Evaluation {
        objective: 0.5,
        sse: vec![0.25, 0.25],
        failure: None,
        residuals: vec![0.5, -0.0, 1e-300, -0.5],
    };
    source
        .put_evaluations(&[(key(1), with.clone()), (key(2), evaluation(2))])
        .unwrap();
    let mut text = Vec::new();
    export::export(&source, &mut text).unwrap();
    let target = MemoryStore::new();
    export::import(&target, &mut &text[..]).unwrap();
    assert_eq!(
        target.raw_entries(Collection::Evaluations).unwrap(),
        source.raw_entries(Collection::Evaluations).unwrap()
    );
    let back = target.get_evaluations(&[key(1), key(2)]).unwrap();
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    let first = back[0].as_ref().unwrap();
    assert_eq!(bits(&first.residuals), bits(&with.residuals));
    assert!(back[1].as_ref().unwrap().residuals.is_empty());
}

#[test]
fn export_and_import_carry_every_entry() {
    let source = MemoryStore::new();
    contract(&source);
    let mut text = Vec::new();
    let exported = export::export(&source, &mut text).unwrap();
    assert_eq!(exported.evaluations, 40);
    let first = text.split(|b| *b == b'\n').next().unwrap();
    assert_eq!(first, br#"{"format":"calib-store","version":1}"#);

    let dir = tempfile::tempdir().unwrap();
    let target = SledStore::open(dir.path()).unwrap();
    let imported = export::import(&target, &mut &text[..]).unwrap();
    assert_eq!(imported, exported);
    for collection in Collection::ALL {
        assert_eq!(
            target.raw_entries(collection).unwrap(),
            source.raw_entries(collection).unwrap(),
            "{collection}"
        );
    }

    // A truncated export is refused (what came before the cut is kept: it is correct).
    let cut = text.len() - 30;
    let error = export::import(&MemoryStore::new(), &mut &text[..cut]).unwrap_err();
    assert!(error.to_string().contains("line") || error.to_string().contains("truncated"));
    let error = export::import(&MemoryStore::new(), &mut &b"{\"a\":1}\n"[..]).unwrap_err();
    assert!(
        error.to_string().contains("not a calib store export"),
        "{error}"
    );
}

// ---- the stored evaluator ----

/// Scores a point by the sum of its values, slowly, counting what it simulates.
#[derive(Default)]
struct Counting {
    simulated: AtomicUsize,
    batches: AtomicUsize,
}

impl Evaluator for Counting {
    fn evaluate(&self, _: &Objective, points: &[Vec<f64>]) -> Result<Vec<Evaluation>, Fault> {
        std::thread::sleep(Duration::from_millis(20));
        self.simulated.fetch_add(points.len(), Ordering::SeqCst);
        self.batches.fetch_add(1, Ordering::SeqCst);
        Ok(points
            .iter()
            .map(|p| Evaluation {
                objective: p.iter().sum(),
                sse: vec![p.iter().sum()],
                failure: None,
                residuals: Vec::new(),
            })
            .collect())
    }
}

fn objective(version_bump: bool) -> Objective {
    let text = r#"
[model]
name = "furuta"
[measurement]
file = "m.csv"
[[outputs]]
model = "armJoint.phi"
measured = "phi"
[[parameters]]
name = "armFriction"
min = 0.0
max = 0.9
[window]
start = 0.0
stop = 1.0
"#;
    let campaign = Campaign::parse(text, Path::new("/campaigns/c.toml")).unwrap();
    let measurement = Measurement {
        source: PathBuf::from("m.csv"),
        time: vec![0.0, 0.5, 1.0],
        columns: vec![(
            "phi".into(),
            if version_bump {
                vec![0.0, 0.1, 0.3]
            } else {
                vec![0.0, 0.1, 0.2]
            },
        )],
    };
    Objective::new(&campaign, &measurement).unwrap()
}

#[test]
fn concurrent_requests_for_one_point_simulate_it_once() {
    let store = MemoryStore::new();
    let inner = Counting::default();
    StoredEvaluator::with(&inner, &store, |evaluator| {
        let objective = objective(false);
        let points: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64 * 0.1]).collect();
        std::thread::scope(|scope| {
            for t in 0..4 {
                let (evaluator, objective, points) = (&evaluator, &objective, &points);
                scope.spawn(move || {
                    // Each thread asks for an overlapping window, one point twice.
                    let mut batch = points[t..t + 3].to_vec();
                    batch.push(points[t].clone());
                    let answers = evaluator.evaluate(objective, &batch).unwrap();
                    for (p, a) in batch.iter().zip(answers) {
                        assert_eq!(a.objective, p[0]);
                    }
                });
            }
        });
        assert_eq!(inner.simulated.load(Ordering::SeqCst), 6);
        let stats = evaluator.stats();
        assert_eq!(
            (stats.requested, stats.simulated, stats.cached),
            (16, 6, 10)
        );
        let store_stats = store.stats().unwrap();
        assert_eq!((store_stats.hits, store_stats.misses), (10, 6));
        assert_eq!(store_stats.evaluations, 6);
    });
}

#[test]
fn a_second_evaluator_on_the_same_store_simulates_nothing() {
    let store = MemoryStore::new();
    let objective = objective(false);
    let points: Vec<Vec<f64>> = (0..5).map(|i| vec![i as f64 * 0.2]).collect();
    let first = Counting::default();
    StoredEvaluator::with(&first, &store, |evaluator| {
        evaluator.evaluate(&objective, &points).unwrap();
    });
    let second = Counting::default();
    StoredEvaluator::with(&second, &store, |again| {
        let answers = again.evaluate(&objective, &points).unwrap();
        assert_eq!(second.simulated.load(Ordering::SeqCst), 0);
        assert_eq!(again.stats().cached, 5);
        assert_eq!(answers[4].objective, 0.8);

        // Other data, other objective: nothing is reused.
        let other = objective_with_other_data();
        again.evaluate(&other, &points).unwrap();
        assert_eq!(second.simulated.load(Ordering::SeqCst), 5);
    });
}

fn objective_with_other_data() -> Objective {
    objective(true)
}

/// Panics on its first batch, then behaves.
/// Crashes on its first batch once let go (it says when that batch has started).
struct PanicsOnce {
    armed: std::sync::atomic::AtomicBool,
    started: AtomicBool,
    let_go: AtomicBool,
    inner: Counting,
}

impl Evaluator for PanicsOnce {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        if self.armed.swap(false, Ordering::SeqCst) {
            self.started.store(true, Ordering::SeqCst);
            await_flag(&self.let_go);
            panic!("simulator crashed");
        }
        self.inner.evaluate(objective, points)
    }
}

/// Wait until `flag` is set (at most 10 s, then the test fails).
fn await_flag(flag: &AtomicBool) {
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while !flag.load(Ordering::SeqCst) {
        assert!(std::time::Instant::now() < deadline, "never set");
        std::thread::yield_now();
    }
}

/// Wait until `holds` (at most 10 s, then the test fails, naming `what`).
fn await_that(what: &str, holds: impl Fn() -> bool) {
    let deadline = std::time::Instant::now() + Duration::from_secs(10);
    while !holds() {
        assert!(
            std::time::Instant::now() < deadline,
            "waited 10 s for {what}"
        );
        std::thread::yield_now();
    }
}

#[test]
fn a_crashed_simulation_does_not_leave_waiters_hanging() {
    let store = MemoryStore::new();
    let inner = PanicsOnce {
        armed: true.into(),
        started: false.into(),
        let_go: false.into(),
        inner: Counting::default(),
    };
    StoredEvaluator::with(&inner, &store, |evaluator| {
        let objective = objective(false);
        let point = vec![vec![0.5]];
        let crashed = std::thread::scope(|scope| {
            let first = scope.spawn(|| evaluator.evaluate(&objective, &point));
            // The second caller asks while the first simulates the point, and waits on it...
            await_flag(&inner.started);
            let second = scope.spawn(|| evaluator.evaluate(&objective, &point));
            let deadline = std::time::Instant::now() + Duration::from_secs(10);
            while evaluator.waiting_on_others() == 0 {
                assert!(!second.is_finished(), "the second caller did not wait");
                assert!(std::time::Instant::now() < deadline, "no caller waits");
                std::thread::yield_now();
            }
            // ...when the simulation crashes.
            inner.let_go.store(true, Ordering::SeqCst);
            let answer = second.join().unwrap().unwrap();
            assert_eq!(answer[0].objective, 0.5);
            first.join().is_err()
        });
        assert!(crashed);
    });
}

/// Has no worker for its first batch, then behaves.
struct UnavailableOnce {
    armed: std::sync::atomic::AtomicBool,
    inner: Counting,
}

impl Evaluator for UnavailableOnce {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        if self.armed.swap(false, Ordering::SeqCst) {
            return Err(Fault::unavailable("no worker available for 300 s"));
        }
        self.inner.evaluate(objective, points)
    }
}

#[test]
fn a_fault_stores_nothing_and_the_points_are_simulated_once_workers_are_back() {
    let store = MemoryStore::new();
    let inner = UnavailableOnce {
        armed: true.into(),
        inner: Counting::default(),
    };
    StoredEvaluator::with(&inner, &store, |evaluator| {
        let objective = objective(false);
        let points: Vec<Vec<f64>> = (0..3).map(|i| vec![i as f64 * 0.1]).collect();
        let fault = evaluator.evaluate(&objective, &points).unwrap_err();
        assert!(fault.is_retryable(), "{fault:?}");
        assert_eq!(store.stats().unwrap().evaluations, 0);
        let answers = evaluator.evaluate(&objective, &points).unwrap();
        assert_eq!(answers[2].objective, 0.2);
        assert_eq!(inner.inner.simulated.load(Ordering::SeqCst), 3);
        assert_eq!(store.stats().unwrap().evaluations, 3);
    });
}

/// Eight runs on threads of their own, each asking five times for `per_ask` new points
/// (`x`, `x + 0.5`, …) and checking the answers ([`Counting`] scores a point by its sum);
/// returns the number of asks.
fn ask_from_runs(evaluator: &impl Evaluator, objective: &Objective, per_ask: usize) -> usize {
    let (runs, calls) = (8, 5);
    std::thread::scope(|scope| {
        for r in 0..runs {
            scope.spawn(move || {
                for c in 0..calls {
                    let x = (r * 100 + c) as f64;
                    let points: Vec<Vec<f64>> =
                        (0..per_ask).map(|k| vec![x + 0.5 * k as f64]).collect();
                    let answers = evaluator.evaluate(objective, &points).unwrap();
                    assert_eq!(answers.len(), per_ask);
                    for (point, answer) in points.iter().zip(&answers) {
                        assert_eq!(answer.objective, point[0]);
                    }
                }
            });
        }
    });
    runs * calls
}

#[test]
fn concurrent_runs_share_one_durable_write_per_round() {
    // One round travels at a time, and the first is held until the seven other runs have
    // asked: their asks then go as one round, and each round is made durable with one write.
    let dir = tempfile::tempdir().unwrap();
    let store = SledStore::open(dir.path()).unwrap();
    let simulator = NoRoom::default();
    let flushes_before = store.flushes();
    StoredEvaluator::with(&simulator, &store, |evaluator| {
        let objective = objective(false);
        std::thread::scope(|scope| {
            for r in 0..8u32 {
                let (evaluator, objective) = (evaluator, &objective);
                scope.spawn(move || {
                    let x = f64::from(r * 100);
                    let answers = evaluator
                        .evaluate(objective, &[vec![x], vec![x + 0.5]])
                        .unwrap();
                    assert_eq!((answers[0].objective, answers[1].objective), (x, x + 0.5));
                });
            }
            assert!(simulator.started(1, Duration::from_secs(10)));
            let first = simulator.first_points.load(Ordering::SeqCst);
            await_that("the other runs' points to queue", || {
                evaluator.rounds_waiting() + first == 16
            });
            simulator.let_go();
        });
    });
    assert_eq!(simulator.counting.simulated.load(Ordering::SeqCst), 16);
    let batches = simulator.counting.batches.load(Ordering::SeqCst);
    let flushes = store.flushes() - flushes_before;
    assert!(batches <= 2, "{batches} rounds for 8 runs' asks");
    assert!(
        flushes <= batches as u64,
        "{flushes} flushes for {batches} rounds"
    );
    assert_eq!(store.stats().unwrap().evaluations, 16);
}

/// Scores as [`Counting`], never has room for a second round, tells when batches start,
/// and holds its first batch until let go (at most 10 s).
#[derive(Default)]
struct NoRoom {
    counting: Counting,
    started: (std::sync::Mutex<usize>, std::sync::Condvar),
    let_go: (std::sync::Mutex<bool>, std::sync::Condvar),
    /// The points of the first batch.
    first_points: AtomicUsize,
}

impl NoRoom {
    /// Let the first batch go on.
    fn let_go(&self) {
        *self.let_go.0.lock().unwrap() = true;
        self.let_go.1.notify_all();
    }

    /// Whether `n` batches have started within `timeout`.
    fn started(&self, n: usize, timeout: Duration) -> bool {
        let started = self.started.0.lock().unwrap();
        let (started, _) = self
            .started
            .1
            .wait_timeout_while(started, timeout, |s| *s < n)
            .unwrap();
        *started >= n
    }
}

impl Evaluator for NoRoom {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        let first = {
            let mut started = self.started.0.lock().unwrap();
            *started += 1;
            if *started == 1 {
                self.first_points.store(points.len(), Ordering::SeqCst);
            }
            *started == 1
        };
        self.started.1.notify_all();
        if first {
            let held = self.let_go.0.lock().unwrap();
            let timeout = Duration::from_secs(10);
            drop(
                self.let_go
                    .1
                    .wait_timeout_while(held, timeout, |go| !*go)
                    .unwrap(),
            );
        }
        self.counting.evaluate(objective, points)
    }

    fn has_room(&self) -> bool {
        false
    }
}

/// A memory store that runs `before_write` ahead of each evaluation write and
/// `before_lookup` ahead of each lookup.
struct HookedStore<F, G> {
    inner: MemoryStore,
    before_write: F,
    before_lookup: G,
}

impl<F: Fn() + Send + Sync, G: Fn() + Send + Sync> Store for HookedStore<F, G> {
    fn get_evaluations(
        &self,
        keys: &[EvaluationKey],
    ) -> Result<Vec<Option<Evaluation>>, StoreError> {
        (self.before_lookup)();
        self.inner.get_evaluations(keys)
    }
    fn put_evaluations(&self, entries: &[(EvaluationKey, Evaluation)]) -> Result<(), StoreError> {
        (self.before_write)();
        self.inner.put_evaluations(entries)
    }
    fn count_lookups(&self, hits: u64, misses: u64) {
        self.inner.count_lookups(hits, misses)
    }
    fn put_campaign(&self, id: &CampaignId, record: &CampaignRecord) -> Result<(), StoreError> {
        self.inner.put_campaign(id, record)
    }
    fn campaign(&self, id: &CampaignId) -> Result<Option<CampaignRecord>, StoreError> {
        self.inner.campaign(id)
    }
    fn campaigns(&self) -> Result<Vec<(CampaignId, CampaignRecord)>, StoreError> {
        self.inner.campaigns()
    }
    fn put_dataset(&self, hash: &DatasetHash, bytes: &[u8]) -> Result<(), StoreError> {
        self.inner.put_dataset(hash, bytes)
    }
    fn dataset(&self, hash: &DatasetHash) -> Result<Option<Vec<u8>>, StoreError> {
        self.inner.dataset(hash)
    }
    fn raw_entries(&self, collection: Collection) -> Result<Vec<RawEntry>, StoreError> {
        self.inner.raw_entries(collection)
    }
    fn put_raw(&self, collection: Collection, entries: &[RawEntry]) -> Result<(), StoreError> {
        self.inner.put_raw(collection, entries)
    }
    fn stats(&self) -> Result<StoreStats, StoreError> {
        self.inner.stats()
    }
}

#[test]
fn the_next_round_is_simulated_while_a_rounds_write_is_made_durable() {
    // No room for a second round: the next one sets out when the first's simulations are
    // answered, not once its write is durable.
    let simulator = NoRoom::default();
    let (first, saw_second) = (AtomicBool::new(true), AtomicBool::new(false));
    // The first write lasts until a second batch has started (at most 10 s).
    let store = HookedStore {
        inner: MemoryStore::new(),
        before_lookup: || {},
        before_write: || {
            if first.swap(false, Ordering::SeqCst) {
                let second = simulator.started(2, Duration::from_secs(10));
                saw_second.store(second, Ordering::SeqCst);
            }
        },
    };
    StoredEvaluator::with(&simulator, &store, |evaluator| {
        let objective = objective(false);
        std::thread::scope(|scope| {
            let (evaluator, objective, simulator) = (&evaluator, &objective, &simulator);
            scope.spawn(move || evaluator.evaluate(objective, &[vec![0.1]]).unwrap());
            scope.spawn(move || {
                assert!(simulator.started(1, Duration::from_secs(10)));
                evaluator.evaluate(objective, &[vec![0.2]]).unwrap()
            });
            // The first batch answers once the second caller waits for the next round.
            scope.spawn(move || {
                await_that("the second ask to queue", || evaluator.rounds_waiting() > 0);
                simulator.let_go();
            });
        });
        assert!(saw_second.load(Ordering::SeqCst));
        assert_eq!(simulator.counting.simulated.load(Ordering::SeqCst), 2);
        assert_eq!(store.stats().unwrap().evaluations, 2);
    });
}

#[test]
fn asks_that_arrive_while_a_round_is_written_gather_into_the_next() {
    // A slow disk: a round's write lasts while four other runs ask. The round keeps its
    // place until written, so their asks wait and then set out together as one round, not
    // each as a round of its own while the first is made durable.
    let (writing, let_go) = (AtomicBool::new(false), AtomicBool::new(false));
    let store = HookedStore {
        inner: MemoryStore::new(),
        before_write: || {
            if !writing.swap(true, Ordering::SeqCst) {
                await_flag(&let_go);
            }
        },
        before_lookup: || {},
    };
    let simulator = Gauge::default();
    let started_during_the_write = StoredEvaluator::with(&simulator, &store, |evaluator| {
        let objective = objective(false);
        std::thread::scope(|scope| {
            let ask = |x: f64| {
                let (evaluator, objective) = (evaluator, &objective);
                scope.spawn(move || {
                    let answers = evaluator.evaluate(objective, &[vec![x]]).unwrap();
                    assert_eq!(answers[0].objective, x);
                })
            };
            ask(0.0);
            await_flag(&writing);
            for r in 1..=4 {
                ask(f64::from(r));
            }
            let batches = || simulator.counting.batches.load(Ordering::SeqCst);
            await_that("four asks queued, or a round sent", || {
                evaluator.rounds_waiting() == 4 || batches() > 1
            });
            let started = batches();
            let_go.store(true, Ordering::SeqCst);
            started
        })
    });
    assert_eq!(
        started_during_the_write, 1,
        "a round set out during the write"
    );
    assert_eq!(simulator.counting.simulated.load(Ordering::SeqCst), 5);
    assert_eq!(simulator.counting.batches.load(Ordering::SeqCst), 2);
}

/// Has no worker for one objective (by fingerprint); scores the others as [`Counting`].
struct UnavailableFor {
    fingerprint: [u8; 32],
    inner: Counting,
}

impl Evaluator for UnavailableFor {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        if objective.fingerprint() == self.fingerprint {
            std::thread::sleep(Duration::from_millis(20));
            return Err(Fault::unavailable("no worker for this one"));
        }
        self.inner.evaluate(objective, points)
    }
}

#[test]
fn a_round_of_two_objectives_stores_the_answered_one_and_faults_only_the_other() {
    let store = MemoryStore::new();
    let (good, bad) = (objective(false), objective_with_other_data());
    let inner = UnavailableFor {
        fingerprint: bad.fingerprint(),
        inner: Counting::default(),
    };
    StoredEvaluator::with(&inner, &store, |evaluator| {
        let (answered, faulted) = std::thread::scope(|scope| {
            let callers: Vec<_> = (0..6)
                .map(|c| {
                    let (evaluator, objective) =
                        (&evaluator, if c % 2 == 0 { &good } else { &bad });
                    scope.spawn(move || {
                        (0..4)
                            .map(|r| {
                                let x = f64::from(c * 10 + r);
                                evaluator
                                    .evaluate(objective, &[vec![x]])
                                    .map(|a| (a[0].objective, x))
                            })
                            .collect::<Vec<_>>()
                    })
                })
                .collect();
            let mut answered = 0;
            let mut faulted = 0;
            for (c, caller) in callers.into_iter().enumerate() {
                for result in caller.join().unwrap() {
                    match result {
                        Ok((objective, x)) => {
                            assert_eq!(c % 2, 0, "the unavailable objective was answered");
                            assert_eq!(objective, x);
                            answered += 1;
                        }
                        Err(fault) => {
                            assert_eq!(c % 2, 1, "the answered objective faulted: {fault}");
                            faulted += 1;
                        }
                    }
                }
            }
            (answered, faulted)
        });
        assert_eq!((answered, faulted), (12, 12));
        // Only the answered objective's points were stored.
        assert_eq!(store.stats().unwrap().evaluations, 12);
        assert_eq!(inner.inner.simulated.load(Ordering::SeqCst), 12);
    });
}

#[test]
fn overlapping_asks_of_many_runs_simulate_each_point_once() {
    let store = MemoryStore::new();
    let inner = Counting::default();
    StoredEvaluator::with(&inner, &store, |evaluator| {
        let objective = objective(false);
        let pool: Vec<Vec<f64>> = (0..40).map(|i| vec![f64::from(i)]).collect();
        let asked = std::sync::Mutex::new(std::collections::HashSet::new());
        std::thread::scope(|scope| {
            for t in 0..8usize {
                let (evaluator, objective, pool, asked) = (&evaluator, &objective, &pool, &asked);
                scope.spawn(move || {
                    for c in 0..12usize {
                        // Three points each, overlapping other runs' asks and earlier rounds.
                        let batch: Vec<Vec<f64>> = (0..3)
                            .map(|k| pool[(t * 7 + c * 5 + k * 11) % pool.len()].clone())
                            .collect();
                        for p in &batch {
                            asked.lock().unwrap().insert(p[0].to_bits());
                        }
                        let answers = evaluator.evaluate(objective, &batch).unwrap();
                        for (p, a) in batch.iter().zip(answers) {
                            assert_eq!(a.objective, p[0]);
                        }
                    }
                });
            }
        });
        let distinct = asked.lock().unwrap().len();
        assert_eq!(inner.simulated.load(Ordering::SeqCst), distinct);
        let stats = evaluator.stats();
        assert_eq!(stats.requested, 8 * 12 * 3);
        assert_eq!(stats.simulated, distinct as u64);
        let store_stats = store.stats().unwrap();
        assert_eq!(
            (store_stats.hits, store_stats.misses),
            (stats.requested - distinct as u64, distinct as u64)
        );
    });
}

/// Answers one point fewer than it was asked for.
struct AnswersShort;

impl Evaluator for AnswersShort {
    fn evaluate(&self, _: &Objective, points: &[Vec<f64>]) -> Result<Vec<Evaluation>, Fault> {
        Ok(points
            .iter()
            .skip(1)
            .map(|p| Evaluation {
                objective: p[0],
                sse: vec![p[0]],
                failure: None,
                residuals: Vec::new(),
            })
            .collect())
    }
}

#[test]
fn a_batch_answered_short_is_a_fault_and_stores_nothing() {
    let store = MemoryStore::new();
    StoredEvaluator::with(AnswersShort, &store, |evaluator| {
        let objective = objective(false);
        let points: Vec<Vec<f64>> = (0..3).map(|i| vec![f64::from(i)]).collect();
        let fault = evaluator.evaluate(&objective, &points).unwrap_err();
        assert!(fault.message.contains("2 answers for 3 points"), "{fault}");
        assert_eq!(store.stats().unwrap().evaluations, 0);
    });
}

#[test]
fn asks_that_arrive_together_share_one_store_lookup() {
    // A slow disk: the first lookup lasts until all eight runs have asked. The dispatcher
    // then looks up the seven asks that waited with one lookup, not one per ask.
    let (lookups, let_go) = (AtomicUsize::new(0), AtomicBool::new(false));
    let store = HookedStore {
        inner: MemoryStore::new(),
        before_write: || {},
        before_lookup: || {
            if lookups.fetch_add(1, Ordering::SeqCst) == 0 {
                await_flag(&let_go);
            }
        },
    };
    let inner = Counting::default();
    StoredEvaluator::with(&inner, &store, |evaluator| {
        let objective = objective(false);
        std::thread::scope(|scope| {
            for r in 0..8u32 {
                let (evaluator, objective) = (evaluator, &objective);
                scope.spawn(move || {
                    let x = f64::from(r);
                    let answers = evaluator.evaluate(objective, &[vec![x]]).unwrap();
                    assert_eq!(answers[0].objective, x);
                });
            }
            await_that("eight asks", || evaluator.asks_sent() == 8);
            let_go.store(true, Ordering::SeqCst);
        });
    });
    assert_eq!(inner.simulated.load(Ordering::SeqCst), 8);
    let lookups = lookups.load(Ordering::SeqCst);
    assert!(
        lookups <= 2,
        "{lookups} lookups for 8 asks that arrived together"
    );
}

/// Scores as [`Counting`], has room as told, and records the most batches it ran at once.
#[derive(Default)]
struct Gauge {
    counting: Counting,
    room: bool,
    running: AtomicUsize,
    most: AtomicUsize,
}

impl Evaluator for Gauge {
    fn evaluate(
        &self,
        objective: &Objective,
        points: &[Vec<f64>],
    ) -> Result<Vec<Evaluation>, Fault> {
        let now = self.running.fetch_add(1, Ordering::SeqCst) + 1;
        self.most.fetch_max(now, Ordering::SeqCst);
        let answers = self.counting.evaluate(objective, points);
        self.running.fetch_sub(1, Ordering::SeqCst);
        answers
    }

    fn has_room(&self) -> bool {
        self.room
    }
}

#[test]
fn a_second_round_travels_only_where_there_is_room_and_never_a_third() {
    for room in [false, true] {
        let store = MemoryStore::new();
        let inner = Gauge {
            room,
            ..Gauge::default()
        };
        StoredEvaluator::with(&inner, &store, |evaluator| {
            let objective = objective(false);
            let asks = ask_from_runs(evaluator, &objective, 1);
            assert_eq!(inner.counting.simulated.load(Ordering::SeqCst), asks);
        });
        let most = inner.most.load(Ordering::SeqCst);
        if room {
            assert!(most <= super::evaluator::ROUNDS, "{most} rounds at once");
        } else {
            assert_eq!(most, 1, "a second round went without room");
        }
    }
}

/// Datasets are files beside sled's (not values sled would keep in its cache); those a
/// store of an earlier calib keeps in its `datasets` tree are still read, listed once,
/// exported and counted.
#[test]
fn datasets_are_files_beside_the_database_and_those_in_the_tree_are_still_read() {
    let dir = tempfile::tempdir().unwrap();
    let (old, new) = ([4u8; 32], [5u8; 32]);
    {
        let db = raw_db(dir.path());
        db.open_tree("datasets")
            .unwrap()
            .insert(old, &b"old"[..])
            .unwrap();
        db.flush().unwrap();
    }
    {
        let store = SledStore::open(dir.path()).unwrap();
        store.put_dataset(&new, b"new").unwrap();
        store.put_dataset(&old, b"old").unwrap();
    }
    let file = dir.path().join("datasets").join(hex(&new));
    assert_eq!(std::fs::read(&file).unwrap(), b"new");
    assert!(
        !dir.path().join("datasets").join(hex(&old)).exists(),
        "kept in its tree"
    );
    let store = SledStore::open(dir.path()).unwrap();
    assert_eq!(store.dataset(&new).unwrap().as_deref(), Some(&b"new"[..]));
    assert_eq!(store.dataset(&old).unwrap().as_deref(), Some(&b"old"[..]));
    assert_eq!(store.dataset(&[6u8; 32]).unwrap(), None);
    assert_eq!(store.stats().unwrap().datasets, 2);
    let listed = store.raw_entries(Collection::Datasets).unwrap();
    assert_eq!(
        listed,
        [
            (old.to_vec(), b"old".to_vec()),
            (new.to_vec(), b"new".to_vec())
        ]
    );
    // Imported into another store: files there too.
    let other = tempfile::tempdir().unwrap();
    let copy = SledStore::open(other.path()).unwrap();
    copy.put_raw(Collection::Datasets, &listed).unwrap();
    assert!(other.path().join("datasets").join(hex(&old)).exists());
    assert_eq!(copy.stats().unwrap().datasets, 2);
}

/// Two campaigns' evaluators of one shared dispatcher ask for the same points while the
/// first's are simulated: each point is simulated once, counted by the evaluator that sent
/// it, answered to the other as a hit; both get every answer.
#[test]
fn two_evaluators_of_one_shared_dispatcher_simulate_a_shared_point_once() {
    let inner = Arc::new(NoRoom::default());
    let store: Arc<dyn Store> = Arc::new(MemoryStore::new());
    let dispatcher = SharedDispatcher::start(inner.clone(), store.clone());
    let objective = objective(false);
    let points: Vec<Vec<f64>> = (0..6).map(|i| vec![i as f64 * 0.1]).collect();
    let (first, second) = (dispatcher.evaluator(), dispatcher.evaluator());
    let ask = |evaluator: &StoredEvaluator<'_, NoRoom>, points: &[Vec<f64>]| {
        let answers = evaluator.evaluate(&objective, points).unwrap();
        for (p, a) in points.iter().zip(answers) {
            assert_eq!(a.objective, p[0]);
        }
    };
    std::thread::scope(|scope| {
        let first_asks = scope.spawn(|| ask(&first, &points[..4]));
        assert!(inner.started(1, Duration::from_secs(10)), "the first batch");
        // The second asks for two of the first's points in flight, and two others.
        let second_asks = scope.spawn(|| ask(&second, &points[2..]));
        await_that("the second to join the first's points", || {
            first.waiting_on_others() == 2
        });
        inner.let_go();
        first_asks.join().unwrap();
        second_asks.join().unwrap();
    });
    assert_eq!(inner.counting.simulated.load(Ordering::SeqCst), 6);
    let (a, b) = (first.stats(), second.stats());
    assert_eq!((a.requested, a.simulated, a.cached), (4, 4, 0));
    assert_eq!((b.requested, b.simulated, b.cached), (4, 2, 2));
    // Every answer was made durable by the one writer.
    let keys: Vec<EvaluationKey> = points
        .iter()
        .map(|p| evaluation_key(&objective, p))
        .collect();
    let stored = store.get_evaluations(&keys).unwrap();
    assert!(stored.iter().all(Option::is_some));
}

/// A shared dispatcher outlives the evaluators it hands out: one dropped, the next still
/// answers, from the store what the first simulated; dropping the dispatcher ends its
/// threads.
#[test]
fn a_shared_dispatcher_serves_evaluators_one_after_another() {
    let inner = Arc::new(Counting::default());
    let dispatcher = SharedDispatcher::start(inner.clone(), Arc::new(MemoryStore::new()));
    let objective = objective(false);
    let points: Vec<Vec<f64>> = (0..3).map(|i| vec![i as f64]).collect();
    {
        let first = dispatcher.evaluator();
        first.evaluate(&objective, &points).unwrap();
        assert_eq!(first.stats().simulated, 3);
    }
    let second = dispatcher.evaluator();
    let answers = second.evaluate(&objective, &points).unwrap();
    assert_eq!(answers[2].objective, 2.0);
    assert_eq!((second.stats().simulated, second.stats().cached), (0, 3));
    drop(second);
    drop(dispatcher);
    assert_eq!(
        Arc::strong_count(&inner),
        1,
        "the dispatcher's threads ended"
    );
}
