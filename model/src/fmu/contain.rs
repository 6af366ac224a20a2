//! Keeping an FMU's code to its own processes and folder (Linux).
//!
//! The host program the worker starts ([`super::host`]) is a *supervisor* that runs no FMU
//! code: it starts in a session and process group of its own, dies with the thread that
//! started it (`PR_SET_PDEATHSIG`), and makes itself the reaper of every orphan below it
//! (`PR_SET_CHILD_SUBREAPER`). It starts the same program again as the FMU's process
//! (the *inner* one, [`INNER`]), in a private working folder, and waits. When the inner
//! process ends, or the supervisor is told to stop (SIGTERM: the deadline passed, the
//! worker dropped the FMU, the worker exited), it kills the inner process and then every
//! process left below it (a child that `fork`ed, `setsid`ed or double-forked is still its
//! descendant, and an orphan comes back to it), removes the working folder and exits as
//! the inner process did.
//!
//! The inner process (its `TMPDIR` the working folder too), before it loads the FMU's
//! library, bounds its address space and CPU
//! time (`setrlimit`) and, where the kernel has Landlock, confines its files: it may
//! write in its working folder alone, and read the unpacked FMU and the system's folders
//! (`/usr`, `/lib*`, `/etc`, `/opt`, `/proc`, `/sys`, `/dev`), nothing else. Landlock (ABI
//! 6 and later) also keeps it from signalling processes outside it. Without Landlock the
//! rest holds and the files are not confined; [`containment`] says which.

use crate::limits;
use std::io;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::sync::{mpsc, OnceLock};
use std::time::{Duration, Instant};

/// Set in the environment of the FMU's own process (the inner one).
pub const INNER: &str = "CALIB_FMU_HOST_INNER";
/// How long a supervisor told to stop may take before its whole group is killed.
const STOP_GRACE: Duration = Duration::from_secs(5);
/// Rounds of killing what is left below a supervisor (each round kills the processes that
/// became its children since the last).
const KILL_ROUNDS: usize = 10_000;

/// What confines an FMU's code on this machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Containment {
    /// The Landlock ABI the kernel offers, if any.
    pub landlock_abi: Option<i32>,
}

impl std::fmt::Display for Containment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "each FMU runs in a process group of its own, killed as a group at its deadline or \
             when the worker exits, in a private working folder, with its memory and CPU time \
             bounded; "
        )?;
        match self.landlock_abi {
            Some(abi) => write!(
                f,
                "its file access is confined by Landlock (ABI {abi}): writes to its working \
                 folder, reads to the FMU and the system's folders"
            ),
            None => write!(
                f,
                "this kernel has no Landlock: the FMU's file access is NOT confined (it may \
                 read and write whatever this user may)"
            ),
        }
    }
}

/// What confines an FMU's code on this machine (a probe of the kernel).
pub fn containment() -> Containment {
    static PROBED: OnceLock<Containment> = OnceLock::new();
    *PROBED.get_or_init(|| {
        // landlock_create_ruleset(NULL, 0, LANDLOCK_CREATE_RULESET_VERSION) answers the ABI.
        // SAFETY: a query that takes no pointer.
        let abi = unsafe {
            libc::syscall(
                libc::SYS_landlock_create_ruleset,
                std::ptr::null::<libc::c_void>(),
                0usize,
                1u32,
            )
        };
        Containment {
            landlock_abi: (abi > 0).then_some(abi as i32),
        }
    })
}

