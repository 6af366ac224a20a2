//! Calibration spread over workers: same results as in one process, whatever happens to
//! the workers; workers found by registration and by DNS.

use crate::common::cluster::*;
use crate::common::*;
use calib_engine::calibration::{calibrate, Calibration};
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use calib_service::dispatch::{DispatchConfig, Health, RemoteWorkers, WorkerAddress};
use std::time::Duration;

fn campaign(dir: &std::path::Path, max_evaluations: usize) -> Campaign {
    let search = format!(
        "methods = [\"nelder-mead\", \"powell\"]\nstarts = 2\nmax_evaluations = {max_evaluations}\nseed = 3"
    );
    Campaign::load(&write(dir, "c.toml", &clean_campaign(&search))).unwrap()
}

/// Every run found the same point with the same objective, bit for bit, in as many evaluations.
fn assert_same(local: &Calibration, cluster: &Calibration) {
    assert_eq!(local.runs.len(), cluster.runs.len());
    for (a, b) in local.runs.iter().zip(&cluster.runs) {
        let bits = |p: &[f64]| p.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert_eq!(
            bits(&a.point),
            bits(&b.point),
            "{} from {}",
            a.method,
            a.start
        );
        assert_eq!(a.objective.to_bits(), b.objective.to_bits());
        assert_eq!(a.evaluations, b.evaluations);
        assert_eq!(a.iterations, b.iterations);
    }
    assert_eq!(local.best, cluster.best);
    assert_eq!(
        local.nominal.objective.to_bits(),
        cluster.nominal.objective.to_bits()
    );
    assert_eq!(local.best_evaluation.sse, cluster.best_evaluation.sse);
    // Which of two concurrent runs asking for one point simulates it is a race: only the
    // count of requests is fixed.
    assert_eq!(local.stats.requested, cluster.stats.requested);
}

#[test]
fn a_cluster_run_equals_the_local_run() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 150);
    let local = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let remote_result = calibrate(&campaign, remote.evaluator(), &Silent).unwrap();
    assert_same(&local, &remote_result);
    let simulations: Vec<u64> = cluster.workers.iter().map(|w| w.simulations()).collect();
    println!(
        "{} simulated, per worker {simulations:?}",
        remote_result.stats.simulated
    );
    assert!(simulations.iter().all(|&s| s > 0), "{simulations:?}");
    assert_eq!(
        simulations.iter().sum::<u64>(),
        remote_result.stats.simulated
    );
}

#[test]
fn a_worker_killed_mid_campaign_costs_only_time() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 400);
    let local = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let mut cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let evaluator = remote.evaluator();
    let (result, at_kill) = std::thread::scope(|scope| {
        let run = scope.spawn(|| calibrate(&campaign, evaluator, &Silent));
        await_condition(
            "worker 0 to serve 20 simulations",
            Duration::from_secs(60),
            || cluster.workers[0].simulations() >= 20,
        );
        assert!(!run.is_finished(), "the campaign ended before the kill");
        cluster.workers[0].kill();
        let at_kill = cluster.workers[1].simulations();
        (run.join().unwrap(), at_kill)
    });
    let result = result.unwrap();
    assert_same(&local, &result);
    let survivor = cluster.workers[1].simulations();
    println!(
        "killed worker served {}, survivor {at_kill} before the kill and {survivor} in all, of {}",
        cluster.workers[0].simulations(),
        result.stats.simulated
    );
    assert!(survivor > at_kill, "the survivor did the rest");
    let views = remote.pool().workers();
    assert!(
        matches!(views[0].health, Health::Down { .. }),
        "{:?}",
        views[0]
    );
}

#[test]
fn a_registered_worker_serves_the_coordinator() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let (coordinator, worker) = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let mut dispatch = DispatchConfig::new(Vec::new());
        dispatch.probe_interval = Duration::from_millis(100);
        let coordinator = calib_service::server::serve_coordinator(
            listener,
            calib_service::server::CoordinatorConfig::new("127.0.0.1:0".parse().unwrap(), dispatch),
        )
        .unwrap();
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let mut config = calib_worker::service::WorkerConfig::new(listener.local_addr().unwrap());
        config.slots = 1;
        config.register = Some(format!("http://{}", coordinator.address()));
        let worker = calib_worker::service::serve_worker(listener, config).unwrap();
        (coordinator, worker)
    });
    let url = format!("http://{}", worker.address());
    await_condition(
        "the worker to register and come up",
        Duration::from_secs(20),
        || {
            coordinator
                .pool()
                .workers()
                .iter()
                .any(|w| w.url == url && w.health == Health::Up)
        },
    );
    let evaluator = calib_service::dispatch::GrpcEvaluator::new(
        coordinator.pool().clone(),
        runtime.handle().clone(),
    );
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 30);
    let result = calibrate(&campaign, evaluator, &Silent).unwrap();
    assert!(result.stats.simulated > 0);
    assert_eq!(worker.load().completed, result.stats.simulated);
}

