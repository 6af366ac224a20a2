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
        let their_fd = theirs.as_raw_fd();
        let mut process = Command::new(&command.program);
        process
            .args(&command.args)
            .arg(&dir)
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
        #[cfg(target_os = "linux")]
        let started = {
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
        };
        #[cfg(not(target_os = "linux"))]
        let started = process.spawn();
        let mut process = started.map_err(cannot)?;
        // Only the child holds its end now: the replies end when it does.
        drop(theirs);
        let stdout = process.stdout.take().expect("piped");
        let stderr = process.stderr.take().expect("piped");
        let mut replies_from = channel.try_clone().map_err(cannot)?;
        let (send, replies) = mpsc::channel();
        std::thread::spawn(move || loop {
            let frame = read_frame(&mut replies_from);
            let end = frame.is_err();
            if send.send(frame).is_err() || end {
                return;
            }
        });
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
        Ok(Child {
            process,
            channel,
            replies,
            output,
            ended: None,
        })
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

impl Drop for Hosts {
    fn drop(&mut self) {
        // Each child stops as it is dropped, with every process its FMU started.
        self.idle
            .get_mut()
            .unwrap_or_else(|e| e.into_inner())
            .clear();
    }
}

/// Which of a child's output streams a line came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Stream {
    Stdout,
    Stderr,
}

/// What a child writes on its stdout and stderr: logged as it comes, the last lines kept.
struct Output {
    name: String,
    pipes: Vec<Mutex<Pipe>>,
    kept: Mutex<VecDeque<String>>,
    /// Lines logged since the last request.
    logged: AtomicUsize,
    /// Pipes whose reader has not yet seen their end.
    open: Mutex<usize>,
    closed: Condvar,
}

/// One of a child's output pipes (non-blocking), with the line it is in the middle of.
struct Pipe {
    file: std::fs::File,
    stream: Stream,
    lines: Lines,
    ended: bool,
}

/// Most bytes read from a pipe by [`Output::catch_up`] at once (what a process the FMU
/// left behind writes meanwhile is read by the pipe's own thread).
const CATCH_UP_MAX: usize = 64 << 20;

impl Output {
    fn new(name: String, pipes: [(std::os::fd::OwnedFd, Stream); 2]) -> Self {
        let pipes: Vec<Mutex<Pipe>> = pipes
            .into_iter()
            .map(|(fd, stream)| {
                // SAFETY: a plain system call on a descriptor this process owns.
                unsafe {
                    let flags = libc::fcntl(fd.as_raw_fd(), libc::F_GETFL);
                    libc::fcntl(fd.as_raw_fd(), libc::F_SETFL, flags | libc::O_NONBLOCK);
                }
                Mutex::new(Pipe {
                    file: std::fs::File::from(fd),
                    stream,
                    lines: Lines::default(),
                    ended: false,
                })
            })
            .collect();
        Self {
            name,
            kept: Mutex::new(VecDeque::new()),
            logged: AtomicUsize::new(0),
            open: Mutex::new(pipes.len()),
            pipes,
            closed: Condvar::new(),
        }
    }

    /// The thread of pipe `index`: read it as it becomes readable, to its end.
    fn follow(&self, index: usize) {
        let fd = self.pipe(index).file.as_raw_fd();
        loop {
            let mut poll = libc::pollfd {
                fd,
                events: libc::POLLIN,
                revents: 0,
            };
            // SAFETY: one valid pollfd; the descriptor lives as long as `self`.
            let ready = unsafe { libc::poll(&mut poll, 1, -1) };
            if ready < 0
                && std::io::Error::last_os_error().kind() != std::io::ErrorKind::Interrupted
            {
                break;
            }
            let mut pipe = self.pipe(index);
            if pipe.ended || !self.drain(&mut pipe, usize::MAX) {
                pipe.ended = true;
                break;
            }
        }
        *self.open.lock().unwrap_or_else(|e| e.into_inner()) -= 1;
        self.closed.notify_all();
    }

