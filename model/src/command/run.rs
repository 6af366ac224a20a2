//! One run of a command model: the model's folder copied into a private run folder, each
//! template written there with the parameters' values, the command run in it by the shell in
//! a process group of its own with a deadline, each output read with its instruction file,
//! and the folder removed.
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
use std::time::{Duration, Instant};

/// Lines of the command's standard error a failure quotes.
pub const QUOTED_LINES: usize = 5;
/// How often a running command is checked on.
const POLL: Duration = Duration::from_millis(5);

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

impl CommandModel {
    /// Run the model with the parameters' values `values` (by name, as the templates name
    /// them) in a folder made under `scratch`; the observations, in the order of the
    /// instruction files and, in each, of its observations.
    pub fn run(
        &self,
        values: &BTreeMap<String, f64>,
        scratch: &Path,
    ) -> Result<Vec<f64>, RunFailure> {
        let folder = tempfile::Builder::new()
            .prefix("calib-run-")
            .tempdir_in(scratch)
            .map_err(|e| RunFailure::Start(format!("run folder in {}: {e}", scratch.display())))?;
        let run = folder.path();
        copy_folder(&self.folder, run)
            .map_err(|e| RunFailure::Start(format!("copying {}: {e}", self.folder.display())))?;
        for (template, file) in &self.templates {
            let text = template.write(values).map_err(RunFailure::Input)?;
            std::fs::write(run.join(file), text)
                .map_err(|e| RunFailure::Start(format!("{}: {e}", file.display())))?;
        }
        self.execute(run)?;
        let mut observations = Vec::new();
        for (instructions, file) in &self.instructions {
            let path = run.join(file);
            let text = std::fs::read(&path).map_err(|e| {
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
        let started = Instant::now();
        let status = loop {
            match child.try_wait() {
                Ok(Some(status)) => break Some(status),
                Ok(None) if started.elapsed() >= self.deadline => break None,
                Ok(None) => std::thread::sleep(POLL),
                Err(e) => {
                    kill_group(group);
                    return Err(RunFailure::Start(format!("waiting for the command: {e}")));
                }
            }
        };
        kill_group(group);
        if status.is_none() {
            let _ = child.wait();
        }
        let stderr = last_lines(&stderr_path);
        match status {
            None => Err(RunFailure::Deadline {
                seconds: self.deadline.as_secs_f64(),
                stderr,
            }),
            Some(status) if !status.success() => Err(RunFailure::Exit {
                status: exit_words(status),
                stderr,
            }),
            Some(_) => Ok(()),
        }
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