/// Start `command` as a supervisor: in a new session and process group, sent SIGTERM when
/// the thread that started it ends. Every supervisor is started by one thread kept for
/// that, which lives as long as the process: the death signal follows the thread that
/// forked, and a worker's simulation threads come and go.
pub fn spawn_supervisor(mut command: Command) -> io::Result<std::process::Child> {
    // SAFETY: only async-signal-safe calls between fork and exec.
    unsafe {
        let parent = libc::getpid();
        command.pre_exec(move || {
            if libc::setsid() < 0 {
                return Err(io::Error::last_os_error());
            }
            if libc::prctl(
                libc::PR_SET_PDEATHSIG,
                libc::SIGTERM as libc::c_ulong,
                0,
                0,
                0,
            ) < 0
            {
                return Err(io::Error::last_os_error());
            }
            // The parent died before the death signal was asked for.
            if libc::getppid() != parent {
                return Err(io::Error::other("the worker ended"));
            }
            Ok(())
        });
    }
    type Job = (Command, mpsc::Sender<io::Result<std::process::Child>>);
    static KEEPER: OnceLock<mpsc::Sender<Job>> = OnceLock::new();
    let keeper = KEEPER.get_or_init(|| {
        let (send, jobs) = mpsc::channel::<Job>();
        std::thread::Builder::new()
            .name("fmu-host-starter".into())
            .spawn(move || {
                for (mut command, reply) in jobs {
                    let _ = reply.send(command.spawn());
                }
            })
            .expect("a thread to start FMU hosts");
        send
    });
    let (reply, answer) = mpsc::channel();
    keeper
        .send((command, reply))
        .map_err(|_| io::Error::other("the FMU host starter is gone"))?;
    answer
        .recv()
        .map_err(|_| io::Error::other("the FMU host starter is gone"))?
}

/// Stop a supervisor: ask it (SIGTERM) to kill its FMU's processes and clean up, give it
/// [`STOP_GRACE`], then kill whatever is left of its process group, and reap it.
///
/// `ending` is how long it may take to end by itself first: a supervisor whose FMU's
/// process ended (its answers stopped) is already cleaning up and then exits the way that
/// process did (a crash's signal); asked to stop meanwhile, it would report the request
/// instead of the crash.
pub fn stop_supervisor(
    process: &mut std::process::Child,
    ending: Duration,
) -> io::Result<ExitStatus> {
    let pid = process.id() as libc::pid_t;
    // SAFETY: plain system calls on our own child, which is not reaped before the end of
    // this function (so its pid, the group's id, is not reused meanwhile).
    unsafe {
        let mut state = exited_within(pid, ending);
        if state == Exit::Running {
            libc::kill(pid, libc::SIGTERM);
            state = exited_within(pid, STOP_GRACE);
        }
        if state != Exit::ReapedElsewhere {
            libc::killpg(pid, libc::SIGKILL);
        }
    }
    process.wait()
}

/// What became of a child while [`exited_within`] waited.
#[derive(Debug, PartialEq, Eq)]
enum Exit {
    Running,
    Exited,
    ReapedElsewhere,
}

