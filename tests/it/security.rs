//! TLS and the bearer token: a calibration over a TLS worker that requires a token gives
//! the local result; requests without the token or with another are refused; a client
//! that does not trust the worker's certificate, or presents a wrong token, stops with a
//! clear message; a worker registers with a TLS coordinator; the token is never logged.
//! Certificates are made here, at test time.

use crate::common::cluster::TestWorker;
use crate::common::pki::Pki;
use crate::common::*;
use calib_engine::calibration::calibrate;
use calib_engine::campaign::Campaign;
use calib_engine::evaluator::LocalEvaluator;
use calib_engine::optim::problem::Silent;
use calib_proto::v1 as proto;
use calib_security::{ClientSecurity, ServerTls};
use calib_service::dispatch::{DispatchConfig, Health, RemoteWorkers, WorkerAddress};
use std::path::Path;
use std::time::Duration;

const TOKEN: &str = "k7Qz-cluster-secret-91";

/// A single-slot worker serving TLS and requiring `token`.
fn secure_worker(pki: &Pki, token: Option<&str>) -> TestWorker {
    let security = pki.server(token);
    TestWorker::start_with(move |config| {
        config.slots = 1;
        config.security = security;
    })
}

fn campaign(dir: &Path, max_evaluations: usize) -> Campaign {
    let search = format!(
        "methods = [\"nelder-mead\", \"powell\"]\nstarts = 2\nmax_evaluations = {max_evaluations}\nseed = 3"
    );
    Campaign::load(&write(dir, "c.toml", &clean_campaign(&search))).unwrap()
}

fn dispatch_config(urls: &[String], security: ClientSecurity) -> DispatchConfig {
    let mut config = DispatchConfig::new(urls.iter().cloned().map(WorkerAddress::Url).collect());
    config.probe_interval = Duration::from_millis(50);
    config.wait_for_workers = Duration::from_secs(30);
    config.security = security;
    config
}

#[test]
fn a_calibration_over_tls_with_a_token_equals_the_local_run() {
    let pki = Pki::new();
    let dir = tempfile::tempdir().unwrap();
    let campaign = campaign(dir.path(), 120);
    let local = calibrate(&campaign, LocalEvaluator, &Silent).unwrap();
    let workers = [
        secure_worker(&pki, Some(TOKEN)),
        secure_worker(&pki, Some(TOKEN)),
    ];
    let urls: Vec<String> = workers.iter().map(|w| w.url()).collect();
    assert!(
        urls.iter().all(|u| u.starts_with("https://127.0.0.1:")),
        "{urls:?}"
    );
    let remote = RemoteWorkers::connect(dispatch_config(&urls, pki.client(Some(TOKEN)))).unwrap();
    assert!(
        remote.wait_until_up(2, Duration::from_secs(20)),
        "{:?}",
        remote.pool().workers()
    );
    let cluster = calibrate(&campaign, remote.evaluator(), &Silent).unwrap();
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
    }
    assert_eq!(local.best, cluster.best);
    let simulated: u64 = workers.iter().map(|w| w.simulations()).sum();
    assert!(simulated > 0);
    assert_eq!(simulated, cluster.stats.simulated);
}

/// The worker's Simulator and Health, called directly over TLS with `token` presented.
async fn call_worker(
    pki: &Pki,
    url: &str,
    token: Option<&str>,
) -> (Result<proto::StatusResponse, tonic::Status>, i32) {
    let security = pki.client(token);
    let channel = security
        .endpoint(url, None)
        .unwrap()
        .connect()
        .await
        .unwrap();
    let channel = security.authorize(channel);
    let status = proto::simulator_client::SimulatorClient::new(channel.clone())
        .status(proto::StatusRequest {
            protocol_version: calib_proto::PROTOCOL_VERSION,
        })
        .await
        .map(|r| r.into_inner());
    let health = tonic_health::pb::health_client::HealthClient::new(channel)
        .check(tonic_health::pb::HealthCheckRequest {
            service: "calib.v1.Simulator".into(),
        })
        .await
        .expect("health checks need no token")
        .into_inner()
        .status;
    (status, health)
}