    fn pipe(&self, index: usize) -> std::sync::MutexGuard<'_, Pipe> {
        self.pipes[index].lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Read what `pipe` holds now (at most `max` bytes), line by line; whether it has not
    /// ended.
    fn drain(&self, pipe: &mut Pipe, max: usize) -> bool {
        let mut buffer = [0u8; 8192];
        let mut read = 0;
        while read < max {
            match pipe.file.read(&mut buffer) {
                Ok(0) => break,
                Ok(n) => {
                    read += n;
                    let stream = pipe.stream;
                    pipe.lines
                        .push(&buffer[..n], |line| self.line(line, stream));
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => return true,
                Err(_) => break,
            }
        }
        if read >= max {
            return true;
        }
        let stream = pipe.stream;
        pipe.lines.finish(|line| self.line(line, stream));
        pipe.ended = true;
        false
    }

    /// Read what the pipes hold now: everything the child wrote before it replied.
    fn catch_up(&self) {
        for index in 0..self.pipes.len() {
            let mut pipe = self.pipe(index);
            if !pipe.ended {
                self.drain(&mut pipe, CATCH_UP_MAX);
            }
        }
    }

    fn line(&self, line: String, stream: Stream) {
        let logged = self.logged.fetch_add(1, Ordering::Relaxed);
        if logged < LINES_LOGGED {
            let name = &self.name;
            if warns(&line, stream) {
                tracing::warn!("{name}: {line}");
            } else {
                tracing::info!("{name}: {line}");
            }
        } else if logged == LINES_LOGGED {
            tracing::warn!(
                "{name}: more than {LINES_LOGGED} lines of output in one simulation; the rest \
                 are not logged",
                name = self.name
            );
        }
        let mut kept = self.kept.lock().unwrap_or_else(|e| e.into_inner());
        if kept.len() == OUTPUT_KEPT {
            kept.pop_front();
        }
        kept.push_back(line);
    }

    /// Wait (at most `within`) until every stream has ended.
    fn wait_closed(&self, within: Duration) {
        let until = Instant::now() + within;
        let mut open = self.open.lock().unwrap_or_else(|e| e.into_inner());
        while *open > 0 {
            let left = until.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return;
            }
            open = self
                .closed
                .wait_timeout(open, left)
                .unwrap_or_else(|e| e.into_inner())
                .0;
        }
    }
}

/// Whether a line of output is logged as a warning: the FMU's log messages by their status
/// (`[warning] …`, as the child writes them), other lines by their stream.
fn warns(line: &str, stream: Stream) -> bool {
    let status = line
        .strip_prefix('[')
        .and_then(|rest| rest.split_once("] "))
        .map(|(status, _)| status);
    match status {
        Some("ok" | "pending") => false,
        Some("warning" | "discard" | "error" | "fatal") => true,
        _ => stream == Stream::Stderr,
    }
}

/// Bytes cut into lines of at most [`LINE_MAX`] bytes (the rest of a longer one dropped,
/// and said so), holding one line at most.
#[derive(Default)]
struct Lines {
    line: Vec<u8>,
    dropped: usize,
}

impl Lines {
    fn push(&mut self, mut bytes: &[u8], mut emit: impl FnMut(String)) {
        while !bytes.is_empty() {
            let (part, end) = match bytes.iter().position(|&b| b == b'\n') {
                Some(i) => (&bytes[..i], Some(i + 1)),
                None => (bytes, None),
            };
            let room = LINE_MAX - self.line.len();
            let taken = part.len().min(room);
            self.line.extend_from_slice(&part[..taken]);
            self.dropped += part.len() - taken;
            match end {
                Some(i) => {
                    emit(self.take());
                    bytes = &bytes[i..];
                }
                None => bytes = &[],
            }
        }
    }

    fn finish(&mut self, emit: impl FnOnce(String)) {
        if !self.line.is_empty() || self.dropped > 0 {
            emit(self.take());
        }
    }

    fn take(&mut self) -> String {
        if self.line.last() == Some(&b'\r') {
            self.line.pop();
        }
        let mut line = String::from_utf8_lossy(&self.line).into_owned();
        if self.dropped > 0 {
            line.push_str(&format!(" … ({} more bytes not shown)", self.dropped));
        }
        self.line.clear();
        self.dropped = 0;
        line
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
                let result = crate::Model::simulate_driven(
                    &model, &params, &grid, &outputs, &options, &inputs,
                );
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

fn read_frame(r: &mut impl Read) -> std::io::Result<Vec<u8>> {
    let mut len = [0u8; 4];
    r.read_exact(&mut len)?;
    let len = u32::from_le_bytes(len) as usize;
    if len > MAX_FRAME {
        return Err(std::io::Error::other("frame too long"));
    }
    let mut body = vec![0u8; len];
    r.read_exact(&mut body)?;
    Ok(body)
}

fn write_frame(w: &mut impl Write, body: &[u8]) -> std::io::Result<()> {
    let mut frame = Vec::with_capacity(4 + body.len());
    frame.extend_from_slice(&(body.len() as u32).to_le_bytes());
    frame.extend_from_slice(body);
    w.write_all(&frame)?;
    w.flush()
}

#[derive(Default)]
struct Writer(Vec<u8>);

impl Writer {
    fn u64(&mut self, v: u64) -> &mut Self {
        self.0.extend_from_slice(&v.to_le_bytes());
        self
    }
    fn f64(&mut self, v: f64) -> &mut Self {
        self.u64(v.to_bits())
    }
    fn f64s(&mut self, v: &[f64]) -> &mut Self {
        self.u64(v.len() as u64);
        for x in v {
            self.f64(*x);
        }
        self
    }
    fn text(&mut self, s: &str) -> &mut Self {
        self.u64(s.len() as u64);
        self.0.extend_from_slice(s.as_bytes());
        self
    }
}

struct Reader<'a>(&'a [u8]);

impl Reader<'_> {
    fn u64(&mut self) -> Option<u64> {
        let (head, rest) = self.0.split_at_checked(8)?;
        self.0 = rest;
        Some(u64::from_le_bytes(head.try_into().ok()?))
    }
    fn f64(&mut self) -> Option<f64> {
        self.u64().map(f64::from_bits)
    }
    fn len(&mut self) -> Option<usize> {
        let n = usize::try_from(self.u64()?).ok()?;
        (n <= self.0.len()).then_some(n)
    }
    fn f64s(&mut self) -> Option<Vec<f64>> {
        let n = self.len()?;
        (0..n).map(|_| self.f64()).collect()
    }
    fn text(&mut self) -> Option<String> {
        let n = self.len()?;
        let (head, rest) = self.0.split_at_checked(n)?;
        self.0 = rest;
        Some(String::from_utf8_lossy(head).into_owned())
    }
}