/// Wait up to `within` for the child `pid` to exit, without reaping it (`WNOWAIT`: its pid,
/// the group's id, stays reserved).
///
/// # Safety
/// `pid` is a child of this process not reaped before the caller is done with its group.
unsafe fn exited_within(pid: libc::pid_t, within: Duration) -> Exit {
    let until = Instant::now() + within;
    loop {
        let mut info: libc::siginfo_t = std::mem::zeroed();
        let r = libc::waitid(
            libc::P_PID,
            pid as libc::id_t,
            &mut info,
            libc::WEXITED | libc::WNOHANG | libc::WNOWAIT,
        );
        if r != 0 {
            return Exit::ReapedElsewhere;
        }
        if info.si_pid() != 0 {
            return Exit::Exited;
        }
        if Instant::now() >= until {
            return Exit::Running;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// The supervisor's side (see the module documentation): start this program again as the
/// FMU's process, handing it `channel` (the descriptor of the channel to the worker, which
/// the supervisor then closes) and its stdout and stderr, wait, clean up and exit as it did.
pub fn supervise(channel: libc::c_int) -> ! {
    // SAFETY: plain system calls; this process runs a single thread.
    unsafe {
        libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0);
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for signal in [libc::SIGTERM, libc::SIGINT, libc::SIGHUP, libc::SIGCHLD] {
            libc::sigaddset(&mut set, signal);
        }
        libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut());
        let workdir = match private_folder() {
            Ok(dir) => dir,
            Err(e) => {
                eprintln!("cannot make the FMU's working folder: {e}");
                libc::_exit(1);
            }
        };
        let inner = start_inner(&workdir);
        // Only the FMU's process answers on the channel: let go of it, so that the worker
        // sees its end when that process ends. (Its stdout and stderr stay open here: they
        // end when this process does, after the last of the FMU's processes.)
        libc::close(channel);
        let ended = wait_for(inner, &set);
        if ended.is_none() {
            libc::kill(inner, libc::SIGKILL);
            let mut status = 0;
            libc::waitpid(inner, &mut status, 0);
        }
        kill_descendants();
        let _ = std::fs::remove_dir_all(&workdir);
        exit_as(ended)
    }
}

/// Start this program again as the FMU's process, in `workdir`, killed when the supervisor
/// ends; its pid. A start that fails ends the supervisor.
///
/// # Safety
/// Plain system calls, in a process that runs a single thread.
unsafe fn start_inner(workdir: &Path) -> libc::pid_t {
    let me = libc::getpid();
    let mut command = Command::new("/proc/self/exe");
    command
        .args(std::env::args_os().skip(1))
        .env(INNER, "1")
        .env("TMPDIR", workdir)
        .current_dir(workdir);
    command.pre_exec(move || {
        let mut none: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut none);
        libc::pthread_sigmask(libc::SIG_SETMASK, &none, std::ptr::null_mut());
        if libc::prctl(
            libc::PR_SET_PDEATHSIG,
            libc::SIGKILL as libc::c_ulong,
            0,
            0,
            0,
        ) < 0
            || libc::getppid() != me
        {
            return Err(io::Error::other("the FMU host ended"));
        }
        Ok(())
    });
    match command.spawn() {
        Ok(child) => child.id() as libc::pid_t,
        Err(e) => {
            eprintln!("cannot start the FMU's process: {e}");
            let _ = std::fs::remove_dir_all(workdir);
            libc::_exit(1);
        }
    }
}

/// Wait until the FMU's process `inner` ends (its wait status) or a stop signal of `set`
/// arrives (`None`, unless the process had ended already).
///
/// # Safety
/// Plain system calls, in a process that runs a single thread, with `set` blocked.
unsafe fn wait_for(inner: libc::pid_t, set: &libc::sigset_t) -> Option<libc::c_int> {
    let mut ended: Option<libc::c_int> = None;
    'wait: loop {
        let signal = libc::sigwaitinfo(set, std::ptr::null_mut());
        if signal == libc::SIGCHLD {
            loop {
                let mut status = 0;
                let pid = libc::waitpid(-1, &mut status, libc::WNOHANG);
                if pid <= 0 {
                    break;
                }
                if pid == inner {
                    ended = Some(status);
                    break 'wait;
                }
            }
        } else if signal > 0 {
            // Told to stop; the FMU's process may have ended already (its SIGCHLD still
            // pending behind the lower-numbered stop signal): report that end, not the
            // request.
            let mut status = 0;
            if libc::waitpid(inner, &mut status, libc::WNOHANG) == inner {
                ended = Some(status);
            }
            break;
        }
    }
    ended
}

/// End as the FMU's process did (its exit code, or its signal without a core dump), or as
/// stopped (143) when it did not end by itself.
///
/// # Safety
/// Plain system calls, in a process that runs a single thread.
unsafe fn exit_as(ended: Option<libc::c_int>) -> ! {
    match ended {
        Some(status) if libc::WIFEXITED(status) => libc::_exit(libc::WEXITSTATUS(status)),
        Some(status) if libc::WIFSIGNALED(status) => {
            // End as the FMU's process did, for the worker to report (no core dump).
            let signal = libc::WTERMSIG(status);
            let none = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            libc::setrlimit(libc::RLIMIT_CORE, &none);
            libc::signal(signal, libc::SIG_DFL);
            let mut only: libc::sigset_t = std::mem::zeroed();
            libc::sigemptyset(&mut only);
            libc::sigaddset(&mut only, signal);
            libc::pthread_sigmask(libc::SIG_UNBLOCK, &only, std::ptr::null_mut());
            libc::raise(signal);
            libc::_exit(128 + signal)
        }
        _ => libc::_exit(143),
    }
}

