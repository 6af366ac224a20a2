//! The web app in a real browser: `calib ui` drives headless Chromium through selenium
//! (`tests/python/web_ui.py`). The whole workflow on the Furuta record gives the values
//! `calib calibrate examples/furuta.toml` gives, read off the page, and leaves a screenshot
//! of each tab (in `docs/screenshots/` with `CALIB_SCREENSHOTS=docs/screenshots`); a CSV that does not parse shows the parser's message;
//! on `calib coordinator --http --token-file`, the page asks for the token, then works; an
//! FMU uploaded on the Model tab is simulated there and calibrated on the Calibration tab.
//! Skipped (with the reason printed) where Chromium, chromedriver or selenium is missing,
//! except under continuous integration (`CI` set), where that fails the test.

mod compare;
mod discovery;
mod experiments;
mod fmu;
mod forms;
mod login;
mod reload;
mod workflow;

use crate::reference_fmus;

use crate::common;
use crate::common::repo;
use serde_json::Value;
use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, Command, Stdio};

/// Why a browser cannot be driven here, if it cannot.
fn browser_missing() -> Option<String> {
    let found = |name: &str| {
        std::env::var_os("PATH")
            .is_some_and(|path| std::env::split_paths(&path).any(|dir| dir.join(name).is_file()))
    };
    if !["chromium", "chromium-browser", "google-chrome"]
        .iter()
        .any(|b| found(b))
    {
        return Some("no chromium on the PATH (apt-get install chromium)".into());
    }
    if !found("chromedriver") {
        return Some("no chromedriver on the PATH (apt-get install chromium-driver)".into());
    }
    match Command::new("python3")
        .args(["-c", "import selenium"])
        .output()
    {
        Err(e) => Some(format!("python3 cannot run: {e}")),
        Ok(out) if !out.status.success() => Some(format!(
            "selenium missing (pip install selenium): {}",
            String::from_utf8_lossy(&out.stderr).trim()
        )),
        Ok(_) => None,
    }
}

/// `calib ui` serving on a port of its choosing; killed when dropped.
struct Ui {
    child: Child,
    url: String,
}

impl Ui {
    fn start(db: &std::path::Path) -> Ui {
        let mut child = Command::new(env!("CARGO_BIN_EXE_calib"))
            .args(["ui", "--no-open", "--listen", "127.0.0.1:0", "--db"])
            .arg(db)
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .expect("start calib ui");
        let mut first = String::new();
        BufReader::new(child.stdout.take().expect("stdout"))
            .read_line(&mut first)
            .expect("first line");
        let url = first
            .trim()
            .strip_prefix("calib ui at ")
            .unwrap_or_else(|| panic!("first line `{first}` does not say where the app is"))
            .to_string();
        assert!(
            url.starts_with("http://127.0.0.1:") && url.ends_with('/'),
            "{url}"
        );
        Ui { child, url }
    }

    /// `GET path` over plain HTTP/1.1: the status code and the body.
    fn get(&self, path: &str) -> (u16, String) {
        let host = self.url.trim_start_matches("http://").trim_end_matches('/');
        let mut stream = std::net::TcpStream::connect(host).expect("connect");
        write!(
            stream,
            "GET {path} HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut answer = String::new();
        stream.read_to_string(&mut answer).unwrap();
        let (head, body) = answer.split_once("\r\n\r\n").unwrap_or((&answer, ""));
        let code = head
            .split_whitespace()
            .nth(1)
            .and_then(|c| c.parse().ok())
            .unwrap_or(0);
        (code, body.to_string())
    }
}

impl Drop for Ui {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Run the page script in `mode` with `args`; what it read off the page.
fn drive(mode: &str, args: &[&str], dir: &std::path::Path) -> Value {
    let out = dir.join(format!("{mode}.json"));
    let run = Command::new("python3")
        .arg(repo().join("tests/python/web_ui.py"))
        .arg(mode)
        .args(args)
        .arg(&out)
        .output()
        .expect("run python3");
    assert!(
        run.status.success(),
        "web_ui.py {mode} failed:\n{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&std::fs::read(&out).expect("page report")).expect("page report JSON")
}

/// The best value of parameter `name` in `calib calibrate --json`'s output, read from its
/// digits (shortest round-trip, as the page's are) with Rust's correctly rounded parser.
fn best_parameter(json: &str, name: &str) -> f64 {
    let best = &json[json.find("\"best\": {").expect("a best point")..];
    let key = format!("\"{name}\": ");
    let value = &best[best.find(&key).expect("the parameter") + key.len()..];
    let end = value.find([',', '\n', '}']).unwrap();
    value[..end].trim().parse().expect("a number")
}

/// Run `tests/python/web_forms.py` in `mode` with `args`; what it read off the page.
fn drive_forms(mode: &str, args: &[&str], dir: &std::path::Path) -> Value {
    let out = dir.join(format!("{mode}.json"));
    let run = Command::new("python3")
        .arg(repo().join("tests/python/web_forms.py"))
        .arg(mode)
        .args(args)
        .arg(&out)
        .output()
        .expect("run python3");
    assert!(
        run.status.success(),
        "web_forms.py {mode} failed:\n{}\n{}",
        String::from_utf8_lossy(&run.stdout),
        String::from_utf8_lossy(&run.stderr)
    );
    serde_json::from_slice(&std::fs::read(&out).expect("page report")).expect("page report JSON")
}