fn encode_request(
    params: &[f64],
    grid: &[f64],
    outputs: &[usize],
    options: &SolverOptions,
    inputs: &Inputs,
) -> Vec<u8> {
    let mut w = Writer::default();
    w.f64s(params).f64s(grid).u64(outputs.len() as u64);
    for o in outputs {
        w.u64(*o as u64);
    }
    w.f64(options.rtol)
        .f64(options.atol)
        .u64(options.max_steps as u64)
        .f64(options.start_time)
        .f64(options.communication_step.unwrap_or(0.0));
    // The signals, once per simulation: the child samples them at every step itself.
    w.u64(inputs.signals.len() as u64);
    for s in &inputs.signals {
        w.u64(s.input as u64)
            .u64(u64::from(s.interpolation.code()))
            .f64s(&s.times)
            .f64s(&s.values);
    }
    w.0
}

type Request = (Vec<f64>, Vec<f64>, Vec<usize>, SolverOptions, Inputs);

fn decode_request(frame: &[u8]) -> Option<Request> {
    let mut r = Reader(frame);
    let params = r.f64s()?;
    let grid = r.f64s()?;
    let n = r.len()?;
    let outputs = (0..n)
        .map(|_| r.u64().map(|o| o as usize))
        .collect::<Option<Vec<_>>>()?;
    let options = SolverOptions {
        rtol: r.f64()?,
        atol: r.f64()?,
        max_steps: r.u64()? as usize,
        start_time: r.f64()?,
        // 0: none (a communication step is positive).
        communication_step: Some(r.f64()?).filter(|h| *h != 0.0),
    };
    let n = r.len()?;
    let signals = (0..n)
        .map(|_| {
            Some(InputSignal {
                input: usize::try_from(r.u64()?).ok()?,
                interpolation: match r.u64()? {
                    0 => Interpolation::Linear,
                    1 => Interpolation::Hold,
                    _ => return None,
                },
                times: r.f64s()?.into(),
                values: r.f64s()?.into(),
            })
        })
        .collect::<Option<Vec<_>>>()?;
    Some((params, grid, outputs, options, Inputs { signals }))
}

fn encode_reply(result: &Result<Trajectory, SimulationError>) -> Vec<u8> {
    let mut w = Writer::default();
    match result {
        Ok(t) => {
            w.u64(0);
            let s = t.stats;
            for v in [
                s.accepted_steps,
                s.rejected_steps,
                s.rhs_evaluations,
                s.events,
            ] {
                w.u64(v as u64);
            }
            w.u64(t.values.len() as u64);
            for series in &t.values {
                w.f64s(series);
            }
        }
        Err(e) => {
            let (kind, time, count, span, text) = match e {
                SimulationError::StepLimit { limit, time } => (1, *time, *limit, 0.0, ""),
                SimulationError::StepTooSmall { time } => (2, *time, 0, 0.0, ""),
                SimulationError::Chattering {
                    time,
                    event,
                    events,
                    span,
                } => (3, *time, *events, *span, event.as_str()),
                SimulationError::Diverged { time } => (4, *time, 0, 0.0, ""),
                SimulationError::InvalidInput(m) => (5, 0.0, 0, 0.0, m.as_str()),
                SimulationError::Failed { time, reason } => (6, *time, 0, 0.0, reason.as_str()),
            };
            w.u64(kind).f64(time).u64(count as u64).f64(span).text(text);
        }
    }
    w.0
}