/// A new folder only this user may enter, in the temporary folder.
fn private_folder() -> io::Result<PathBuf> {
    use std::os::unix::fs::DirBuilderExt;
    let base = std::env::temp_dir();
    let pid = std::process::id();
    for attempt in 0..100u32 {
        let dir = base.join(format!("calib-fmu-run-{pid}-{attempt}"));
        match std::fs::DirBuilder::new().mode(0o700).create(&dir) {
            Ok(()) => return Ok(dir),
            Err(e) if e.kind() == io::ErrorKind::AlreadyExists => continue,
            Err(e) => return Err(e),
        }
    }
    Err(io::Error::other(
        "no free name for the FMU's working folder",
    ))
}

/// The processes whose parent is `parent` (from `/proc`).
fn children_of(parent: libc::pid_t) -> Vec<libc::pid_t> {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return Vec::new();
    };
    entries
        .filter_map(|e| e.ok()?.file_name().to_str()?.parse::<libc::pid_t>().ok())
        .filter(|&pid| {
            std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|stat| {
                // `pid (comm) state ppid …`, where comm may hold anything.
                stat.rsplit_once(')')
                    .and_then(|(_, rest)| rest.split_whitespace().nth(1)?.parse().ok())
                    == Some(parent)
            })
        })
        .collect()
}

/// Kill every process below this one, round after round: the orphans of a killed process
/// come back to this one (a subreaper), to be killed in the next round.
fn kill_descendants() {
    // SAFETY: plain system calls on this process's own children.
    unsafe {
        let me = libc::getpid();
        for _ in 0..KILL_ROUNDS {
            let children = children_of(me);
            if children.is_empty() {
                break;
            }
            for &pid in &children {
                libc::kill(pid, libc::SIGKILL);
            }
            for &pid in &children {
                libc::waitpid(pid, std::ptr::null_mut(), 0);
            }
        }
        while libc::waitpid(-1, std::ptr::null_mut(), libc::WNOHANG) > 0 {}
    }
}

/// The FMU's process, after each simulation: kill every process the simulation left
/// running below it (a child it forked, and every orphan of one, which comes back to this
/// process, a subreaper since [`confine`]) and reap them. How many there were: an instance
/// that had processes running may count on them, so it is not used again.
pub fn reap_leftovers() -> usize {
    let mut killed = 0;
    // SAFETY: plain system calls on this process's own children.
    unsafe {
        for _ in 0..KILL_ROUNDS {
            let children = own_children();
            if children.is_empty() {
                break;
            }
            for &pid in &children {
                libc::kill(pid, libc::SIGKILL);
            }
            for &pid in &children {
                libc::waitpid(pid, std::ptr::null_mut(), 0);
            }
            killed += children.len();
        }
        while libc::waitpid(-1, std::ptr::null_mut(), libc::WNOHANG) > 0 {}
    }
    killed
}

/// This process's children, from each of its threads' `children` lists (a few small
/// files; every process's `stat` is read only where the kernel lists no children).
fn own_children() -> Vec<libc::pid_t> {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return children_of(std::process::id() as libc::pid_t);
    };
    let mut children = Vec::new();
    for task in tasks.flatten() {
        match std::fs::read_to_string(task.path().join("children")) {
            Ok(list) => children.extend(
                list.split_whitespace()
                    .filter_map(|p| p.parse::<libc::pid_t>().ok()),
            ),
            Err(_) => return children_of(std::process::id() as libc::pid_t),
        }
    }
    children.sort_unstable();
    children.dedup();
    children
}

