//! What an FMU's code can and cannot do on a worker: the FMU of `tests/escaping_fmu/`
//! (built with the C compiler at test time) starts a process that leaves its session, hangs,
//! writes and reads outside its folders and asks for more memory than it may have. No
//! process of it outlives its host being dropped, its deadline, or the program that ran it;
//! its working folder is private and removed afterwards; where the kernel has Landlock its
//! files are confined. And an archive that lies about a size is refused by `calib models`.

// Its own test program, not a module of `it/`: it sets the FMU deadline in its environment
// and has every FMU of the process run in child processes of the calib binary.
#[allow(dead_code, unused_imports)]
#[path = "it/common/mod.rs"]
mod common;
#[path = "../model/tests/common/zips.rs"]
mod zips;

use calib_model::fmu::{self, contain};
use calib_model::Run;
use calib_model::{Model, SimulationError};
use common::*;
use std::path::PathBuf;
use std::sync::OnceLock;
use std::time::{Duration, Instant};

/// The deadline of a simulation in this test program [s].
const DEADLINE: &str = "3";

/// The escaping FMU, built once per test program, with the name its runaway process takes,
/// the file it tries to write and the one it tries to read.
struct Escape {
    path: PathBuf,
    marker: String,
    outside: PathBuf,
    secret: PathBuf,
    _dir: tempfile::TempDir,
}

fn escape_fmu() -> Option<&'static Escape> {
    static BUILT: OnceLock<Option<Escape>> = OnceLock::new();
    BUILT
        .get_or_init(|| {
            // Every FMU of this program runs in child processes of the calib binary.
            std::env::set_var("CALIB_FMU_DEADLINE", DEADLINE);
            fmu::isolate_with(fmu::HostCommand {
                program: env!("CARGO_BIN_EXE_calib").into(),
                args: vec!["fmu-host".into()],
            });
            let dir = tempfile::tempdir().unwrap();
            let marker = format!("calib-esc{}", std::process::id() % 1_000_000);
            let outside = dir.path().join("outside.txt");
            let secret = dir.path().join("secret.txt");
            std::fs::write(&secret, "not for FMUs\n").unwrap();
            let defines = [
                format!("-DMARKER=\"{marker}\""),
                format!("-DOUTSIDE=\"{}\"", outside.display()),
                format!("-DSECRET=\"{}\"", secret.display()),
            ];
            let path = c_test_fmu("escaping_fmu", "escape", "Escape", &defines, dir.path())?;
            Some(Escape {
                path,
                marker,
                outside,
                secret,
                _dir: dir,
            })
        })
        .as_ref()
}

/// The escaping FMU with its instances in child processes of the calib binary, not
/// registered (dropping it stops them).
fn open(escape: &Escape) -> fmu::FmuModel {
    fmu::open_unregistered(&escape.path, None, true).unwrap()
}

/// Simulate `mode` for a second: the output `y`.
fn attempt(model: &fmu::FmuModel, mode: f64) -> Result<f64, SimulationError> {
    let y = model
        .info()
        .outputs
        .iter()
        .position(|o| o.name == "y")
        .expect("output y");
    let trajectory = model.simulate(&Run::new(
        &[mode],
        &[0.0, 1.0],
        &[y],
        &model.default_options(),
    ))?;
    Ok(trajectory.values[0][1])
}

/// The pids of live processes named `marker`.
fn named(marker: &str) -> Vec<u32> {
    std::fs::read_dir("/proc")
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<u32>().ok())
        .filter(|pid| {
            let live = std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
                !s.rsplit_once(')')
                    .is_some_and(|(_, r)| r.trim_start().starts_with('Z'))
            });
            live && std::fs::read_to_string(format!("/proc/{pid}/comm"))
                .is_ok_and(|c| c.trim_end() == marker)
        })
        .collect()
}

/// Wait (at most `within`) until `done` holds; whether it did.
fn eventually(within: Duration, mut done: impl FnMut() -> bool) -> bool {
    let until = Instant::now() + within;
    loop {
        if done() {
            return true;
        }
        if Instant::now() >= until {
            return false;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// One test of this program at a time: they count the processes named by one marker.
fn serial() -> std::sync::MutexGuard<'static, ()> {
    static SERIAL: std::sync::Mutex<()> = std::sync::Mutex::new(());
    SERIAL.lock().unwrap_or_else(|e| e.into_inner())
}

/// Whether process `pid` is alive (a zombie is not).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
        !s.rsplit_once(')')
            .is_some_and(|(_, r)| r.trim_start().starts_with('Z'))
    })
}