#[test]
fn a_dns_name_resolves_to_workers() {
    let cluster = TestCluster::start(1, 1);
    let port = cluster.workers[0].address().port();
    let mut config = DispatchConfig::new(vec![WorkerAddress::Dns {
        host: "localhost".into(),
        port,
    }]);
    config.probe_interval = Duration::from_millis(100);
    config.resolve_interval = Duration::from_millis(200);
    let remote = RemoteWorkers::connect(config).unwrap();
    assert!(
        remote.wait_until_up(1, Duration::from_secs(10)),
        "{:?}",
        remote.pool().workers()
    );
    let up: Vec<_> = remote
        .pool()
        .workers()
        .into_iter()
        .filter(|w| w.health == Health::Up)
        .collect();
    assert_eq!(up[0].url, format!("http://127.0.0.1:{port}"));
}

#[test]
fn an_invalid_request_is_a_fault_and_is_not_retried() {
    use calib_engine::evaluator::Evaluator;
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 10);
    let measurement = calib_engine::calibration::load_measurement(&campaign).unwrap();
    let mut objective = calib_engine::objective::Objective::new(&campaign, &measurement).unwrap();
    let g = objective.model.info().parameter_index("g").unwrap();
    objective.base[g] = f64::NAN;
    let cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let fault = remote
        .evaluator()
        .evaluate(&objective, &[vec![0.01, 0.002], vec![0.011, 0.002]])
        .unwrap_err();
    // No penalty is made up for the points: the batch fails as a whole, not retryable.
    assert!(!fault.is_retryable(), "{fault:?}");
    assert!(fault.message.contains("rejected the request"), "{fault}");
    assert!(fault.message.contains("parameters["), "{fault}");
    // Nobody simulated, and no worker was taken out for the client's mistake.
    assert!(cluster.workers.iter().all(|w| w.simulations() == 0));
    assert!(remote
        .pool()
        .workers()
        .iter()
        .all(|w| w.health == Health::Up));
}

#[test]
fn a_hanging_worker_costs_a_deadline_and_its_points_go_elsewhere() {
    use calib_engine::evaluator::Evaluator;
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 10);
    let measurement = calib_engine::calibration::load_measurement(&campaign).unwrap();
    let objective = calib_engine::objective::Objective::new(&campaign, &measurement).unwrap();
    let good = TestWorker::start(1, 64);
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let (hanging_url, hanging) = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let url = format!("http://{}", listener.local_addr().unwrap());
        let napper = calib_sandbox::serve_napping(listener, Duration::from_secs(3600), 1).await;
        (url, napper)
    });
    let mut config = DispatchConfig::new(vec![
        WorkerAddress::Url(good.url()),
        WorkerAddress::Url(hanging_url.clone()),
    ]);
    config.probe_interval = Duration::from_millis(100);
    // Far longer than the good worker's chunks take, queued behind each other on its one
    // slot, even on a loaded machine (a chunk past it would be sent again: simulated twice).
    config.deadline = Duration::from_secs(5);
    let remote = RemoteWorkers::connect(config).unwrap();
    assert!(remote.wait_until_up(2, Duration::from_secs(10)));
    let points: Vec<Vec<f64>> = (0..8)
        .map(|i| vec![0.01 + 1e-4 * f64::from(i), 0.002])
        .collect();
    let expected: Vec<_> = points.iter().map(|p| objective.evaluate(p)).collect();
    let answered = remote.evaluator().evaluate(&objective, &points).unwrap();
    assert_eq!(answered, expected);
    assert!(
        hanging.requests() >= 1,
        "the hanging worker was never tried"
    );
    // Every point answered once, all by the good worker. (A chunk of the good worker's that
    // outlives the deadline on a loaded machine is sent again, so it may simulate a point
    // twice: what it simulated is at least, not exactly, what it answered.)
    let answered_by = |url: &str| {
        let workers = remote.pool().workers();
        let worker = workers.iter().find(|w| w.url == url);
        worker
            .unwrap_or_else(|| panic!("{url} not in {workers:?}"))
            .evaluated
    };
    assert_eq!(answered_by(&good.url()), 8);
    assert_eq!(answered_by(&hanging_url), 0);
    assert!(good.simulations() >= 8, "{}", good.simulations());
}

