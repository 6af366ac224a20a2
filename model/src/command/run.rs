//! Runs of a command model. A slot's run folder is the model's folder copied once
//! ([`CommandModel::prepare`]); each run in it ([`CommandModel::run_in`]) removes the outputs
//! a run before left, writes each template with the parameters' values, runs the command by
//! the shell in a process group of its own with a deadline, and reads each output with its
//! instruction file. The folder is removed when its slot drops it. As with PEST++'s agents, a
//! command that changes the other files of its folder changes them for the slot's next runs.
//!
//! A run that cannot start, exits non-zero, outlives its deadline or leaves an output its
//! instructions cannot read is a [`RunFailure`] that says which, with the last lines the
//! command wrote to its standard error. Whatever the command started in its process group
//! (a background job, a forked child) is killed when the run ends, however it ended. Not yet
//! here: the FMU host's confinement of files (Landlock) and bounds of memory and CPU time;
//! a command that leaves its process group (`setsid`) outlives the run.

use super::instructions::{Instructions, PestFileError};
use super::template::Template;
use std::collections::BTreeMap;
use std::fmt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Lines of the command's standard error a failure quotes.
pub const QUOTED_LINES: usize = 5;

/// A command model: its folder, its command line, its templates and instruction files
/// (each with the file it writes or reads, relative to the run folder).
pub struct CommandModel {
    pub folder: PathBuf,
    pub command: String,
    pub templates: Vec<(Template, PathBuf)>,
    pub instructions: Vec<(Instructions, PathBuf)>,
    pub deadline: Duration,
}

/// Why a run gave no observations.
#[derive(Debug, Clone, PartialEq)]
pub enum RunFailure {
    /// The run folder could not be made or the command not started.
    Start(String),
    /// A template could not be written (a value that does not fit, a missing parameter).
    Input(PestFileError),
    /// The command exited with this status (or was killed by a signal).
    Exit { status: String, stderr: String },
    /// The command outlived the deadline, and was killed.
    Deadline { seconds: f64, stderr: String },
    /// An output could not be read with its instruction file.
    Output(PestFileError),
}

impl fmt::Display for RunFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let quoted = |stderr: &str| {
            if stderr.is_empty() {
                String::new()
            } else {
                format!("; its last lines on standard error:\n{stderr}")
            }
        };
        match self {
            RunFailure::Start(m) => write!(f, "the command could not start: {m}"),
            RunFailure::Input(e) => write!(f, "an input could not be written: {e}"),
            RunFailure::Exit { status, stderr } => {
                write!(f, "the command {status}{}", quoted(stderr))
            }
            RunFailure::Deadline { seconds, stderr } => write!(
                f,
                "the command did not end within its deadline of {seconds} s and was killed{}",
                quoted(stderr)
            ),
            RunFailure::Output(e) => write!(f, "an output could not be read: {e}"),
        }
    }
}

impl std::error::Error for RunFailure {}

/// A slot's private copy of the model's folder, removed when dropped.
pub struct RunFolder(tempfile::TempDir);

impl RunFolder {
    pub fn path(&self) -> &Path {
        self.0.path()
    }
}

impl CommandModel {
    /// A run folder for one slot: the model's folder copied into a new folder under
    /// `scratch`.
    pub fn prepare(&self, scratch: &Path) -> Result<RunFolder, RunFailure> {
        let folder = tempfile::Builder::new()
            .prefix("calib-run-")
            .tempdir_in(scratch)
            .map_err(|e| RunFailure::Start(format!("run folder in {}: {e}", scratch.display())))?;
        copy_folder(&self.folder, folder.path())
            .map_err(|e| RunFailure::Start(format!("copying {}: {e}", self.folder.display())))?;
        Ok(RunFolder(folder))
    }

    /// One run in a folder of its own under `scratch`, removed after it.
    pub fn run(
        &self,
        values: &BTreeMap<String, f64>,
        scratch: &Path,
    ) -> Result<Vec<f64>, RunFailure> {
        self.run_in(&self.prepare(scratch)?, values)
    }

