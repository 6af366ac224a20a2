//! A coordinator with a token: the page asks for it, then works.

use super::*;

/// `calib coordinator --http` with a token, serving on ports of its choosing; killed when
/// dropped.
struct TokenCoordinator {
    child: Child,
    url: String,
}

impl TokenCoordinator {
    fn start(dir: &std::path::Path, token_file: &std::path::Path) -> Self {
        let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
            .args([
                "coordinator",
                "--listen",
                "127.0.0.1:0",
                "--http",
                "127.0.0.1:0",
                "--token-file",
            ])
            .arg(token_file)
            .arg("--api-dir")
            .arg(dir.join("api"))
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start calib coordinator");
        let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
        let url = loop {
            let line = lines
                .next()
                .expect("the coordinator says where the app is")
                .expect("a line");
            if let Some(url) = line.strip_prefix("calib ui at ") {
                break url.to_string();
            }
        };
        TokenCoordinator { child, url }
    }
}

impl Drop for TokenCoordinator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn the_page_of_a_coordinator_with_a_token_asks_for_it_then_works() {
    if let Some(reason) = browser_missing() {
        common::skip(&reason);
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let token = "a-token-of-32-characters-or-more!";
    let token_file = dir.path().join("token");
    std::fs::write(&token_file, format!("{token}\n")).unwrap();
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&token_file, std::fs::Permissions::from_mode(0o600)).unwrap();
    }
    let coordinator = TokenCoordinator::start(dir.path(), &token_file);
    let data = repo().join("examples/data/furuta_clean.csv");
    let page = drive(
        "login",
        &[
            &coordinator.url,
            token_file.to_str().unwrap(),
            data.to_str().unwrap(),
        ],
        dir.path(),
    );
    assert_eq!(page["tabs_hidden"], true, "{page}");
    assert_eq!(
        page["models_before"], 0,
        "nothing loaded before the login: {page}"
    );
    let wrong = page["wrong"].as_str().unwrap();
    assert!(wrong.contains("token"), "{page}");
    assert_eq!(page["login_hidden"], true, "{page}");
    assert!(page["model_plots"].as_u64().unwrap() >= 1, "{page}");
    assert!(
        page["measurement_status"]
            .as_str()
            .unwrap()
            .contains("samples"),
        "{page}"
    );
    assert!(page["measurement_plots"].as_u64().unwrap() >= 1, "{page}");
    assert_eq!(page["token_visible_to_scripts"], false, "{page}");
    // The session cookie is HttpOnly: scripts see none.
    assert!(
        !page["script_storage"]
            .as_str()
            .unwrap()
            .contains("calib_session"),
        "{page}"
    );
}
