//! The web app's door: requests from other web pages and under other Host names are
//! refused (403) while the page and its own calls keep working; a coordinator with a token
//! serves the app behind its login (401 without the token, the session cookie after
//! `/login`); concurrent uploads of one file all succeed with one intact dataset; an FMU
//! upload passes the same door, and the uploaded FMU simulates on the Model tab's route
//! (on a coordinator only behind its token).

use crate::reference_fmus;

use calib_service::server::{serve_coordinator, CoordinatorConfig, RunningCoordinator};
use calib_service::web::local::{start_ui, RunningUi, UiConfig};
use std::io::{Read, Write};
use std::net::SocketAddr;
use std::path::Path;

const TOKEN: &str = "a-token-of-32-characters-or-more!";

fn runtime() -> tokio::runtime::Runtime {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap()
}

/// An answer: status code, head (lowercase header names) and body.
struct Answer {
    code: u16,
    head: String,
    body: String,
}

impl Answer {
    fn header(&self, name: &str) -> Option<&str> {
        self.head.lines().find_map(|line| {
            let (n, v) = line.split_once(':')?;
            n.eq_ignore_ascii_case(name).then(|| v.trim())
        })
    }
}

/// One HTTP/1.1 request to `address` with `headers` (a `Host` of the address unless one
/// is given).
fn request(
    address: SocketAddr,
    method: &str,
    path: &str,
    headers: &[(&str, &str)],
    body: &[u8],
) -> Answer {
    let mut stream = std::net::TcpStream::connect(address).unwrap();
    let mut head = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\n");
    if !headers.iter().any(|(n, _)| n.eq_ignore_ascii_case("host")) {
        head.push_str(&format!("Host: {address}\r\n"));
    }
    for (name, value) in headers {
        head.push_str(&format!("{name}: {value}\r\n"));
    }
    head.push_str(&format!("Content-Length: {}\r\n\r\n", body.len()));
    stream.write_all(head.as_bytes()).unwrap();
    stream.write_all(body).unwrap();
    let mut answer = Vec::new();
    stream.read_to_end(&mut answer).unwrap();
    let answer = String::from_utf8_lossy(&answer).into_owned();
    let (head, body) = answer.split_once("\r\n\r\n").unwrap();
    let code = head.split_whitespace().nth(1).unwrap().parse().unwrap();
    Answer {
        code,
        head: head.to_string(),
        body: body.to_string(),
    }
}

fn ui(runtime: &tokio::runtime::Runtime, dir: &Path, allow_hosts: &[&str]) -> RunningUi {
    runtime
        .block_on(start_ui(UiConfig {
            listen: "127.0.0.1:0".parse().unwrap(),
            store: dir.join("db"),
            api: Some(dir.join("api")),
            allow_hosts: allow_hosts.iter().map(|h| h.to_string()).collect(),
        }))
        .unwrap()
}

const CSV: &[u8] = b"time,x\n0,1\n1,2\n2,3\n";

