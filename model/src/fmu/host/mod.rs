//! FMU instances in child processes: a crash, an abort or a hang of the FMU's native code
//! is a failed simulation, never the end of the process that asked for it.
//!
//! The parent starts children as `HOST DIR INTERFACE` (the `calib` binary's hidden
//! `fmu-host` subcommand, see [`super::isolate_with`]), at most one per simulation running
//! at once (so one per worker slot), and keeps idle ones for the next simulation. Each child
//! opens the unpacked FMU in its own process and answers requests with replies on a channel
//! of their own (a Unix socket, the child's descriptor [`CHANNEL_FD`]), framed as a 4-byte
//! little-endian length and a body of little-endian numbers (values travel as their bits:
//! results are those of an in-process run, bit for bit).
//!
//! The child's stdout and stderr carry nothing of the protocol: they are the FMU's own
//! (what its code prints, C `stdout` made line-buffered) and its log messages. The parent
//! reads both as they come: each line is logged (`tracing`, info for stdout and for
//! messages of status ok, warn for stderr and for warnings and errors), prefixed with the
//! FMU's model identifier, at most [`LINES_LOGGED`] per simulation, each cut at
//! [`LINE_MAX`] bytes; the last lines are kept to explain a crash. The reading never stops,
//! so an FMU that prints a lot is never blocked by it, and never holds more than one line.
//!
//! A child that dies (a signal, an exit) or does not answer within the deadline
//! ([`deadline`]: `CALIB_FMU_DEADLINE` seconds, default 60) is killed and forgotten; the
//! simulation is [`SimulationError::Failed`] with what happened and the FMU's last
//! messages, and the next simulation starts a fresh child.
//!
//! On Linux each child is a supervisor in a session and process group of its own, and the
//! FMU's code runs one process below it, in a private working folder, with its memory, CPU
//! time and (with Landlock) files bounded; killing a child kills every process the FMU
//! started, whatever it did to get away ([`super::contain`]).

use super::{FmuError, Interface};
use crate::inputs::{InputSignal, Inputs, Interpolation};
use crate::model::{SimulationError, SolverOptions, SolverStats, Trajectory};
use std::collections::VecDeque;
use std::io::{Read, Write};
use std::os::fd::{AsRawFd, FromRawFd, RawFd};
use std::os::unix::net::UnixStream;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::mpsc;
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

mod output;
mod wire;

use output::{Output, Stream};
use wire::*;

/// The child's descriptor of its channel to the parent (named in its environment as
/// [`CHANNEL`]).
pub const CHANNEL_FD: RawFd = 3;
/// Set in a child's environment: the descriptor of its channel.
pub const CHANNEL: &str = "CALIB_FMU_CHANNEL";
/// Lines of a child's output kept to explain its failure.
const OUTPUT_KEPT: usize = 10;
/// Lines of a child's output logged per simulation; the rest are counted.
pub const LINES_LOGGED: usize = 1000;
/// Longest line of a child's output kept or logged [bytes]; the rest of it is dropped.
pub const LINE_MAX: usize = 4096;
/// How long a lost child's output may take to end once the child is reaped.
const OUTPUT_GRACE: Duration = Duration::from_secs(2);
/// How long a host whose FMU's process ended may take to clean up and exit by itself before
/// it is told to stop.
const ENDING_GRACE: Duration = Duration::from_secs(5);
/// Largest reply accepted from a child (the largest trajectory a request allows is far less).
const MAX_FRAME: usize = 1 << 30;

/// How long one simulation may take in a child before it is killed.
pub fn deadline() -> Duration {
    std::env::var("CALIB_FMU_DEADLINE")
        .ok()
        .and_then(|s| s.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s > 0.0)
        .map_or(
            Duration::from_secs_f64(crate::limits::FMU_DEADLINE_SECONDS),
            Duration::from_secs_f64,
        )
}

fn interface_arg(interface: Interface) -> &'static str {
    match interface {
        Interface::ModelExchange => "me",
        Interface::CoSimulation => "cs",
    }
}

/// Parse the interface argument a child is started with.
pub fn parse_interface(arg: &str) -> Option<Interface> {
    match arg {
        "me" => Some(Interface::ModelExchange),
        "cs" => Some(Interface::CoSimulation),
        _ => None,
    }
}