fn decode_reply(
    frame: &[u8],
    grid: &[f64],
) -> Result<Result<Trajectory, SimulationError>, FmuError> {
    let malformed = || FmuError::Host("malformed reply from the FMU host".into());
    let mut r = Reader(frame);
    let kind = r.u64().ok_or_else(malformed)?;
    if kind == 0 {
        let mut s = [0usize; 4];
        for v in &mut s {
            *v = r.u64().ok_or_else(malformed)? as usize;
        }
        let n = r.len().ok_or_else(malformed)?;
        let values = (0..n)
            .map(|_| r.f64s())
            .collect::<Option<Vec<_>>>()
            .ok_or_else(malformed)?;
        return Ok(Ok(Trajectory {
            time: grid.to_vec(),
            values,
            stats: SolverStats {
                accepted_steps: s[0],
                rejected_steps: s[1],
                rhs_evaluations: s[2],
                events: s[3],
            },
        }));
    }
    let time = r.f64().ok_or_else(malformed)?;
    let count = r.u64().ok_or_else(malformed)? as usize;
    let span = r.f64().ok_or_else(malformed)?;
    let text = r.text().ok_or_else(malformed)?;
    Ok(Err(match kind {
        1 => SimulationError::StepLimit { limit: count, time },
        2 => SimulationError::StepTooSmall { time },
        3 => SimulationError::Chattering {
            time,
            event: text,
            events: count,
            span,
        },
        4 => SimulationError::Diverged { time },
        5 => SimulationError::InvalidInput(text),
        6 => SimulationError::Failed { time, reason: text },
        _ => return Err(malformed()),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn output_is_cut_into_bounded_lines_across_reads() {
        let mut lines = Lines::default();
        let mut out = Vec::new();
        lines.push(b"one\r\ntw", |l| out.push(l));
        lines.push(b"o\n", |l| out.push(l));
        let long = vec![b'z'; LINE_MAX + 10];
        lines.push(&long, |l| out.push(l));
        lines.push(b"zz\nrest", |l| out.push(l));
        lines.finish(|l| out.push(l));
        assert_eq!(out.len(), 4, "{out:?}");
        assert_eq!((out[0].as_str(), out[1].as_str()), ("one", "two"));
        assert!(out[2].starts_with(&"z".repeat(LINE_MAX)));
        assert!(
            out[2].ends_with(" … (12 more bytes not shown)"),
            "{}",
            &out[2][LINE_MAX..]
        );
        assert_eq!(out[3], "rest");
        assert!(lines.line.capacity() <= 2 * LINE_MAX);
    }

    #[test]
    fn log_messages_warn_by_their_status_and_other_lines_by_their_stream() {
        assert!(!warns("[ok] logAll: fine", Stream::Stderr));
        assert!(warns("[warning] logStatusWarning: careful", Stream::Stdout));
        assert!(warns("[error] x: y", Stream::Stdout));
        assert!(!warns("printed", Stream::Stdout));
        assert!(warns("printed", Stream::Stderr));
        assert!(!warns("[note] printed", Stream::Stdout));
    }

    #[test]
    fn requests_and_replies_travel_bit_for_bit() {
        let options = SolverOptions {
            rtol: 1e-7,
            atol: 1e-9,
            max_steps: 1234,
            start_time: 0.5,
            communication_step: Some(1e-3),
        };
        let inputs = Inputs {
            signals: vec![
                InputSignal {
                    input: 1,
                    times: vec![0.0, 0.25, 0.5].into(),
                    values: vec![1.0 / 3.0, -0.0, 7.0].into(),
                    interpolation: Interpolation::Hold,
                },
                InputSignal {
                    input: 0,
                    times: vec![0.0].into(),
                    values: vec![2.5].into(),
                    interpolation: Interpolation::Linear,
                },
            ],
        };
        let (p, g, o, opts, i) = decode_request(&encode_request(
            &[0.1, f64::NAN],
            &[0.0, 0.5],
            &[2, 0],
            &options,
            &inputs,
        ))
        .unwrap();
        assert_eq!(
            (p[0], g, o, opts, i),
            (0.1, vec![0.0, 0.5], vec![2, 0], options, inputs)
        );
        assert!(p[1].is_nan());
        let t = Trajectory {
            time: vec![0.0, 1.0],
            values: vec![vec![1.0 / 3.0, -0.0]],
            stats: SolverStats {
                accepted_steps: 3,
                rejected_steps: 1,
                rhs_evaluations: 20,
                events: 2,
            },
        };
        let back = decode_reply(&encode_reply(&Ok(t.clone())), &t.time)
            .unwrap()
            .unwrap();
        assert_eq!(back, t);
        let e = SimulationError::Chattering {
            time: 1.5,
            event: "x".into(),
            events: 32,
            span: 1e-9,
        };
        let back = decode_reply(&encode_reply(&Err(e.clone())), &[]).unwrap();
        assert_eq!(back, Err(e));
    }
}
