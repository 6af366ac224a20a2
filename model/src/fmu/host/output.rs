//! The child's stdout and stderr, followed as they come: cut into bounded lines, logged
//! (at most [`LINES_LOGGED`] per simulation), the last ones kept to explain a crash.

use super::*;

/// Which of a child's output streams a line came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Stream {
    Stdout,
    Stderr,
}

/// What a child writes on its stdout and stderr: logged as it comes, the last lines kept.
pub(super) struct Output {
    pub(super) name: String,
    pub(super) pipes: Vec<Mutex<Pipe>>,
    pub(super) kept: Mutex<VecDeque<String>>,
    /// Lines logged since the last request.
    pub(super) logged: AtomicUsize,
    /// Pipes whose reader has not yet seen their end.
    pub(super) open: Mutex<usize>,
    pub(super) closed: Condvar,
}

/// One of a child's output pipes (non-blocking), with the line it is in the middle of.
pub(super) struct Pipe {
    pub(super) file: std::fs::File,
    pub(super) stream: Stream,
    pub(super) lines: Lines,
    pub(super) ended: bool,
}

/// Most bytes read from a pipe by [`Output::catch_up`] at once (what a process the FMU
/// left behind writes meanwhile is read by the pipe's own thread).
pub(super) const CATCH_UP_MAX: usize = 64 << 20;

impl Output {
    pub(super) fn new(name: String, pipes: [(std::os::fd::OwnedFd, Stream); 2]) -> Self {
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
    pub(super) fn follow(&self, index: usize) {
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

    pub(super) fn pipe(&self, index: usize) -> std::sync::MutexGuard<'_, Pipe> {
        self.pipes[index].lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Read what `pipe` holds now (at most `max` bytes), line by line; whether it has not
    /// ended.
    pub(super) fn drain(&self, pipe: &mut Pipe, max: usize) -> bool {
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
    pub(super) fn catch_up(&self) {
        for index in 0..self.pipes.len() {
            let mut pipe = self.pipe(index);
            if !pipe.ended {
                self.drain(&mut pipe, CATCH_UP_MAX);
            }
        }
    }

    pub(super) fn line(&self, line: String, stream: Stream) {
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
    pub(super) fn wait_closed(&self, within: Duration) {
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
pub(super) fn warns(line: &str, stream: Stream) -> bool {
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
pub(super) struct Lines {
    pub(super) line: Vec<u8>,
    pub(super) dropped: usize,
}

impl Lines {
    pub(super) fn push(&mut self, mut bytes: &[u8], mut emit: impl FnMut(String)) {
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

    pub(super) fn finish(&mut self, emit: impl FnOnce(String)) {
        if !self.line.is_empty() || self.dropped > 0 {
            emit(self.take());
        }
    }

    pub(super) fn take(&mut self) -> String {
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
}