/// The children of one FMU.
pub struct Hosts {
    dir: PathBuf,
    interface: Interface,
    /// What its output lines are prefixed with (the model identifier).
    name: String,
    idle: Mutex<Vec<Child>>,
    /// Children that died or were killed, for tests and benchmarks.
    lost: std::sync::atomic::AtomicUsize,
}

struct Child {
    process: std::process::Child,
    channel: UnixStream,
    replies: mpsc::Receiver<std::io::Result<Vec<u8>>>,
    output: Arc<Output>,
    /// How it ended, once stopped.
    ended: Option<std::io::Result<std::process::ExitStatus>>,
}

impl Child {
    /// Stop it and every process its FMU started, and reap it (once); `ending`: how long
    /// it may take to end by itself first (see [`super::contain::stop_supervisor`]).
    fn stop(&mut self, ending: Duration) -> &std::io::Result<std::process::ExitStatus> {
        self.ended.get_or_insert_with(|| {
            #[cfg(target_os = "linux")]
            return super::contain::stop_supervisor(&mut self.process, ending);
            #[cfg(not(target_os = "linux"))]
            {
                let _ = self.process.kill();
                self.process.wait()
            }
        })
    }
}

impl Drop for Child {
    fn drop(&mut self) {
        self.stop(Duration::ZERO);
    }
}

impl Hosts {
    pub(super) fn new(dir: PathBuf, interface: Interface, name: String) -> Self {
        Self {
            dir,
            interface,
            name,
            idle: Mutex::new(Vec::new()),
            lost: std::sync::atomic::AtomicUsize::new(0),
        }
    }

    fn spawn(&self) -> Result<Child, FmuError> {
        let command = super::host_command()
            .ok_or_else(|| FmuError::Host("no host program to run FMU instances in".into()))?;
        // The FMU's process works in a folder of its own: the FMU's by its full path.
        let dir = std::fs::canonicalize(&self.dir).unwrap_or_else(|_| self.dir.clone());
        let cannot = |e: std::io::Error| {
            FmuError::Host(format!("cannot start {}: {e}", command.program.display()))
        };
        // The channel: our end here, theirs (close-on-exec like every descriptor of this
        // process) the child's CHANNEL_FD.
        let (channel, theirs) = UnixStream::pair().map_err(cannot)?;
        let process = self.command(command, &dir, theirs.as_raw_fd());
        let mut process = start_child(process).map_err(cannot)?;
        // Only the child holds its end now: the replies end when it does.
        drop(theirs);
        let stdout = process.stdout.take().expect("piped");
        let stderr = process.stderr.take().expect("piped");
        let replies = follow_replies(channel.try_clone().map_err(cannot)?);
        let output = self.follow_output(stdout, stderr);
        Ok(Child {
            process,
            channel,
            replies,
            output,
            ended: None,
        })
    }

    /// The command that starts a child by `host` on the FMU at `dir`, with our descriptor
    /// `their_fd` as its channel [`CHANNEL_FD`] and its stdout and stderr piped to us.
    fn command(&self, host: &super::HostCommand, dir: &Path, their_fd: RawFd) -> Command {
        let mut process = Command::new(&host.program);
        process
            .args(&host.args)
            .arg(dir)
            .arg(interface_arg(self.interface))
            .env(CHANNEL, CHANNEL_FD.to_string())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        // SAFETY: only async-signal-safe calls between fork and exec.
        unsafe {
            process.pre_exec(move || {
                let done = if their_fd == CHANNEL_FD {
                    libc::fcntl(CHANNEL_FD, libc::F_SETFD, 0)
                } else {
                    libc::dup2(their_fd, CHANNEL_FD)
                };
                if done < 0 {
                    return Err(std::io::Error::last_os_error());
                }
                Ok(())
            });
        }
        process
    }