#[test]
fn the_test_cluster_binds_distinct_ports_and_kill_closes_one() {
    let mut cluster = TestCluster::start(3, 1);
    let mut ports: Vec<u16> = cluster.workers.iter().map(|w| w.address().port()).collect();
    ports.sort_unstable();
    ports.dedup();
    assert_eq!(ports.len(), 3);
    let address = cluster.workers[1].address();
    assert!(std::net::TcpStream::connect(address).is_ok());
    cluster.workers[1].kill();
    assert!(!cluster.workers[1].is_alive());
    await_condition(
        "the killed worker's port to close",
        Duration::from_secs(5),
        || std::net::TcpStream::connect(address).is_err(),
    );
    assert!(std::net::TcpStream::connect(cluster.workers[0].address()).is_ok());
}

/// The viscous-arm example with two starts, its measurement path made absolute.
fn small_diagnosis(dir: &std::path::Path) -> Campaign {
    let text = std::fs::read_to_string(repo().join("examples/furuta_viscous_arm.toml"))
        .unwrap()
        .replace("starts = 4", "starts = 2")
        .replace(
            "file = \"data/furuta_viscous_arm.csv\"",
            &format!(
                "file = \"{}\"",
                repo()
                    .join("examples/data/furuta_viscous_arm.csv")
                    .display()
            ),
        );
    Campaign::load(&write(dir, "viscous.toml", &text)).unwrap()
}