#[test]
fn a_missing_or_wrong_token_is_refused_as_unauthenticated() {
    let pki = Pki::new();
    let worker = secure_worker(&pki, Some(TOKEN));
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        let serving = tonic_health::pb::health_check_response::ServingStatus::Serving as i32;
        for token in [None, Some("k7Qz-cluster-secret-92"), Some("k7Qz")] {
            let (status, health) = call_worker(&pki, &worker.url(), token).await;
            let refused = status.expect_err("a request without the right token is refused");
            assert_eq!(refused.code(), tonic::Code::Unauthenticated, "{token:?}");
            assert!(!refused.message().contains(TOKEN), "{refused:?}");
            assert_eq!(health, serving, "health checks stay open");
        }
        let (status, _) = call_worker(&pki, &worker.url(), Some(TOKEN)).await;
        assert_eq!(status.unwrap().slots, 1);
    });
    assert_eq!(worker.simulations(), 0);
}

/// `calib calibrate` of a small campaign on `workers` with `extra` arguments: exit code
/// and standard error.
fn calibrate_cli(dir: &Path, workers: &str, extra: &[&str]) -> (Option<i32>, String) {
    let campaign = write(
        dir,
        "clean.toml",
        &clean_campaign("methods = [\"nelder-mead\"]\nmax_evaluations = 30"),
    );
    let db = dir.join("db");
    let mut args = vec![
        "calibrate",
        campaign.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
        "--workers",
        workers,
    ];
    args.extend_from_slice(extra);
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .args(&args)
        .env_remove(calib_security::TOKEN_ENV)
        .env("CALIB_PROGRESS", "lines")
        .output()
        .expect("run calib");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_client_that_does_not_trust_the_certificate_stops_with_a_clear_error() {
    let pki = Pki::new();
    let worker = secure_worker(&pki, None);
    let remote =
        RemoteWorkers::connect(dispatch_config(&[worker.url()], ClientSecurity::default()))
            .unwrap();
    let error = remote
        .wait_for_worker(Duration::from_secs(30), |_| {})
        .expect_err("a certificate of an unknown CA is not trusted");
    assert!(error.contains("TLS handshake failed"), "{error}");
    assert!(error.contains("--tls-ca"), "{error}");
    assert!(
        matches!(remote.pool().workers()[0].health, Health::Untrusted { .. }),
        "{:?}",
        remote.pool().workers()
    );

    // The same from the command line, another CA given: exit 1, the reason in words.
    let dir = tempfile::tempdir().unwrap();
    let other = Pki::new();
    let (code, stderr) = calibrate_cli(
        dir.path(),
        &worker.url(),
        &["--tls-ca", other.ca.to_str().unwrap()],
    );
    assert_eq!(code, Some(1), "{stderr}");
    assert!(stderr.contains("error: no worker can be used"), "{stderr}");
    assert!(
        stderr.contains("TLS handshake failed: invalid peer certificate"),
        "{stderr}"
    );
    assert!(!stderr.contains("Status {"), "{stderr}");
    assert_eq!(worker.simulations(), 0);
}

#[test]
fn a_scheme_that_does_not_match_the_server_says_which_to_dial() {
    let pki = Pki::new();
    let plain = TestWorker::start(1, 64);
    let remote = RemoteWorkers::connect(dispatch_config(
        &[plain.url().replace("http://", "https://")],
        pki.client(None),
    ))
    .unwrap();
    let error = remote
        .wait_for_worker(Duration::from_secs(30), |_| {})
        .expect_err("a plain server does not speak TLS");
    assert!(
        error.contains("A server without --tls-cert is dialed http://"),
        "{error}"
    );

    let secure = secure_worker(&pki, None);
    let mut config = dispatch_config(
        &[secure.url().replace("https://", "http://")],
        pki.client(None),
    );
    // Long enough for a probe to come back even on a loaded machine.
    config.wait_for_workers = Duration::from_secs(5);
    let remote = RemoteWorkers::connect(config).unwrap();
    let error = remote
        .wait_for_worker(Duration::from_secs(5), |_| {})
        .expect_err("a TLS server does not speak plain HTTP/2");
    assert!(error.contains("dial it with https://"), "{error}");
}

#[test]
fn a_wrong_token_stops_the_campaign_and_the_right_one_is_never_logged() {
    let pki = Pki::new();
    let worker = secure_worker(&pki, Some(TOKEN));
    let dir = tempfile::tempdir().unwrap();
    let ca = pki.ca.to_str().unwrap().to_string();

    let wrong = pki.file("wrong-token", "not-the-cluster-token\n");
    let (code, stderr) = calibrate_cli(
        dir.path(),
        &worker.url(),
        &["--tls-ca", &ca, "--token-file", wrong.to_str().unwrap()],
    );
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("the token was refused (UNAUTHENTICATED"),
        "{stderr}"
    );
    assert!(!stderr.contains("not-the-cluster-token"), "{stderr}");
    assert_eq!(worker.simulations(), 0, "a refused token is never scored");

    let (code, stderr) = calibrate_cli(dir.path(), &worker.url(), &["--tls-ca", &ca]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains("the token was refused (UNAUTHENTICATED"),
        "{stderr}"
    );

    // The right token, every log line on: the campaign runs, the token shows nowhere.
    let right = pki.file("token", &format!("{TOKEN}\n"));
    let (code, stderr) = calibrate_cli(
        dir.path(),
        &worker.url(),
        &[
            "--tls-ca",
            &ca,
            "--token-file",
            right.to_str().unwrap(),
            "--log",
            "trace",
        ],
    );
    assert_eq!(
        code,
        Some(0),
        "{}",
        &stderr[stderr.len().saturating_sub(4000)..]
    );
    assert!(worker.simulations() > 0);
    assert!(stderr.contains("worker up"), "the log was captured");
    assert!(!stderr.contains(TOKEN), "the token is in the log");
}