/// The session of process `pid`.
fn session(pid: u32) -> u32 {
    std::fs::read_to_string(format!("/proc/{pid}/stat"))
        .unwrap()
        .rsplit_once(')')
        .unwrap()
        .1
        .split_whitespace()
        .nth(3)
        .unwrap()
        .parse::<u32>()
        .unwrap()
}

#[test]
fn a_process_an_fmu_sends_away_ends_with_its_simulation() {
    let _serial = serial();
    let Some(escape) = escape_fmu() else { return };
    let model = open(escape);
    // It left (another session, its parent gone) while the simulation ran; the simulation
    // answers once it is gone, and the next simulation of the same host starts another.
    let first = attempt(&model, 1.0).unwrap() as u32;
    assert!(first > 1);
    assert!(!alive(first), "process {first} outlived its simulation");
    let second = attempt(&model, 1.0).unwrap() as u32;
    assert!(second > 1 && second != first);
    assert!(!alive(second), "process {second} outlived its simulation");
    assert_eq!(named(&escape.marker), Vec::<u32>::new(), "nothing left");
    drop(model);
}

#[test]
fn a_process_an_fmu_sends_away_is_killed_at_the_deadline() {
    let _serial = serial();
    let Some(escape) = escape_fmu() else { return };
    let model = open(escape);
    let (failed, seen) = std::thread::scope(|scope| {
        let running = scope.spawn(|| attempt(&model, 2.0));
        // The runaway process exists while the simulation hangs, in a session of its own.
        let seen = eventually(Duration::from_secs(30), || {
            !named(&escape.marker).is_empty()
        });
        let sessions: Vec<(u32, u32)> = named(&escape.marker)
            .into_iter()
            .map(|pid| (pid, session(pid)))
            .collect();
        (running.join().unwrap(), seen.then_some(sessions))
    });
    let sessions = seen.expect("the FMU started its process");
    assert!(sessions.iter().all(|(pid, sid)| pid == sid), "{sessions:?}");
    let message = failed.unwrap_err().to_string();
    assert!(
        message.contains(&format!("did not finish within {DEADLINE} s")),
        "{message}"
    );
    // Killed with the host at the deadline, before the model is dropped.
    assert_eq!(named(&escape.marker), Vec::<u32>::new(), "nothing left");
    drop(model);
}

#[test]
fn a_process_an_fmu_sends_away_ends_with_the_program_that_ran_it() {
    let _serial = serial();
    let Some(escape) = escape_fmu() else { return };
    let out = calib(&[
        "simulate",
        escape.path.to_str().unwrap(),
        "--set",
        "mode=1",
        "--stop",
        "1",
    ]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut lines = stdout.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let y = header
        .iter()
        .position(|h| h.trim_matches('"') == "y")
        .unwrap();
    let pid: f64 = lines
        .last()
        .unwrap()
        .split(',')
        .nth(y)
        .unwrap()
        .parse()
        .unwrap();
    assert!(pid > 1.0);
    // calib has exited: its FMU hosts are told so by the kernel and clean up.
    assert!(
        eventually(Duration::from_secs(20), || named(&escape.marker).is_empty()),
        "process {pid} outlived calib"
    );
}

#[test]
fn an_fmu_works_in_a_private_folder_removed_afterwards() {
    let _serial = serial();
    let Some(escape) = escape_fmu() else { return };
    let model = open(escape);
    let supervisor = attempt(&model, 6.0).unwrap() as u32;
    let folders = || -> Vec<PathBuf> {
        std::fs::read_dir(std::env::temp_dir())
            .unwrap()
            .filter_map(|e| e.ok())
            .filter(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with(&format!("calib-fmu-run-{supervisor}-"))
            })
            .map(|e| e.path())
            .collect()
    };
    let live = folders();
    assert_eq!(live.len(), 1, "{live:?}");
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(&live[0]).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o700, "only this user may enter it");
    // The FMU writes there (and nowhere else, below).
    assert_eq!(attempt(&model, 3.0).unwrap() as u32 & 2, 2);
    drop(model);
    assert_eq!(folders(), Vec::<PathBuf>::new());
}

