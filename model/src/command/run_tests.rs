//! A command that hangs, crashes, writes garbage or leaves a process behind costs a failed
//! run and nothing else.

use super::run::{CommandModel, RunFailure};
use super::{Instructions, Template};
use std::collections::BTreeMap;
use std::path::Path;
use std::time::{Duration, Instant};

/// A model whose folder holds `script` (run by `sh script.sh`), a template writing `k` into
/// `in.txt`, and an instruction file reading `y` from the line after `y =` in `out.txt`.
fn model(folder: &Path, script: &str, deadline: Duration) -> CommandModel {
    std::fs::write(folder.join("script.sh"), script).unwrap();
    CommandModel {
        folder: folder.to_path_buf(),
        command: "sh script.sh".into(),
        templates: vec![(
            Template::parse("ptf #\nk = #k      #\n", "in.tpl").unwrap(),
            "in.txt".into(),
        )],
        instructions: vec![(
            Instructions::parse("pif @\n@y =@ !y!\n", "out.ins").unwrap(),
            "out.txt".into(),
        )],
        deadline,
    }
}

fn run(script: &str, deadline: Duration) -> (Result<Vec<f64>, RunFailure>, tempfile::TempDir) {
    let (folder, scratch) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let model = model(folder.path(), script, deadline);
    let values = BTreeMap::from([("k".to_string(), 2.5)]);
    (model.run(&values, scratch.path()), scratch)
}

fn alive(pid: i32) -> bool {
    Path::new(&format!("/proc/{pid}")).exists()
        && !std::fs::read_to_string(format!("/proc/{pid}/stat"))
            .unwrap_or_default()
            .contains(") Z ")
}

#[test]
fn a_command_reads_its_input_and_writes_its_output() {
    // The template wrote "k = <value>"; the script doubles it (awk, in the base system).
    let script = "awk '{ print \"y = \" $3 * 2 }' in.txt > out.txt\n";
    let (values, scratch) = run(script, Duration::from_secs(30));
    assert_eq!(values.unwrap(), [5.0]);
    assert_eq!(std::fs::read_dir(scratch.path()).unwrap().count(), 0);
}

#[test]
fn a_command_that_exits_non_zero_is_a_failure_quoting_its_last_lines() {
    let script = (1..=8)
        .map(|i| format!("echo line {i} >&2\n"))
        .collect::<String>()
        + "exit 3\n";
    let (failure, _) = run(&script, Duration::from_secs(30));
    let failure = failure.unwrap_err();
    let RunFailure::Exit { status, stderr } = &failure else {
        panic!("{failure}");
    };
    assert_eq!(status, "exited with status 3");
    assert_eq!(stderr, "line 4\nline 5\nline 6\nline 7\nline 8");
}

#[test]
fn a_command_that_hangs_is_killed_at_its_deadline() {
    let started = Instant::now();
    let (failure, _) = run("sleep 100\n", Duration::from_millis(500));
    let failure = failure.unwrap_err();
    assert!(matches!(failure, RunFailure::Deadline { .. }), "{failure}");
    assert!(
        failure.to_string().contains("deadline of 0.5 s"),
        "{failure}"
    );
    // Killed at its deadline, not waited for (100 s).
    assert!(started.elapsed() < Duration::from_secs(60));
}

#[test]
fn a_process_the_command_leaves_behind_ends_with_the_run() {
    let scratch = tempfile::tempdir().unwrap();
    let pid_file = scratch.path().join("child.pid");
    let script = format!(
        "sleep 300 &\necho $! > {}\necho 'y = 1.5' > out.txt\n",
        pid_file.display()
    );
    let folder = tempfile::tempdir().unwrap();
    let model = model(folder.path(), &script, Duration::from_secs(30));
    let values = BTreeMap::from([("k".to_string(), 2.5)]);
    assert_eq!(model.run(&values, scratch.path()).unwrap(), [1.5]);
    let pid: i32 = std::fs::read_to_string(&pid_file)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    while alive(pid) {
        assert!(
            Instant::now() < deadline,
            "the background sleep {pid} outlived the run"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

#[test]
fn garbage_or_no_output_is_a_failure_naming_the_file() {
    let (failure, _) = run("echo 'y = twelve' > out.txt\n", Duration::from_secs(30));
    let failure = failure.unwrap_err();
    let RunFailure::Output(e) = &failure else {
        panic!("{failure}");
    };
    assert!(
        e.message.contains("`twelve` is not a number") && e.message.contains("out.txt"),
        "{e}"
    );
    let (failure, _) = run("true\n", Duration::from_secs(30));
    assert!(
        failure
            .unwrap_err()
            .to_string()
            .contains("left no readable output"),
        "no output"
    );
}

#[test]
fn a_value_that_cannot_be_written_is_a_failure_before_anything_runs() {
    let (folder, scratch) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    let model = model(folder.path(), "touch ran\n", Duration::from_secs(30));
    let values = BTreeMap::from([("k".to_string(), f64::NAN)]);
    let failure = model.run(&values, scratch.path()).unwrap_err();
    assert!(matches!(failure, RunFailure::Input(_)), "{failure}");
    assert_eq!(std::fs::read_dir(scratch.path()).unwrap().count(), 0);
}

/// Runs in one slot's folder: each reads its own output, never one a run before left.
#[test]
fn a_slots_runs_read_their_own_outputs_never_a_stale_one() {
    let (folder, scratch) = (tempfile::tempdir().unwrap(), tempfile::tempdir().unwrap());
    // Writes y = 2k the first time, nothing after (a marker file says it ran once).
    let script = "if [ -e ran ]; then exit 0; fi\ntouch ran\nawk '{ print \"y = \" $3 * 2 }' in.txt > out.txt\n";
    let model = model(folder.path(), script, Duration::from_secs(30));
    let slot = model.prepare(scratch.path()).unwrap();
    let first = model.run_in(&slot, &BTreeMap::from([("k".to_string(), 1.25)]));
    assert_eq!(first.unwrap(), [2.5]);
    let second = model.run_in(&slot, &BTreeMap::from([("k".to_string(), 4.0)]));
    let failure = second.unwrap_err();
    assert!(
        failure.to_string().contains("left no readable output"),
        "{failure}"
    );
    drop(slot);
    assert_eq!(
        std::fs::read_dir(scratch.path()).unwrap().count(),
        0,
        "the slot's folder goes with it"
    );
}