    /// The child's stdout and stderr, each read by a thread of its own as it comes (its lines
    /// logged with the FMU's name, the last ones kept).
    fn follow_output(
        &self,
        stdout: std::process::ChildStdout,
        stderr: std::process::ChildStderr,
    ) -> Arc<Output> {
        let output = Arc::new(Output::new(
            self.name.clone(),
            [
                (std::os::fd::OwnedFd::from(stdout), Stream::Stdout),
                (std::os::fd::OwnedFd::from(stderr), Stream::Stderr),
            ],
        ));
        for pipe in 0..output.pipes.len() {
            let output = Arc::clone(&output);
            std::thread::spawn(move || output.follow(pipe));
        }
        output
    }

    /// Children lost to a crash or a deadline so far.
    pub fn lost(&self) -> usize {
        self.lost.load(std::sync::atomic::Ordering::Relaxed)
    }

    pub(super) fn simulate(
        &self,
        params: &[f64],
        grid: &[f64],
        outputs: &[usize],
        options: &SolverOptions,
        inputs: &Inputs,
    ) -> Result<Trajectory, SimulationError> {
        let failed = |reason: String| SimulationError::Failed { time: 0.0, reason };
        let idle = self.idle.lock().unwrap_or_else(|e| e.into_inner()).pop();
        let mut child = match idle {
            Some(child) => child,
            None => self.spawn().map_err(|e| failed(e.to_string()))?,
        };
        let request = encode_request(params, grid, outputs, options, inputs);
        child.output.logged.store(0, Ordering::Relaxed);
        let sent = write_frame(&mut child.channel, &request);
        let reply = match sent {
            Ok(()) => child.replies.recv_timeout(deadline()),
            Err(e) => Ok(Err(e)),
        };
        match reply {
            Ok(Ok(frame)) => {
                // What the FMU printed before it replied is logged before the result.
                child.output.catch_up();
                let result = decode_reply(&frame, grid).map_err(|e| failed(e.to_string()))?;
                self.idle
                    .lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .push(child);
                result
            }
            Ok(Err(_)) | Err(mpsc::RecvTimeoutError::Disconnected) => {
                Err(failed(self.lose(child, None)))
            }
            Err(mpsc::RecvTimeoutError::Timeout) => Err(failed(self.lose(child, Some(deadline())))),
        }
    }

    /// Kill and reap a child; what happened to it, with its last messages.
    fn lose(&self, mut child: Child, timed_out: Option<Duration>) -> String {
        self.lost.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        // Answers that stopped mean the FMU's process ended: its supervisor is cleaning up
        // and will exit as that process did.
        let ending = if timed_out.is_none() {
            ENDING_GRACE
        } else {
            Duration::ZERO
        };
        let output = Arc::clone(&child.output);
        let status = child.stop(ending);
        // Every process of the FMU is gone: its output ends once read.
        output.wait_closed(OUTPUT_GRACE);
        let what = match (timed_out, status) {
            (Some(d), _) => format!(
                "the FMU did not finish within {} s and was stopped",
                d.as_secs_f64()
            ),
            (None, Ok(status)) => {
                use std::os::unix::process::ExitStatusExt;
                match status.signal() {
                    Some(24) => "the FMU's process used up its CPU time and was stopped".into(),
                    Some(signal) => format!("the FMU's process crashed ({})", signal_name(signal)),
                    None => format!("the FMU's process ended ({status})"),
                }
            }
            (None, Err(e)) => format!("the FMU's process was lost: {e}"),
        };
        let lines: Vec<String> = output
            .kept
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .cloned()
            .collect();
        if lines.is_empty() {
            what
        } else {
            format!("{what}; the FMU says: {}", lines.join(" | "))
        }
    }
}

/// Start the child of `process`: on Linux a supervisor that contains the FMU's process
/// (saying once, on the first start, how it is contained).
#[cfg(target_os = "linux")]
fn start_child(process: Command) -> std::io::Result<std::process::Child> {
    static SAID: std::sync::Once = std::sync::Once::new();
    SAID.call_once(|| {
        let containment = super::contain::containment();
        if containment.landlock_abi.is_some() {
            tracing::info!("FMUs: {containment}");
        } else {
            tracing::warn!("FMUs: {containment}");
        }
    });
    super::contain::spawn_supervisor(process)
}

/// Start the child of `process`.
#[cfg(not(target_os = "linux"))]
fn start_child(mut process: Command) -> std::io::Result<std::process::Child> {
    process.spawn()
}