#[test]
fn the_token_is_not_in_the_debug_output_of_any_configuration() {
    let pki = Pki::new();
    let mut worker = calib_worker::service::WorkerConfig::new("127.0.0.1:0".parse().unwrap());
    worker.security = pki.server(Some(TOKEN));
    worker.register_security = pki.client(Some(TOKEN));
    let dispatch = dispatch_config(&[], pki.client(Some(TOKEN)));
    let mut coordinator =
        calib_service::server::CoordinatorConfig::new("127.0.0.1:0".parse().unwrap(), dispatch);
    coordinator.security = pki.server(Some(TOKEN));
    let key = std::fs::read_to_string(&pki.key).unwrap();
    let key_body = key.lines().nth(1).unwrap();
    for shown in [format!("{worker:?}"), format!("{coordinator:?}")] {
        assert!(!shown.contains(TOKEN), "{shown}");
        assert!(!shown.contains(key_body), "{shown}");
        assert!(shown.contains("redacted"), "{shown}");
        assert!(shown.contains("server.pem"), "{shown}");
    }
}

#[test]
fn a_worker_registering_with_a_tls_coordinator_serves_it() {
    let pki = Pki::new();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let coordinator = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let mut dispatch = dispatch_config(&[], pki.client(Some(TOKEN)));
        dispatch.probe_interval = Duration::from_millis(100);
        let mut config =
            calib_service::server::CoordinatorConfig::new("127.0.0.1:0".parse().unwrap(), dispatch);
        config.security = pki.server(Some(TOKEN));
        calib_service::server::serve_coordinator(listener, config).unwrap()
    });
    let registry = format!("https://{}", coordinator.address());
    let (server, client) = (pki.server(Some(TOKEN)), pki.client(Some(TOKEN)));
    let worker = TestWorker::start_with(move |config| {
        config.slots = 1;
        config.security = server;
        config.register_security = client;
        config.register = Some(registry);
    });
    let url = worker.url();
    assert!(url.starts_with("https://"), "{url}");
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
    let result = calibrate(&campaign(dir.path(), 30), evaluator, &Silent).unwrap();
    assert!(result.stats.simulated > 0);
    assert_eq!(worker.simulations(), result.stats.simulated);
}