#[test]
fn a_diagnosis_on_the_cluster_equals_the_local_one() {
    use calib_analysis::diagnosis::diagnose;
    let dir = tempfile::tempdir().unwrap();
    let campaign = small_diagnosis(dir.path());
    let local = diagnose(&campaign, &LocalEvaluator, &Silent).unwrap();
    let cluster = TestCluster::start(2, 1);
    let remote = cluster.connect();
    let remote_result = diagnose(&campaign, &remote.evaluator(), &Silent).unwrap();

    // `Simulate` runs the same model call on the same parameters, grid, outputs and solver
    // settings as `Objective::simulate`: everything agrees bit for bit.
    let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(local.selected, remote_result.selected);
    assert_eq!(local.verdict, remote_result.verdict);
    let ranking = |d: &calib_analysis::diagnosis::Diagnosis| {
        d.candidates
            .iter()
            .map(|c| {
                (
                    c.effect.clone(),
                    c.score.to_bits(),
                    c.objective.map(f64::to_bits),
                )
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(ranking(&local), ranking(&remote_result));
    for (a, b) in [
        (&local.baseline, &remote_result.baseline),
        (&local.final_fit, &remote_result.final_fit),
    ] {
        assert_eq!(a.objective.to_bits(), b.objective.to_bits());
        assert_eq!(
            a.held_out_objective.to_bits(),
            b.held_out_objective.to_bits()
        );
        assert_eq!(bits(&a.point), bits(&b.point));
        assert_eq!(bits(&a.rms), bits(&b.rms));
    }
    let simulations: Vec<u64> = cluster.workers.iter().map(|w| w.simulations()).collect();
    println!(
        "selected {:?}, objective {:.4e} -> {:.4e}; per worker {simulations:?}",
        remote_result.selected, remote_result.baseline.objective, remote_result.final_fit.objective
    );
    assert!(simulations.iter().all(|&s| s > 0), "{simulations:?}");
}

/// A resolver the test sets: the addresses a name resolves to, or a failure.
#[derive(Default)]
struct SetResolver {
    answer: std::sync::Mutex<Option<Vec<std::net::SocketAddr>>>,
    calls: std::sync::atomic::AtomicU64,
}

impl SetResolver {
    fn set(&self, answer: Option<Vec<std::net::SocketAddr>>) {
        *self.answer.lock().unwrap() = answer;
    }

    fn calls(&self) -> u64 {
        self.calls.load(std::sync::atomic::Ordering::SeqCst)
    }
}

impl calib_service::dispatch::Resolve for SetResolver {
    fn resolve(&self, _name: &str) -> calib_service::dispatch::discovery::Resolution {
        self.calls.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        let answer = self.answer.lock().unwrap().clone();
        Box::pin(
            async move { answer.ok_or_else(|| std::io::Error::other("name server unreachable")) },
        )
    }
}

/// URLs of the pool's workers that are up, sorted.
fn up_urls(remote: &RemoteWorkers) -> Vec<String> {
    let mut urls: Vec<String> = remote
        .pool()
        .workers()
        .into_iter()
        .filter(|w| w.health == Health::Up)
        .map(|w| w.url)
        .collect();
    urls.sort();
    urls
}

#[test]
fn a_dns_name_resolved_again_adds_and_drops_workers() {
    use calib_engine::evaluator::Evaluator;
    let cluster = TestCluster::start(2, 1);
    let (a, b) = (cluster.workers[0].address(), cluster.workers[1].address());
    let resolver = std::sync::Arc::new(SetResolver::default());
    resolver.set(Some(vec![a]));
    let mut config = DispatchConfig::new(vec![WorkerAddress::Dns {
        host: "calib-workers.test".into(),
        port: 50051,
    }]);
    config.probe_interval = Duration::from_millis(100);
    config.resolve_interval = Duration::from_millis(100);
    config.resolver = calib_service::dispatch::Resolver(resolver.clone());
    let remote = RemoteWorkers::connect(config).unwrap();
    let wait_for = |what: &str, urls: Vec<String>| {
        await_condition(what, Duration::from_secs(10), || {
            up_urls(&remote) == urls && remote.pool().workers().len() == urls.len()
        })
    };
    wait_for("the first address to be up", vec![format!("http://{a}")]);

    resolver.set(Some(vec![b, a]));
    let mut both = vec![format!("http://{a}"), format!("http://{b}")];
    both.sort();
    wait_for("the added address to join", both);

    resolver.set(Some(vec![b]));
    wait_for("the vanished address to leave", vec![format!("http://{b}")]);

    // A failed resolution keeps the workers there are.
    resolver.set(None);
    let calls = resolver.calls();
    await_condition("two failed resolutions", Duration::from_secs(10), || {
        resolver.calls() >= calls + 2
    });
    assert_eq!(up_urls(&remote), vec![format!("http://{b}")]);

    // Work goes to the worker the name resolves to now, and only there.
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 10);
    let measurement = calib_engine::calibration::load_measurement(&campaign).unwrap();
    let objective = calib_engine::objective::Objective::new(&campaign, &measurement).unwrap();
    let points: Vec<Vec<f64>> = (0..4)
        .map(|i| vec![0.01 + 1e-4 * f64::from(i), 0.002])
        .collect();
    let expected: Vec<_> = points.iter().map(|p| objective.evaluate(p)).collect();
    assert_eq!(
        remote.evaluator().evaluate(&objective, &points).unwrap(),
        expected
    );
    assert_eq!(cluster.workers[0].simulations(), 0);
    assert_eq!(cluster.workers[1].simulations(), 4);
}

#[test]
fn a_failed_worker_is_probed_back_in() {
    use calib_engine::evaluator::Evaluator;
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 10);
    let measurement = calib_engine::calibration::load_measurement(&campaign).unwrap();
    let objective = calib_engine::objective::Objective::new(&campaign, &measurement).unwrap();
    let mut first = TestWorker::start(1, 64);
    let address = first.address();
    // Held across the kill: the port refuses connections and stays free for the second.
    let _port = calib_sandbox::hold_port(address).unwrap();
    let mut config = DispatchConfig::new(vec![WorkerAddress::Url(first.url())]);
    config.probe_interval = Duration::from_millis(100);
    config.wait_for_workers = Duration::from_secs(60);
    let remote = RemoteWorkers::connect(config).unwrap();
    assert!(remote.wait_until_up(1, Duration::from_secs(10)));
    first.kill();
    await_condition(
        "the killed worker's port to refuse connections",
        Duration::from_secs(5),
        || std::net::TcpStream::connect(address).is_err(),
    );
    assert!(
        std::net::TcpListener::bind(address).is_err(),
        "the port is free for anyone to take"
    );

    let points: Vec<Vec<f64>> = vec![vec![0.01, 0.002], vec![0.012, 0.002]];
    let expected: Vec<_> = points.iter().map(|p| objective.evaluate(p)).collect();
    let evaluator = remote.evaluator();
    let (answered, second) = std::thread::scope(|scope| {
        let batch = scope.spawn(|| evaluator.evaluate(&objective, &points));
        // The batch finds the worker gone and takes it out...
        await_condition(
            "the dead worker to be taken out",
            Duration::from_secs(20),
            || matches!(remote.pool().workers()[0].health, Health::Down { .. }),
        );
        assert!(!batch.is_finished(), "the batch waits for a worker");
        // ...until it is back at its address, where a probe finds it.
        let second = TestWorker::start_at(address, 1);
        (batch.join().unwrap(), second)
    });
    assert_eq!(answered.unwrap(), expected);
    assert_eq!(second.simulations(), 2);
    assert_eq!(remote.pool().workers()[0].health, Health::Up);
}

#[test]
fn a_registration_lapses_after_missed_renewals() {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let coordinator = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let mut dispatch = DispatchConfig::new(Vec::new());
        dispatch.probe_interval = Duration::from_millis(100);
        // Renewals every two seconds; three missed (6 s) and the worker is dropped: a
        // renewal late by seconds on a loaded machine still keeps a live worker listed.
        dispatch.heartbeat = Duration::from_secs(2);
        calib_service::server::serve_coordinator(
            listener,
            calib_service::server::CoordinatorConfig::new("127.0.0.1:0".parse().unwrap(), dispatch),
        )
        .unwrap()
    });
    let registry = format!("http://{}", coordinator.address());
    let mut leaving = TestWorker::start_registered(1, &registry);
    let staying = TestWorker::start_registered(1, &registry);
    let listed = |worker: &TestWorker| {
        coordinator
            .pool()
            .workers()
            .iter()
            .any(|w| w.url == worker.url())
    };
    await_condition(
        "both workers to register and come up",
        Duration::from_secs(20),
        || {
            coordinator
                .pool()
                .workers()
                .iter()
                .filter(|w| w.health == Health::Up)
                .count()
                == 2
        },
    );
    leaving.kill();
    assert!(listed(&leaving), "dropped before its registration lapsed");
    await_condition(
        "the silent worker's registration to lapse",
        Duration::from_secs(30),
        || !listed(&leaving),
    );
    // The worker that kept renewing stays.
    assert!(listed(&staying));
    runtime.block_on(coordinator.shutdown());
}