/// The address space the FMU's process may have [bytes]: `CALIB_FMU_MEMORY_MIB`, or
/// [`limits::FMU_HOST_MEMORY_BYTES`].
pub fn memory_limit() -> u64 {
    std::env::var("CALIB_FMU_MEMORY_MIB")
        .ok()
        .and_then(|s| s.trim().parse::<u64>().ok())
        .filter(|&mib| mib > 0)
        .map_or(limits::FMU_HOST_MEMORY_BYTES, |mib| {
            mib.saturating_mul(1 << 20)
        })
}

/// The inner process's side, before the FMU's library is loaded: bound its memory, make no
/// core dumps, and confine its files to `workdir` (writes) and `fmu` and the system's
/// folders (reads) where the kernel has Landlock.
pub fn confine(fmu: &Path, workdir: &Path) {
    // Orphans of the processes the FMU starts come back here, to be reaped after each
    // simulation ([`reap_leftovers`]).
    // SAFETY: a plain system call on this process.
    unsafe { libc::prctl(libc::PR_SET_CHILD_SUBREAPER, 1, 0, 0, 0) };
    set_limit(libc::RLIMIT_AS, memory_limit());
    set_limit(libc::RLIMIT_CORE, 0);
    if let Err(e) = confine_files(fmu, workdir) {
        eprintln!("calib: the FMU's file access is not confined: {e}");
    }
}

/// Lower the soft limit of `resource` to `value` (never above the hard limit).
fn set_limit(resource: libc::__rlimit_resource_t, value: u64) {
    // SAFETY: plain system calls on this process.
    unsafe {
        let mut current: libc::rlimit = std::mem::zeroed();
        if libc::getrlimit(resource, &mut current) != 0 {
            return;
        }
        let value = value.min(current.rlim_max);
        let hard = if resource == libc::RLIMIT_CPU {
            current.rlim_max
        } else {
            value
        };
        libc::setrlimit(
            resource,
            &libc::rlimit {
                rlim_cur: value,
                rlim_max: hard,
            },
        );
    }
}

/// Allow `seconds` more CPU time to the simulation about to run in this process (the soft
/// `RLIMIT_CPU`: past it the kernel sends SIGXCPU, which ends the process).
pub fn allow_cpu(seconds: f64) {
    // SAFETY: plain system calls on this process.
    let used = unsafe {
        let mut usage: libc::rusage = std::mem::zeroed();
        libc::getrusage(libc::RUSAGE_SELF, &mut usage);
        (usage.ru_utime.tv_sec + usage.ru_stime.tv_sec) as u64
    };
    set_limit(libc::RLIMIT_CPU, used + seconds.ceil() as u64 + 1);
}

fn confine_files(fmu: &Path, workdir: &Path) -> Result<(), landlock::RulesetError> {
    use landlock::{
        path_beneath_rules, Access, AccessFs, Ruleset, RulesetAttr, RulesetCreatedAttr, Scope, ABI,
    };
    let abi = ABI::V6;
    let readable: Vec<&Path> = [
        fmu,
        Path::new("/usr"),
        Path::new("/lib"),
        Path::new("/lib32"),
        Path::new("/lib64"),
        Path::new("/bin"),
        Path::new("/etc"),
        Path::new("/opt"),
        Path::new("/proc"),
        Path::new("/sys"),
        Path::new("/dev"),
    ]
    .into_iter()
    .filter(|p| p.exists())
    .collect();
    // Without Landlock the ruleset is not enforced, silently here: the worker says so
    // once ([`containment`]), not each FMU process in the FMU's messages.
    Ruleset::default()
        .handle_access(AccessFs::from_all(abi))?
        .scope(Scope::from_all(abi))?
        .create()?
        .add_rules(path_beneath_rules(readable, AccessFs::from_read(abi)))?
        .add_rules(path_beneath_rules([workdir], AccessFs::from_all(abi)))?
        .add_rules(path_beneath_rules(
            [Path::new("/dev/null")],
            AccessFs::from_file(abi),
        ))?
        .restrict_self()?;
    Ok(())
}