#[test]
fn a_worker_without_the_token_cannot_register() {
    let pki = Pki::new();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    let coordinator = runtime.block_on(async {
        let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
        let mut config = calib_service::server::CoordinatorConfig::new(
            "127.0.0.1:0".parse().unwrap(),
            dispatch_config(&[], pki.client(Some(TOKEN))),
        );
        config.security = pki.server(Some(TOKEN));
        calib_service::server::serve_coordinator(listener, config).unwrap()
    });
    let registry = format!("https://{}", coordinator.address());
    // Were the registration let in, the pool would find nothing at this address.
    let (_held, refusing) = refusing_address();
    let refused = runtime.block_on(async {
        let security = pki.client(None);
        let channel = security
            .endpoint(&registry, None)
            .unwrap()
            .connect()
            .await
            .unwrap();
        proto::registry_client::RegistryClient::new(security.authorize(channel))
            .register(proto::RegisterRequest {
                protocol_version: calib_proto::PROTOCOL_VERSION,
                address: format!("https://{refusing}"),
            })
            .await
            .expect_err("a registration without the token is refused")
    });
    assert_eq!(refused.code(), tonic::Code::Unauthenticated);
    assert!(coordinator.pool().workers().is_empty());
}

#[test]
fn a_bad_certificate_or_key_file_is_named() {
    let pki = Pki::new();
    let garbage = pki.file("garbage.pem", "not a certificate\n");
    let missing = pki.dir.path().join("missing.pem");
    for (cert, key, named) in [
        (&missing, &pki.key, &missing),
        (&garbage, &pki.key, &garbage),
        (&pki.cert, &garbage, &garbage),
        (&pki.cert, &pki.ca, &pki.ca),
    ] {
        let error = ServerTls::load(cert, key).expect_err("unusable");
        let text = error.to_string();
        assert!(text.contains(named.to_str().unwrap()), "{text}");
    }
    // From the command line: the file in the message, exit 2.
    let out = calib(&[
        "worker",
        "--listen",
        "127.0.0.1:0",
        "--tls-cert",
        garbage.to_str().unwrap(),
        "--tls-key",
        pki.key.to_str().unwrap(),
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains(garbage.to_str().unwrap()), "{stderr}");
}

/// Trials of [`a_tls_coordinator_outlives_its_workers`].
const WORKER_EXITS: usize = 50;

/// A TLS coordinator whose TLS workers each finish a campaign and are then stopped with
/// SIGTERM: the coordinator keeps serving through every one of their exits. (It used to
/// die of SIGPIPE, without a word, when it wrote to a worker whose connection had closed.)
#[test]
fn a_tls_coordinator_outlives_its_workers() {
    let pki = Pki::new();
    let dir = tempfile::tempdir().unwrap();
    let (ca, cert, key) = (
        pki.ca.to_str().unwrap(),
        pki.cert.to_str().unwrap(),
        pki.key.to_str().unwrap(),
    );
    let coordinator_log = dir.path().join("coordinator.log");
    let (mut coordinator, address) = spawn_server(
        &[
            "coordinator",
            "--listen",
            "127.0.0.1:0",
            "--tls-cert",
            cert,
            "--tls-key",
            key,
            "--tls-ca",
            ca,
        ],
        "coordinator listening on ",
        &coordinator_log,
    );
    let url = format!("https://{address}");
    for trial in 0..WORKER_EXITS {
        let (mut worker, _) = spawn_server(
            &[
                "worker",
                "--listen",
                "127.0.0.1:0",
                "--slots",
                "1",
                "--register",
                &url,
                "--tls-cert",
                cert,
                "--tls-key",
                key,
                "--tls-ca",
                ca,
            ],
            "worker listening on ",
            &dir.path().join(format!("worker{trial}.log")),
        );
        // A new campaign each time (the seed changes its points), so the worker simulates.
        let search = format!(
            "methods = [\"differential-evolution\"]\nstarts = 1\nmax_evaluations = 40\nseed = {trial}"
        );
        let campaign = write(
            dir.path(),
            "tls.toml",
            &clean_campaign(&search).replace("name = \"clean\"", &format!("name = \"tls{trial}\"")),
        );
        let out = dir.path().join("out");
        let submitted = calib(&[
            "submit",
            campaign.to_str().unwrap(),
            "--coordinator",
            &url,
            "--tls-ca",
            ca,
            "--out",
            out.to_str().unwrap(),
            "--json",
        ]);
        assert!(
            submitted.status.success(),
            "trial {trial}: {}",
            String::from_utf8_lossy(&submitted.stderr)
        );
        // SAFETY: a signal to a child process of this test.
        unsafe { libc::kill(worker.id() as i32, libc::SIGTERM) };
        worker.wait().unwrap();
        let health = calib(&["health", &url, "--tls-ca", ca]);
        let exited = coordinator.try_wait().unwrap();
        assert!(
            exited.is_none() && health.status.success(),
            "trial {trial}: the coordinator {exited:?} after its worker stopped; \
             health said {}; its log: {}",
            String::from_utf8_lossy(&health.stderr),
            std::fs::read_to_string(&coordinator_log).unwrap()
        );
    }
    coordinator.kill().unwrap();
    coordinator.wait().unwrap();
}

/// A token file of `text` with permissions `mode`.
fn token_file(dir: &Path, text: &str, mode: u32) -> String {
    use std::os::unix::fs::PermissionsExt;
    let path = write(dir, "token", text);
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
    path.to_str().unwrap().to_string()
}

#[test]
fn no_client_sends_the_token_over_plain_http_to_another_machine() {
    let dir = tempfile::tempdir().unwrap();
    let token = token_file(dir.path(), &format!("{TOKEN}\n"), 0o600);
    // 192.0.2.0/24 is set aside for documentation: nothing is ever dialed there, the
    // refusal comes first.
    let remote = "http://192.0.2.7:50050";
    let campaign = repo().join("examples/furuta.toml");
    let campaign = campaign.to_str().unwrap();
    for args in [
        vec!["status", "--coordinator", remote],
        vec!["submit", campaign, "--coordinator", remote],
        vec!["worker", "--listen", "127.0.0.1:0", "--register", remote],
        vec![
            "coordinator",
            "--listen",
            "127.0.0.1:0",
            "--workers",
            remote,
        ],
    ] {
        let mut args = args.clone();
        args.extend(["--token-file", token.as_str()]);
        let out = calib(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains(remote)
                && stderr.contains("clear text")
                && stderr.contains("--allow-plaintext-token"),
            "{args:?}: {stderr}"
        );
        assert!(!stderr.contains(TOKEN), "{stderr}");
    }
}

#[test]
fn a_weak_token_or_a_token_file_others_can_read_is_warned_about() {
    let dir = tempfile::tempdir().unwrap();
    // A port this test holds without listening refuses: the command fails at once, after
    // reading its token.
    let (_held, refusing) = refusing_address();
    let coordinator = format!("http://{refusing}");
    let status = |token: &str| {
        let out = calib(&[
            "status",
            "--coordinator",
            &coordinator,
            "--token-file",
            token,
        ]);
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let stderr = status(&token_file(dir.path(), "x\n", 0o644));
    assert!(stderr.contains("shorter than 16"), "{stderr}");
    assert!(
        stderr.contains("can be read by other users") && stderr.contains("chmod 600"),
        "{stderr}"
    );
    assert!(
        stderr.contains("it can be guessed; make one with"),
        "{stderr}"
    );
    let stderr = status(&token_file(dir.path(), &format!("{TOKEN}\n"), 0o600));
    assert!(
        !stderr.contains("shorter than") && !stderr.contains("other users"),
        "{stderr}"
    );
    // A server reads its token twice (its door, and to dial): each warning once.
    let weak = token_file(dir.path(), "x\n", 0o644);
    let log = dir.path().join("coordinator.log");
    let args = [
        "coordinator",
        "--listen",
        "127.0.0.1:0",
        "--token-file",
        &weak,
    ];
    let (mut coordinator, _) = spawn_server(&args, "coordinator listening on ", &log);
    coordinator.kill().unwrap();
    coordinator.wait().unwrap();
    let stderr = std::fs::read_to_string(&log).unwrap();
    assert_eq!(stderr.matches("shorter than 16").count(), 1, "{stderr}");
    assert_eq!(
        stderr.matches("can be read by other users").count(),
        1,
        "{stderr}"
    );
}