#[test]
fn an_fmu_cannot_write_or_read_outside_its_folders_where_the_kernel_has_landlock() {
    let _serial = serial();
    let Some(escape) = escape_fmu() else { return };
    let model = open(escape);
    let wrote = attempt(&model, 3.0).unwrap() as u32;
    let read = attempt(&model, 4.0).unwrap() as u32;
    assert_eq!(wrote & 2, 2, "it writes in its working folder");
    match contain::containment().landlock_abi {
        Some(_) => {
            assert_eq!(wrote & 1, 0, "it could write {}", escape.outside.display());
            assert!(!escape.outside.exists());
            assert_eq!(read, 0, "it could read {}", escape.secret.display());
        }
        // Under CI the claim must be reached: a kernel without Landlock fails the test there.
        None => calib_model::testing::skip(&format!(
            "this kernel has no Landlock: file confinement is not tested (it wrote outside: \
             {}, read outside: {read})",
            wrote & 1
        )),
    }
}

#[test]
fn an_fmu_cannot_take_more_memory_than_its_bound() {
    let _serial = serial();
    let Some(escape) = escape_fmu() else { return };
    const { assert!(calib_model::limits::FMU_HOST_MEMORY_BYTES < 6 << 30) };
    let model = open(escape);
    assert_eq!(attempt(&model, 5.0).unwrap(), 0.0, "6 GiB were allocated");
}

#[test]
fn calib_models_refuses_an_archive_lying_about_a_size() {
    let dir = tempfile::tempdir().unwrap();
    let lying = zips::stored_zip64(
        &[("modelDescription.xml", zips::DESCRIPTION.as_bytes())],
        zips::Lies {
            first_size: Some(1 << 40),
            entries: None,
        },
    );
    let path = dir.path().join("Lying.fmu");
    std::fs::write(&path, lying).unwrap();
    let out = calib(&["models", path.to_str().unwrap()]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains("header says 1099511627776 bytes"),
        "{stderr}"
    );
}

#[test]
fn a_process_an_fmu_sends_away_ends_with_a_killed_worker() {
    use calib_proto::v1 as proto;
    use std::io::BufRead;
    let _serial = serial();
    let Some(escape) = escape_fmu() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cache = dir.path().join("fmu-cache");
    let mut worker = std::process::Command::new(env!("CARGO_BIN_EXE_calib"))
        .args([
            "worker",
            "--listen",
            "127.0.0.1:0",
            "--slots",
            "1",
            "--allow-fmu",
        ])
        .arg("--fmu-cache")
        .arg(&cache)
        // The simulation hangs until the worker is killed, not until its deadline.
        .env("CALIB_FMU_DEADLINE", "600")
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufReader::new(worker.stdout.take().unwrap())
        .read_line(&mut line)
        .unwrap();
    let address = line
        .strip_prefix("worker listening on ")
        .and_then(|rest| rest.split_whitespace().next())
        .unwrap_or_else(|| panic!("unexpected first line: {line}"))
        .to_string();
    let fmu = std::fs::read(&escape.path).unwrap();
    // A simulation that hangs (its process sent away), left running on a thread.
    let url = format!("http://{address}");
    std::thread::spawn(move || {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        runtime.block_on(async {
            let mut client = proto::simulator_client::SimulatorClient::connect(url)
                .await
                .unwrap();
            let uploaded = client
                .upload_fmu(proto::UploadFmuRequest {
                    protocol_version: calib_proto::PROTOCOL_VERSION,
                    fmu,
                })
                .await
                .unwrap()
                .into_inner();
            let _ = client
                .simulate(proto::SimulateRequest {
                    protocol_version: calib_proto::PROTOCOL_VERSION,
                    model: uploaded.models[0].clone(),
                    parameters: vec![proto::ParameterValue {
                        name: "mode".into(),
                        value: 2.0,
                    }],
                    times: vec![0.0, 1.0],
                    outputs: vec!["y".into()],
                    solver: None,
                    fmu_hash: uploaded.fmu_hash,
                    inputs: vec![],
                    effects: vec![],
                })
                .await;
        })
    });
    assert!(
        eventually(Duration::from_secs(30), || named(&escape.marker).len() == 1),
        "{:?}",
        named(&escape.marker)
    );
    let pid = named(&escape.marker)[0];
    // The worker is killed outright: it has no chance to stop its FMU hosts itself.
    worker.kill().unwrap();
    worker.wait().unwrap();
    assert!(
        eventually(Duration::from_secs(20), || named(&escape.marker).is_empty()),
        "process {pid} outlived the worker"
    );
}
