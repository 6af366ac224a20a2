//! A client in another language: Python's grpcio, with stubs generated from `proto/`,
//! calls a worker. Skipped (with the reason printed) where python3 or grpcio is missing,
//! except under `CI=true`, where that fails the test.

mod common;

use common::cluster::TestWorker;
use common::repo;
use std::process::Command;

/// Why the Python side cannot run here, if it cannot.
fn python_missing() -> Option<String> {
    match Command::new("python3")
        .args(["-c", "import grpc, grpc_tools"])
        .output()
    {
        Err(e) => Some(format!("python3 cannot run: {e}")),
        Ok(out) if !out.status.success() => Some(format!(
            "grpcio or grpcio-tools missing (pip install grpcio grpcio-tools): {}",
            String::from_utf8_lossy(&out.stderr).trim()
        )),
        Ok(_) => None,
    }
}

#[test]
fn a_python_client_lists_models_and_simulates() {
    if let Some(reason) = python_missing() {
        common::skip(&reason);
        return;
    }
    let stubs = tempfile::tempdir().unwrap();
    let out = Command::new("python3")
        .args(["-m", "grpc_tools.protoc", "-I"])
        .arg(repo().join("proto"))
        .arg(format!("--python_out={}", stubs.path().display()))
        .arg(format!("--grpc_python_out={}", stubs.path().display()))
        .arg(repo().join("proto/calib/v1/simulator.proto"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "protoc: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let worker = TestWorker::start(1, 16);
    let out = Command::new("python3")
        .arg(repo().join("tests/python/simulator_client.py"))
        .arg(worker.address().to_string())
        .arg(stubs.path())
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    println!("{stdout}");
    assert!(
        out.status.success(),
        "python client failed:\n{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.trim_end().ends_with("ok"));
    assert_eq!(worker.simulations(), 1);
}