#[test]
fn other_web_pages_and_other_host_names_are_refused_and_the_page_works() {
    let dir = tempfile::tempdir().unwrap();
    let runtime = runtime();
    let ui = ui(&runtime, dir.path(), &["calib.lab"]);
    let web = ui.address();
    let own = format!("http://{web}");
    let evil = [
        ("Origin", "http://evil.example"),
        ("Content-Type", "text/plain"),
    ];

    // The page and its own calls.
    let page = request(web, "GET", "/", &[], b"");
    assert_eq!(page.code, 200);
    assert!(page.body.contains("<title>calib</title>"));
    assert_eq!(request(web, "GET", "/js/main.js", &[], b"").code, 200);
    let same = [
        ("Origin", own.as_str()),
        ("Sec-Fetch-Site", "same-origin"),
        ("Content-Type", "application/json"),
    ];
    let listed = request(web, "POST", "/api/v1/ListCampaigns", &same, b"{}");
    assert_eq!(listed.code, 200, "{}", listed.body);
    // A program (curl, the Python client) sends neither Origin nor Sec-Fetch-Site.
    assert_eq!(
        request(web, "POST", "/api/v1/ListCampaigns", &[], b"{}").code,
        200
    );

    // A cross-origin "simple" request (no preflight) to every state-changing route.
    for (path, body) in [
        (
            "/api/v1/UploadDataset?file_name=rig.csv&time_column=time",
            CSV,
        ),
        ("/api/v1/SubmitCampaign", b"{}".as_slice()),
        ("/api/v1/CancelCampaign", b"{\"id\":\"x\"}".as_slice()),
        ("/login", b"".as_slice()),
    ] {
        let refused = request(web, "POST", path, &evil, body);
        assert_eq!(refused.code, 403, "{path}: {}", refused.body);
        assert!(
            refused.body.contains("other web pages") && refused.body.contains("evil.example"),
            "{path}: {}",
            refused.body
        );
    }
    let datasets = dir.path().join("api/datasets");
    assert_eq!(
        std::fs::read_dir(&datasets).unwrap().count(),
        0,
        "nothing was uploaded"
    );
    // What the browser says of a request another site sent, without an Origin (a GET).
    let refused = request(
        web,
        "GET",
        "/api/v1/WatchCampaign/x",
        &[("Sec-Fetch-Site", "cross-site")],
        b"",
    );
    assert_eq!(refused.code, 403, "{}", refused.body);
    for origin in ["null", "http://127.0.0.1:1", "file://"] {
        let refused = request(
            web,
            "POST",
            "/api/v1/ListCampaigns",
            &[("Origin", origin)],
            b"{}",
        );
        assert_eq!(refused.code, 403, "{origin}: {}", refused.body);
    }

    // DNS rebinding: a name that resolves here but is not this server's.
    let port = web.port();
    for host in [
        format!("evil.example:{port}"),
        format!("127.0.0.1.nip.io:{port}"),
    ] {
        for (method, path) in [("GET", "/"), ("POST", "/api/v1/ListCampaigns")] {
            let refused = request(web, method, path, &[("Host", &host)], b"{}");
            assert_eq!(refused.code, 403, "{host} {path}");
            assert!(
                refused.body.contains("--allow-host") && refused.body.contains(&host),
                "{}",
                refused.body
            );
        }
    }
    // The names it answers as.
    for host in [
        format!("localhost:{port}"),
        format!("[::1]:{port}"),
        "calib.lab".to_string(),
    ] {
        let origin = format!("http://{host}");
        let answer = request(
            web,
            "POST",
            "/api/v1/ListCampaigns",
            &[("Host", &host), ("Origin", &origin)],
            b"{}",
        );
        assert_eq!(answer.code, 200, "{host}: {}", answer.body);
    }
    runtime.block_on(ui.shutdown());
}

struct Coordinator {
    runtime: tokio::runtime::Runtime,
    server: Option<RunningCoordinator>,
}

impl Coordinator {
    fn start(dir: &Path, token: Option<&str>) -> Self {
        let mut config = CoordinatorConfig::new(
            "127.0.0.1:0".parse().unwrap(),
            calib_sandbox::cluster::dispatch_config(&[]),
        );
        config.api = Some(dir.join("api"));
        config.http = Some("127.0.0.1:0".parse().unwrap());
        config.security.token = token.map(|t| calib_security::Token::new(t).unwrap());
        let runtime = runtime();
        let server = runtime.block_on(async {
            let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
            serve_coordinator(listener, config).unwrap()
        });
        Self {
            runtime,
            server: Some(server),
        }
    }

    fn http(&self) -> SocketAddr {
        self.server.as_ref().unwrap().http_address().unwrap()
    }
}

impl Drop for Coordinator {
    fn drop(&mut self) {
        if let Some(server) = self.server.take() {
            self.runtime.block_on(server.shutdown());
        }
    }
}

