//! What `calib calibrate --workers` says when workers are missing or misnamed, and where
//! it writes its results.

use crate::common::*;
use std::path::Path;

fn small_campaign(dir: &Path) -> std::path::PathBuf {
    write(
        dir,
        "clean.toml",
        &clean_campaign("methods = [\"nelder-mead\"]\nmax_evaluations = 30"),
    )
}

fn calibrate_on(campaign: &Path, extra: &[&str]) -> (Option<i32>, String) {
    let db = campaign.parent().unwrap().join("db");
    let mut args = vec![
        "calibrate",
        campaign.to_str().unwrap(),
        "--db",
        db.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let out = calib(&args);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn a_worker_address_where_nothing_listens_fails_at_once_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = small_campaign(dir.path());
    // A port this test holds without listening: refused for as long as `_held` lives,
    // whatever else runs on the machine (a port bound and let go may be taken meanwhile).
    let (_held, refusing) = refusing_address();
    let url = format!("http://{refusing}");
    // The default wait is 300 s: a refused connection ends it long before.
    let (code, stderr) = calibrate_on(&campaign, &["--workers", &url]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "workers: waiting up to 300 s for a worker: 0 of 1 up; {url}"
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!(
            "error: no worker is listening: 0 of 1 up; {url} down: connection refused"
        )),
        "{stderr}"
    );
    assert!(!stderr.contains("Down {"), "{stderr}");
}

#[test]
fn a_worker_that_never_answers_is_waited_for_then_named() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = small_campaign(dir.path());
    // Accepts connections (the kernel does) and never answers.
    let silent = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let url = format!("http://{}", silent.local_addr().unwrap());
    let (code, stderr) = calibrate_on(&campaign, &["--workers", &url, "--wait-for-workers", "1"]);
    assert_eq!(code, Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!(
            "workers: waiting up to 1 s for a worker: 0 of 1 up; {url} joining"
        )),
        "{stderr}"
    );
    assert!(
        stderr.contains(&format!("error: no worker up after 1 s: 0 of 1 up; {url}")),
        "{stderr}"
    );
    assert!(!stderr.contains("Down {"), "{stderr}");
}

#[test]
fn an_unbounded_deadline_or_wait_is_refused_as_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = small_campaign(dir.path());
    let (_held, refusing) = refusing_address();
    let workers = format!("http://{refusing}");
    for option in ["--deadline", "--wait-for-workers"] {
        for value in ["inf", "0", "-3"] {
            let (code, stderr) = calibrate_on(
                &campaign,
                &["--workers", &workers, &format!("{option}={value}")],
            );
            assert_eq!(code, Some(2), "{option} {value}: {stderr}");
            assert!(stderr.contains(option), "{stderr}");
            assert!(
                stderr.contains("finite number of seconds above 0"),
                "{stderr}"
            );
            assert!(!stderr.contains("panicked"), "{stderr}");
        }
    }
}

#[test]
fn out_is_a_results_root_with_one_folder_per_campaign() {
    let dir = tempfile::tempdir().unwrap();
    let campaign = small_campaign(dir.path());
    let out = dir.path().join("all-results");
    let (code, stderr) = calibrate_on(&campaign, &["--out", out.to_str().unwrap()]);
    assert_eq!(code, Some(0), "{stderr}");
    // As `calib coordinator --out` writes the campaigns it resumes.
    let result: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("clean").join("result.json")).unwrap())
            .unwrap();
    assert!(result["best"]["objective"].as_f64().unwrap() >= 0.0);
    assert!(!out.join("result.json").exists());
}