/// A thread that reads the replies off `channel` (our end) until it ends or fails; the
/// replies, as they come.
fn follow_replies(mut channel: UnixStream) -> mpsc::Receiver<std::io::Result<Vec<u8>>> {
    let (send, replies) = mpsc::channel();
    std::thread::spawn(move || loop {
        let frame = read_frame(&mut channel);
        let end = frame.is_err();
        if send.send(frame).is_err() || end {
            return;
        }
    });
    replies
}

impl Drop for Hosts {
    fn drop(&mut self) {
        // Each child stops as it is dropped, with every process its FMU started.
        self.idle
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .clear();
    }
}

fn signal_name(signal: i32) -> String {
    let name = match signal {
        4 => "SIGILL",
        6 => "SIGABRT",
        7 => "SIGBUS",
        8 => "SIGFPE",
        9 => "SIGKILL",
        11 => "SIGSEGV",
        15 => "SIGTERM",
        24 => "SIGXCPU",
        _ => return format!("signal {signal}"),
    };
    format!("signal {signal}, {name}")
}

extern "C" {
    /// C `stdout` line-buffered, `stderr` unbuffered (`csrc/fmi2_logger.c`).
    fn calib_stdio_line_buffered();
}

/// The child's side: open the FMU unpacked at `dir` and answer requests on the channel the
/// parent gave ([`CHANNEL`]) until it closes. FMU log messages are written to stderr as they
/// come. On Linux the child first becomes the supervisor of the FMU's own process
/// ([`super::contain`]), which serves.
pub fn serve(dir: &Path, interface: Interface) -> Result<(), FmuError> {
    let fd: RawFd = std::env::var(CHANNEL)
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&fd| fd > 2)
        .ok_or_else(|| {
            FmuError::Host(format!(
                "no channel to the parent (the FMU host is started by calib, with {CHANNEL})"
            ))
        })?;
    // SAFETY: a plain query of a descriptor.
    if unsafe { libc::fcntl(fd, libc::F_GETFD) } < 0 {
        return Err(FmuError::Host(format!("no channel to the parent at {fd}")));
    }
    #[cfg(target_os = "linux")]
    {
        if std::env::var_os(super::contain::INNER).is_none() {
            super::contain::supervise(fd);
        }
        let workdir = std::env::current_dir()
            .map_err(|e| FmuError::Host(format!("no working folder: {e}")))?;
        super::contain::confine(dir, &workdir);
    }
    // SAFETY: the descriptor is open and this process's alone to own from here; made
    // close-on-exec, so that no program the FMU runs holds it.
    let channel = unsafe {
        libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC);
        UnixStream::from_raw_fd(fd)
    };
    // SAFETY: before any FMU code runs, nothing else uses C stdio.
    unsafe { calib_stdio_line_buffered() };
    super::ffi::echo_log_to_stderr();
    let model = super::open_unpacked(dir, interface)?;
    let mut input = std::io::BufReader::new(
        channel
            .try_clone()
            .map_err(|e| FmuError::Host(format!("the channel to the parent: {e}")))?,
    );
    let mut output = channel;
    loop {
        let frame = match read_frame(&mut input) {
            Ok(frame) => frame,
            Err(_) => return Ok(()),
        };
        let reply = match decode_request(&frame) {
            Some((params, grid, outputs, options, inputs)) => {
                #[cfg(target_os = "linux")]
                super::contain::allow_cpu(deadline().as_secs_f64());
                let run = crate::Run::new(&params, &grid, &outputs, &options).driven(&inputs);
                let result = crate::Model::simulate(&model, &run);
                // Nothing the simulation started outlives it.
                #[cfg(target_os = "linux")]
                if super::contain::reap_leftovers() > 0 {
                    model.forget_idle_instances();
                }
                encode_reply(&result)
            }
            None => encode_reply(&Err(SimulationError::InvalidInput(
                "malformed request to the FMU host".into(),
            ))),
        };
        // What the FMU printed is in the pipes before the reply is sent.
        // SAFETY: flushes every C output stream.
        unsafe { libc::fflush(std::ptr::null_mut()) };
        if write_frame(&mut output, &reply).is_err() {
            return Ok(());
        }
    }
}