#[test]
fn a_coordinator_with_a_token_serves_the_web_app_behind_its_login() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), Some(TOKEN));
    let web = c.http();
    let right = format!("Bearer {TOKEN}");

    // The page and the login need no token.
    assert_eq!(request(web, "GET", "/", &[], b"").code, 200);
    assert_eq!(request(web, "GET", "/app.css", &[], b"").code, 200);
    let state = request(web, "GET", "/login", &[], b"");
    assert_eq!(state.code, 200);
    assert_eq!(
        serde_json::from_str::<serde_json::Value>(&state.body).unwrap(),
        serde_json::json!({ "required": true, "signed_in": false })
    );

    // Every API and drawing route requires it.
    for (method, path) in [
        ("POST", "/api/v1/ListCampaigns"),
        ("POST", "/api/v1/ListModels"),
        (
            "POST",
            "/api/v1/UploadDataset?file_name=rig.csv&time_column=time",
        ),
        ("GET", "/api/v1/WatchCampaign/x"),
        ("POST", "/ui/plot"),
        ("GET", "/ui/campaigns/x/campaign.toml"),
    ] {
        // Wrong tokens on the first route only: each counts against this address.
        let wrong = [Some("Bearer wrong"), Some(TOKEN.get(1..).unwrap())];
        let tried = if path.contains("ListCampaigns") {
            &wrong[..]
        } else {
            &[]
        };
        for authorization in std::iter::once(None).chain(tried.iter().copied()) {
            let headers: Vec<(&str, &str)> = authorization
                .map(|a| ("Authorization", a))
                .into_iter()
                .collect();
            let refused = request(web, method, path, &headers, CSV);
            assert_eq!(refused.code, 401, "{path} with {authorization:?}");
            assert_eq!(refused.header("www-authenticate"), Some("Bearer"));
            assert!(refused.body.contains("token"), "{}", refused.body);
        }
    }
    assert_eq!(
        std::fs::read_dir(dir.path().join("api/datasets"))
            .unwrap()
            .count(),
        0
    );

    // The token as the gRPC clients present it.
    let listed = request(
        web,
        "POST",
        "/api/v1/ListCampaigns",
        &[("Authorization", &right)],
        b"{}",
    );
    assert_eq!(listed.code, 200, "{}", listed.body);
    // ... but not from another page, token or not.
    let refused = request(
        web,
        "POST",
        "/api/v1/ListCampaigns",
        &[("Authorization", &right), ("Origin", "http://evil.example")],
        b"{}",
    );
    assert_eq!(refused.code, 403);

    // The login: a wrong token gets no cookie; the right one a session cookie that is not
    // the token, and that every route then accepts.
    let wrong = request(
        web,
        "POST",
        "/login",
        &[("Authorization", "Bearer wrong")],
        b"",
    );
    assert_eq!(wrong.code, 401);
    assert_eq!(wrong.header("set-cookie"), None);
    let login = request(web, "POST", "/login", &[("Authorization", &right)], b"");
    assert_eq!(login.code, 204, "{}", login.body);
    let cookie = login.header("set-cookie").expect("a session cookie");
    assert!(
        cookie.contains("HttpOnly") && cookie.contains("SameSite=Strict"),
        "{cookie}"
    );
    assert!(!cookie.contains(TOKEN), "the cookie is not the token");
    let session = cookie.split(';').next().unwrap().to_string();
    let uploaded = request(
        web,
        "POST",
        "/api/v1/UploadDataset?file_name=rig.csv&time_column=time",
        &[("Cookie", &session)],
        CSV,
    );
    assert_eq!(uploaded.code, 200, "{}", uploaded.body);
    let id = serde_json::from_str::<serde_json::Value>(&uploaded.body).unwrap()["id"]
        .as_str()
        .unwrap()
        .to_string();
    let plot = request(
        web,
        "GET",
        &format!("/ui/datasets/{id}/plot/x"),
        &[("Cookie", &session)],
        b"",
    );
    assert_eq!(plot.code, 200, "{}", plot.body);
    assert!(plot.body.contains("<svg"));
    let state = request(web, "GET", "/login", &[("Cookie", &session)], b"");
    assert!(state.body.contains("\"signed_in\":true"), "{}", state.body);
    let (name, value) = session.split_once('=').unwrap();
    let forged = format!("{name}={}", "0".repeat(value.len()));
    let refused = request(
        web,
        "POST",
        "/api/v1/ListCampaigns",
        &[("Cookie", &forged)],
        b"{}",
    );
    assert_eq!(refused.code, 401);
}

/// A login's session cookie (`name=value`).
fn log_in(web: SocketAddr, headers: &[(&str, &str)]) -> String {
    let right = format!("Bearer {TOKEN}");
    let mut all = vec![("Authorization", right.as_str())];
    all.extend_from_slice(headers);
    let login = request(web, "POST", "/login", &all, b"");
    assert_eq!(login.code, 204, "{}", login.body);
    let cookie = login.header("set-cookie").expect("a session cookie");
    cookie.split(';').next().unwrap().to_string()
}