/// A coordinator's pool on one napping worker of two slots that sleeps `nap` per point,
/// once the worker has answered a first point (so that its speed is known).
fn napping_pool(
    nap: Duration,
) -> (
    tokio::runtime::Runtime,
    std::sync::Arc<calib_sandbox::NappingSimulator>,
    calib_service::dispatch::RemoteWorkers,
    calib_engine::objective::Objective,
    tempfile::TempDir,
) {
    use calib_engine::evaluator::Evaluator;
    let pool = unmeasured_napping_pool(nap);
    // The worker gets the measurement first.
    pool.2
        .evaluator()
        .evaluate(&pool.3, &[vec![0.01, 0.002]])
        .unwrap();
    pool
}

/// A coordinator's pool on one napping worker of two slots that sleeps `nap` per point, up
/// and not yet sent anything (its speed unknown, the measurement not yet sent).
fn unmeasured_napping_pool(
    nap: Duration,
) -> (
    tokio::runtime::Runtime,
    std::sync::Arc<calib_sandbox::NappingSimulator>,
    calib_service::dispatch::RemoteWorkers,
    calib_engine::objective::Objective,
    tempfile::TempDir,
) {
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 10);
    let measurement = calib_engine::calibration::load_measurement(&campaign).unwrap();
    let objective = calib_engine::objective::Objective::new(&campaign, &measurement).unwrap();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let (url, napper) = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let url = format!("http://{}", listener.local_addr().unwrap());
        let napper = calib_sandbox::serve_napping(listener, nap, 2).await;
        (url, napper)
    });
    let mut config = DispatchConfig::new(vec![WorkerAddress::Url(url)]);
    config.probe_interval = Duration::from_millis(100);
    let remote = RemoteWorkers::connect(config).unwrap();
    assert!(remote.wait_until_up(1, Duration::from_secs(10)));
    (runtime, napper, remote, objective, dir)
}