    /// Run the model in `folder` with the parameters' values `values` (by name, as the
    /// templates name them); the observations, in the order of the instruction files and, in
    /// each, of its observations.
    pub fn run_in(
        &self,
        folder: &RunFolder,
        values: &BTreeMap<String, f64>,
    ) -> Result<Vec<f64>, RunFailure> {
        let run = folder.path();
        // An output a run before left is not this run's.
        for (_, file) in &self.instructions {
            match std::fs::remove_file(run.join(file)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(RunFailure::Start(format!("{}: {e}", file.display())))
                }
                _ => {}
            }
        }
        for (template, file) in &self.templates {
            let text = template.write(values).map_err(RunFailure::Input)?;
            std::fs::write(run.join(file), text)
                .map_err(|e| RunFailure::Start(format!("{}: {e}", file.display())))?;
        }
        self.execute(run)?;
        let mut observations = Vec::new();
        for (instructions, file) in &self.instructions {
            let text = std::fs::read(run.join(file)).map_err(|e| {
                RunFailure::Output(PestFileError {
                    file: file.display().to_string(),
                    line: 0,
                    column: 0,
                    message: format!("the command left no readable output: {e}"),
                })
            })?;
            let text = String::from_utf8_lossy(&text);
            let values = instructions
                .read(&text, &file.display().to_string())
                .map_err(RunFailure::Output)?;
            observations.extend(values);
        }
        Ok(observations)
    }

    /// Run the command in `run` until it ends or its deadline passes; its process group is
    /// killed either way.
    fn execute(&self, run: &Path) -> Result<(), RunFailure> {
        let stderr_path = run.join(".calib-stderr");
        let stderr = std::fs::File::create(&stderr_path)
            .map_err(|e| RunFailure::Start(format!("{}: {e}", stderr_path.display())))?;
        let mut child = Command::new("/bin/sh")
            .arg("-c")
            .arg(&self.command)
            .current_dir(run)
            .env("TMPDIR", run)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(stderr)
            .process_group(0)
            .spawn()
            .map_err(|e| RunFailure::Start(format!("`{}`: {e}", self.command)))?;
        let group = child.id() as libc::pid_t;
        // A thread waits for the command to end, without reaping it (`WNOWAIT`): its end is
        // seen at once, not at a poll, and its id stays its own until the group is killed.
        let (sender, ended) = std::sync::mpsc::channel();
        let waiter = std::thread::spawn(move || {
            // SAFETY: waitid writes only into `info`, which lives for the call.
            let mut info: libc::siginfo_t = unsafe { std::mem::zeroed() };
            let waited = loop {
                let waited = unsafe {
                    libc::waitid(
                        libc::P_PID,
                        group as libc::id_t,
                        &mut info,
                        libc::WEXITED | libc::WNOWAIT,
                    )
                };
                // Interrupted by a signal: the command has not ended; wait again.
                if waited == -1
                    && std::io::Error::last_os_error().kind() == std::io::ErrorKind::Interrupted
                {
                    continue;
                }
                break waited;
            };
            let _ = sender.send(waited);
        });
        let in_time = ended.recv_timeout(self.deadline).is_ok();
        // What the command started in its group ends with it (and the command itself, at
        // the deadline); then it is reaped.
        kill_group(group);
        let status = child
            .wait()
            .map_err(|e| RunFailure::Start(format!("waiting for the command: {e}")));
        let _ = waiter.join();
        let status = status?;
        let stderr = last_lines(&stderr_path);
        if !in_time {
            return Err(RunFailure::Deadline {
                seconds: self.deadline.as_secs_f64(),
                stderr,
            });
        }
        if !status.success() {
            return Err(RunFailure::Exit {
                status: exit_words(status),
                stderr,
            });
        }
        Ok(())
    }
}

/// Kill every process of the group `group` (the command's shell and what it started).
fn kill_group(group: libc::pid_t) {
    // SAFETY: kill(2) with a negative pid signals the process group; it touches no memory.
    unsafe {
        libc::kill(-group, libc::SIGKILL);
    }
}

/// How a command ended, in words.
fn exit_words(status: std::process::ExitStatus) -> String {
    use std::os::unix::process::ExitStatusExt;
    match (status.code(), status.signal()) {
        (Some(code), _) => format!("exited with status {code}"),
        (None, Some(signal)) => format!("was killed by signal {signal}"),
        _ => format!("ended: {status}"),
    }
}

/// The last [`QUOTED_LINES`] lines of the file at `path` (empty when there is none).
fn last_lines(path: &Path) -> String {
    let text = std::fs::read(path).unwrap_or_default();
    let text = String::from_utf8_lossy(&text);
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(QUOTED_LINES)..].join("\n")
}

/// Copy the folder `from` into `to` (which exists), files and folders, symbolic links as
/// links.
fn copy_folder(from: &Path, to: &Path) -> std::io::Result<()> {
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let (source, target) = (entry.path(), to.join(entry.file_name()));
        let kind = entry.file_type()?;
        if kind.is_dir() {
            std::fs::create_dir(&target)?;
            copy_folder(&source, &target)?;
        } else if kind.is_symlink() {
            std::os::unix::fs::symlink(std::fs::read_link(&source)?, &target)?;
        } else {
            std::fs::copy(&source, &target)?;
        }
    }
    Ok(())
}