#[test]
fn each_login_is_a_session_that_logout_ends_and_wrong_tokens_are_throttled() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), Some(TOKEN));
    let web = c.http();
    let list = |headers: &[(&str, &str)]| {
        request(web, "POST", "/api/v1/ListCampaigns", headers, b"{}").code
    };

    // Two logins, two sessions: ending one leaves the other.
    let (one, two) = (log_in(web, &[]), log_in(web, &[]));
    assert_ne!(one, two);
    assert_eq!(
        (list(&[("Cookie", &one)]), list(&[("Cookie", &two)])),
        (200, 200)
    );
    let out = request(web, "POST", "/logout", &[("Cookie", &one)], b"");
    assert_eq!(out.code, 204);
    assert!(out.header("set-cookie").unwrap().contains("Max-Age=0"));
    assert_eq!(list(&[("Cookie", &one)]), 401, "the old cookie is revoked");
    assert_eq!(list(&[("Cookie", &two)]), 200);

    // The cookie lasts 12 hours; `Secure` when the page came over HTTPS through a proxy.
    let right = format!("Bearer {TOKEN}");
    let plain = request(web, "POST", "/login", &[("Authorization", &right)], b"");
    let plain = plain.header("set-cookie").unwrap().to_string();
    assert!(
        plain.contains("Max-Age=43200") && !plain.contains("Secure"),
        "{plain}"
    );
    let proxied = request(
        web,
        "POST",
        "/login",
        &[("Authorization", &right), ("X-Forwarded-Proto", "https")],
        b"",
    );
    assert!(proxied.header("set-cookie").unwrap().contains("; Secure"));

    // Wrong tokens: four cost nothing, the fifth closes this address for 1 s, during
    // which even the right token is refused unread; the next wrong one closes it for 2 s.
    let wrong = |path: &str| {
        let headers = [("Authorization", "Bearer wrong-wrong-wrong")];
        request(web, "POST", path, &headers, b"{}")
    };
    for path in [
        "/login",
        "/api/v1/ListCampaigns",
        "/login",
        "/login",
        "/login",
    ] {
        assert_eq!(wrong(path).code, 401);
    }
    for path in ["/login", "/api/v1/ListCampaigns"] {
        let closed = request(web, "POST", path, &[("Authorization", &right)], b"{}");
        assert_eq!(closed.code, 429, "{}", closed.body);
        assert_eq!(closed.header("retry-after"), Some("1"));
        assert!(
            closed.body.contains("too many wrong tokens"),
            "{}",
            closed.body
        );
    }
    assert_eq!(
        list(&[("Cookie", &two)]),
        200,
        "a session is not a token: it passes"
    );
    std::thread::sleep(std::time::Duration::from_millis(1100));
    assert_eq!(wrong("/login").code, 401);
    let closed = wrong("/login");
    assert_eq!(
        (closed.code, closed.header("retry-after")),
        (429, Some("2"))
    );
    std::thread::sleep(std::time::Duration::from_millis(2100));
    // The right token opens the address again.
    let three = log_in(web, &[]);
    for _ in 0..4 {
        assert_eq!(wrong("/login").code, 401, "counted afresh");
    }
    assert_eq!(list(&[("Cookie", &three)]), 200);
}