fn distinct_points(n: u32) -> Vec<Vec<f64>> {
    (0..n)
        .map(|i| vec![0.01 + 1e-6 * f64::from(i), 0.002])
        .collect()
}

#[test]
fn a_slow_workers_chunks_hold_a_point_per_slot_two_in_flight() {
    use calib_engine::evaluator::Evaluator;
    // Half a second per point: far beyond the 50 ms of work a chunk holds per slot.
    let (_runtime, napper, remote, objective, _dir) = napping_pool(Duration::from_millis(500));
    let before = napper.requests();
    let answered = remote
        .evaluator()
        .evaluate(&objective, &distinct_points(10))
        .unwrap();
    assert_eq!(answered.len(), 10);
    assert_eq!(
        napper.requests() - before,
        5,
        "five chunks of one point per slot"
    );
    assert_eq!(napper.most_points(), 2, "one point per slot");
    assert_eq!(napper.most_in_flight(), 2, "one chunk runs, the next waits");
}

#[test]
fn a_fast_workers_chunks_grow_past_eight_points_per_slot() {
    use calib_engine::evaluator::Evaluator;
    use calib_service::dispatch::pool::{CHUNK_SECONDS, MAX_POINTS_PER_SLOT};
    // A worker of two slots that takes a millisecond per point. Its speed is recorded in
    // the pool as its first answer records it (one point in 1 ms), not timed here: what a
    // loaded machine would measure is no part of the claim, how chunks follow it is.
    let (_runtime, napper, remote, objective, _dir) =
        unmeasured_napping_pool(Duration::from_millis(1));
    let pool = remote.pool();
    let leases = pool.acquire(1, usize::MAX);
    assert_eq!(leases.iter().map(|l| l.points).collect::<Vec<_>>(), [1]);
    pool.release(&leases[0], 1, Duration::from_millis(1));
    let answered = remote
        .evaluator()
        .evaluate(&objective, &distinct_points(1024))
        .unwrap();
    assert_eq!(answered.len(), 1024);
    // The first chunk holds CHUNK_SECONDS of work per slot: 50 points on each of the two,
    // far more than the eight points per slot a worker of unknown speed is sent. Later
    // chunks follow the speed the answers measure, which the nap keeps at 1 ms or more.
    let per_slot = (CHUNK_SECONDS / 1e-3) as u64;
    assert!(per_slot > MAX_POINTS_PER_SLOT as u64);
    assert_eq!(napper.most_points(), 2 * per_slot, "the largest request");
}

/// `workers` napping workers of `slots` slots each, sleeping `nap` per point, a coordinator's
/// pool connected to them (not yet waited for), and the objective of a small campaign (its
/// files live in the returned folder).
fn napping_cluster(
    workers: usize,
    nap: Duration,
    slots: u32,
) -> (
    tempfile::TempDir,
    calib_engine::objective::Objective,
    calib_sandbox::NappingCluster,
    RemoteWorkers,
) {
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 10);
    let measurement = calib_engine::calibration::load_measurement(&campaign).unwrap();
    let objective = calib_engine::objective::Objective::new(&campaign, &measurement).unwrap();
    let nappers = calib_sandbox::NappingCluster::start(workers, nap, slots).unwrap();
    let remote = nappers.try_connect().unwrap();
    (dir, objective, nappers, remote)
}

#[test]
fn a_batch_that_fits_the_idle_slots_goes_evenly_in_one_request_per_worker() {
    use calib_engine::evaluator::Evaluator;
    let (_dir, objective, nappers, remote) = napping_cluster(2, Duration::from_millis(20), 2);
    assert!(remote.wait_until_up(2, Duration::from_secs(10)));
    let batch = |k: u32| -> Vec<Vec<f64>> {
        (0..8)
            .map(|i| vec![0.01 + 1e-4 * f64::from(8 * k + i), 0.002])
            .collect()
    };
    // The workers get the measurement first.
    remote.evaluator().evaluate(&objective, &batch(0)).unwrap();
    let requests = || -> Vec<u64> { nappers.simulators.iter().map(|n| n.requests()).collect() };
    for k in 1..4 {
        // Each batch from a pool of its own, to which the workers' speed is unknown: up to
        // eight points per slot, whatever this machine's speed would have made of the naps.
        let remote = nappers.try_connect().unwrap();
        assert!(remote.wait_until_up(2, Duration::from_secs(10)));
        let before = requests();
        let answered = remote.evaluator().evaluate(&objective, &batch(k)).unwrap();
        assert_eq!(answered.len(), 8);
        let sent: Vec<u64> = requests().iter().zip(&before).map(|(a, b)| a - b).collect();
        // Eight points over four idle slots: four to each worker, in one request each.
        assert_eq!(sent, vec![1, 1], "requests per worker for batch {k}");
    }
    let most: Vec<u64> = nappers.simulators.iter().map(|n| n.most_points()).collect();
    assert_eq!(most, vec![4, 4], "largest request per worker");
}

#[test]
fn a_pool_whose_slots_are_all_busy_has_no_room_for_a_second_round() {
    use calib_engine::evaluator::Evaluator;
    let (_dir, objective, _nappers, remote) = napping_cluster(1, Duration::from_millis(300), 2);
    assert!(remote.wait_until_up(1, Duration::from_secs(10)));
    let evaluator = remote.evaluator();
    assert!(evaluator.has_room(), "an idle worker is room");
    let batch: Vec<Vec<f64>> = (0..4)
        .map(|i| vec![0.01 + 1e-4 * f64::from(i), 0.002])
        .collect();
    let busy = || remote.pool().workers()[0].busy;
    // The batch goes as one chunk of two points per slot, whose slots stay busy from the
    // lease until its answer: room asked between two readings of both slots busy is room
    // asked while they were busy. Should the batch be answered between the readings (a
    // stalled machine), the next batch asks again.
    let mut seen = None;
    for attempt in 0..20 {
        std::thread::scope(|scope| {
            let points: Vec<Vec<f64>> = batch
                .iter()
                .map(|p| vec![p[0] + 1e-3 * f64::from(attempt), p[1]])
                .collect();
            let (evaluator, objective) = (&evaluator, &objective);
            let running = scope.spawn(move || evaluator.evaluate(objective, &points).unwrap());
            await_condition(
                "the batch to occupy both slots",
                Duration::from_secs(10),
                || busy() >= 2 || running.is_finished(),
            );
            let before = busy();
            let room = evaluator.has_room();
            if before >= 2 && busy() >= 2 {
                seen = Some(room);
            }
            assert_eq!(running.join().unwrap().len(), 4);
        });
        if seen.is_some() {
            break;
        }
    }
    // The worker's queue could take more, but a queue is not an idle slot: a second round
    // would only wait there, and it grows larger by waiting here instead.
    assert_eq!(seen, Some(false), "room while both slots were busy");
    assert!(evaluator.has_room(), "answered, the slots are idle again");
}

#[test]
fn the_measurement_travels_to_each_worker_once() {
    use calib_engine::evaluator::Evaluator;
    let (_dir, objective, nappers, remote) = napping_cluster(2, Duration::from_millis(20), 1);
    // Both up before the first batch, or one of them could take it all.
    assert!(remote.wait_until_up(2, Duration::from_secs(10)));
    let batch = |k: u32| -> Vec<Vec<f64>> {
        (0..8)
            .map(|i| vec![0.01 + 1e-4 * f64::from(8 * k + i), 0.002])
            .collect()
    };
    remote.evaluator().evaluate(&objective, &batch(0)).unwrap();
    let uploads: Vec<u64> = nappers.simulators.iter().map(|n| n.uploads()).collect();
    // Once per worker, or once per chunk in flight when the first chunks cross.
    assert!(uploads.iter().all(|&u| (1..=2).contains(&u)), "{uploads:?}");
    for k in 1..4 {
        remote.evaluator().evaluate(&objective, &batch(k)).unwrap();
    }
    let again: Vec<u64> = nappers.simulators.iter().map(|n| n.uploads()).collect();
    assert_eq!(
        again, uploads,
        "later batches name the measurement by its hash"
    );
    let requests: u64 = nappers.simulators.iter().map(|n| n.requests()).sum();
    assert!(
        requests >= 8,
        "{requests} requests for 32 points: at least a chunk per worker per batch"
    );
}