#[test]
fn an_fmu_upload_passes_the_door_and_the_fmu_simulates_through_the_web_routes() {
    let Some(fmus) = reference_fmus::reference_fmus() else {
        return;
    };
    let fmu = std::fs::read(fmus.join("fmi2/BouncingBall.fmu")).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), Some(TOKEN));
    let web = c.http();
    let right = format!("Bearer {TOKEN}");
    let path = "/api/v1/UploadFmu?file_name=BouncingBall.fmu";
    for headers in [
        vec![],
        vec![("Authorization", "Bearer wrong")],
        vec![
            ("Authorization", right.as_str()),
            ("Origin", "http://evil.example"),
        ],
        vec![("Authorization", right.as_str()), ("Host", "evil.example")],
    ] {
        let refused = request(web, "POST", path, &headers, &fmu);
        assert!(
            [401, 403].contains(&refused.code),
            "{headers:?}: {} {}",
            refused.code,
            refused.body
        );
    }
    let kept = || {
        std::fs::read_dir(dir.path().join("api/fmus"))
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .path()
                    .extension()
                    .is_some_and(|x| x == "fmu")
            })
            .count()
    };
    assert_eq!(kept(), 0, "nothing was kept");

    let uploaded = request(web, "POST", path, &[("Authorization", &right)], &fmu);
    assert_eq!(uploaded.code, 200, "{}", uploaded.body);
    let answer: serde_json::Value = serde_json::from_str(&uploaded.body).unwrap();
    let id = answer["id"].as_str().unwrap();
    assert_eq!(kept(), 1);
    let model = answer["models"][0]["name"].as_str().unwrap();
    assert!(model.starts_with("BouncingBall.me@"), "{answer}");
    // A JSON body that is not an FMU is refused as one.
    let refused = request(web, "POST", path, &[("Authorization", &right)], b"{}");
    assert_eq!(refused.code, 400, "{}", refused.body);
    assert!(refused.body.contains("fmu: "), "{}", refused.body);

    // The Model tab's simulation of it: free fall from h = 1 m until the first bounce.
    let hash: Vec<u8> = (0..32)
        .map(|i| u8::from_str_radix(&id[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    let simulate = serde_json::json!({
        "protocol_version": 1,
        "model": model,
        "fmu_hash": hash,
        "times": [0.0, 0.1, 0.2, 0.3],
        "outputs": ["h"],
    });
    let simulated = request(
        web,
        "POST",
        "/api/v1/Simulate",
        &[("Authorization", &right)],
        simulate.to_string().as_bytes(),
    );
    assert_eq!(simulated.code, 200, "{}", simulated.body);
    let answer: serde_json::Value = serde_json::from_str(&simulated.body).unwrap();
    let h = answer["series"][0]["values"].as_array().unwrap();
    for (i, t) in [0.0, 0.1, 0.2, 0.3].iter().enumerate() {
        let expected = 1.0 - 0.5 * 9.81 * t * t;
        let value = h[i].as_f64().unwrap();
        assert!((value - expected).abs() < 1e-6, "h({t}) = {value}");
    }
}

#[test]
fn a_coordinator_without_a_token_asks_no_login() {
    let dir = tempfile::tempdir().unwrap();
    let c = Coordinator::start(dir.path(), None);
    let web = c.http();
    let state = request(web, "GET", "/login", &[], b"");
    assert!(state.body.contains("\"required\":false"), "{}", state.body);
    let listed = request(web, "POST", "/api/v1/ListCampaigns", &[], b"{}");
    assert_eq!(listed.code, 200, "{}", listed.body);
    // Anyone may reach it: the Model tab runs no FMU code here.
    let simulate = serde_json::json!({
        "protocol_version": 1,
        "model": "BouncingBall.me@000000000000",
        "fmu_hash": vec![0u8; 32],
        "times": [0.0, 0.1],
        "outputs": ["h"],
    });
    let refused = request(
        web,
        "POST",
        "/api/v1/Simulate",
        &[],
        simulate.to_string().as_bytes(),
    );
    assert_eq!(refused.code, 403, "{}", refused.body);
    assert!(refused.body.contains("--token-file"), "{}", refused.body);
}

#[test]
fn concurrent_uploads_of_one_file_all_succeed_with_one_intact_dataset() {
    let dir = tempfile::tempdir().unwrap();
    let runtime = runtime();
    let ui = ui(&runtime, dir.path(), &[]);
    let web = ui.address();
    for round in 0..6 {
        // Another file each round, so that every round writes.
        let csv: Vec<u8> = std::iter::once("time,x,y\n".to_string())
            .chain((0..40_000).map(|i| format!("{i},{},{round}\n", i * 7 % 13)))
            .collect::<String>()
            .into_bytes();
        let together = std::sync::Barrier::new(16);
        let answers: Vec<Answer> = std::thread::scope(|scope| {
            let uploads: Vec<_> = (0..16)
                .map(|_| {
                    scope.spawn(|| {
                        together.wait();
                        request(
                            web,
                            "POST",
                            "/api/v1/UploadDataset?file_name=rig.csv&time_column=time",
                            &[],
                            &csv,
                        )
                    })
                })
                .collect();
            uploads.into_iter().map(|u| u.join().unwrap()).collect()
        });
        let mut ids = Vec::new();
        for answer in &answers {
            assert_eq!(answer.code, 200, "round {round}: {}", answer.body);
            let info: serde_json::Value = serde_json::from_str(&answer.body).unwrap();
            ids.push(info["id"].as_str().unwrap().to_string());
        }
        ids.dedup();
        assert_eq!(ids.len(), 1, "round {round}: one id, {ids:?}");
        let kept = std::fs::read(dir.path().join(format!("api/datasets/{}.csv", ids[0]))).unwrap();
        assert_eq!(kept, csv, "round {round}: the file as uploaded");
        let record: serde_json::Value = serde_json::from_slice(
            &std::fs::read(dir.path().join(format!("api/datasets/{}.json", ids[0]))).unwrap(),
        )
        .unwrap();
        assert_eq!(record["samples"], 40_000);
    }
    let names: Vec<String> = std::fs::read_dir(dir.path().join("api/datasets"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names.len(), 12, "a file and a record per round: {names:?}");
    runtime.block_on(ui.shutdown());
}
