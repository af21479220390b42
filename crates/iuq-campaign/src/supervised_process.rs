//! Running one command under supervision: in its own process group, with a wall-clock limit
//! enforced by SIGTERM to the whole group and, after a grace period, SIGKILL.
//!
//! The exit and the command's output are awaited with one `poll` on a pidfd and the stdout and
//! stderr pipes (no busy waiting, no latency) where the kernel has pidfds, else with a poll
//! timeout of a few milliseconds. Output goes to log files created only when there is output.
//! The child is inspected with `waitid(WNOWAIT)` before it is reaped, so that the process-group
//! id cannot be reused while stragglers of the group are killed.

use std::os::unix::process::{CommandExt, ExitStatusExt};
use std::path::Path;
use std::process::{Child, Command};
use std::sync::atomic::{AtomicI32, AtomicU32, Ordering};
use std::time::{Duration, Instant};

use crate::outcome::unix_now;

/// Slots of [`SUPERVISED_GROUPS`]: more commands than this at once in one process (a local
/// executor's `max_parallel`) are supervised as before but not reached by the signal handler.
const GROUP_SLOTS: usize = 1024;

/// Process groups of the commands this process supervises now (0: a free slot). Read by the
/// signal handler of [`forward_termination_signals`]; a slot is taken right after the spawn and
/// freed before the reap, while the group id cannot yet be reused.
static SUPERVISED_GROUPS: [AtomicU32; GROUP_SLOTS] = [const { AtomicU32::new(0) }; GROUP_SLOTS];

/// Takes a free slot for `group`; `None` when every slot is taken.
fn register_group(group: u32) -> Option<usize> {
    SUPERVISED_GROUPS.iter().position(|slot| {
        slot.compare_exchange(0, group, Ordering::SeqCst, Ordering::SeqCst)
            .is_ok()
    })
}

/// The signal the handler of [`forward_termination_signals`] received (0: none yet).
static TERMINATING: AtomicI32 = AtomicI32::new(0);

/// The termination signal this process is dying of, once the handler of
/// [`forward_termination_signals`] has run: the commands it stops then ended by the process's
/// stop, not by a fault of their own (the worker files their runs as lost, to be retried).
pub fn termination_signal() -> Option<i32> {
    Some(TERMINATING.load(Ordering::SeqCst)).filter(|&s| s != 0)
}

/// Sends `signal` to every supervised group; whether there was one. Async-signal-safe (`kill`
/// and lock-free atomic loads only), for [`forward_and_exit`].
fn signal_supervised_groups(signal: libc::c_int) -> bool {
    let mut any = false;
    for slot in &SUPERVISED_GROUPS {
        let group = slot.load(Ordering::SeqCst);
        if group != 0 {
            // SAFETY: kill is async-signal-safe and takes no pointers.
            unsafe {
                libc::kill(-(group as libc::pid_t), signal);
            }
            any = true;
        }
    }
    any
}

/// The handler of [`forward_termination_signals`]: the signal goes on to every supervised
/// group, which get a second to stop before SIGKILL, and then this process dies of it.
extern "C" fn forward_and_exit(signal: libc::c_int) {
    // SAFETY: kill, nanosleep, signal and raise are async-signal-safe; nothing else is called
    // (atomic loads are lock-free).
    unsafe {
        TERMINATING.store(signal, Ordering::SeqCst);
        if signal_supervised_groups(signal) {
            let grace = libc::timespec {
                tv_sec: 1,
                tv_nsec: 0,
            };
            libc::nanosleep(&grace, std::ptr::null_mut());
            signal_supervised_groups(libc::SIGKILL);
        }
        libc::signal(signal, libc::SIG_DFL);
        libc::raise(signal);
    }
}

/// Make SIGTERM, SIGINT and SIGHUP stop the supervised commands with this process. Each command
/// runs in a process group of its own, so a signal meant for this process (Ctrl-C in a terminal
/// reaches the foreground group only; a scheduler that stops a worker — HyperQueue's time
/// limit or cancel, Slurm's `scancel` — signals the worker's group; `kill` reaches one process)
/// would otherwise leave them running on, orphaned. For `iuq worker` and for the coordinator of
/// a local campaign; a later run of the campaign files the stopped runs as lost and retries them.
pub fn forward_termination_signals() {
    let handler = forward_and_exit as extern "C" fn(libc::c_int) as libc::sighandler_t;
    for signal in [libc::SIGTERM, libc::SIGINT, libc::SIGHUP] {
        // SAFETY: installs a handler that only calls async-signal-safe functions.
        unsafe {
            libc::signal(signal, handler);
        }
    }
}

/// How a supervised process ended.
#[derive(Debug, Clone, PartialEq)]
pub struct ProcessExit {
    /// Its process id (and process-group id).
    pub pid: u32,
    /// Exit status, when it exited.
    pub exit_code: Option<i32>,
    /// The signal that ended it, when one did.
    pub signal: Option<i32>,
    /// True when it ran past its timeout and was stopped.
    pub timed_out: bool,
    /// Start time, seconds since the Unix epoch.
    pub started_at: f64,
    /// End time, seconds since the Unix epoch.
    pub finished_at: f64,
}

/// The conventional name of a signal number (`SIGKILL`), or `signal N`.
pub fn signal_name(signal: i32) -> String {
    let name = match signal {
        libc::SIGHUP => "SIGHUP",
        libc::SIGINT => "SIGINT",
        libc::SIGQUIT => "SIGQUIT",
        libc::SIGILL => "SIGILL",
        libc::SIGABRT => "SIGABRT",
        libc::SIGBUS => "SIGBUS",
        libc::SIGFPE => "SIGFPE",
        libc::SIGKILL => "SIGKILL",
        libc::SIGSEGV => "SIGSEGV",
        libc::SIGPIPE => "SIGPIPE",
        libc::SIGALRM => "SIGALRM",
        libc::SIGTERM => "SIGTERM",
        libc::SIGUSR1 => "SIGUSR1",
        libc::SIGUSR2 => "SIGUSR2",
        libc::SIGXCPU => "SIGXCPU",
        _ => return format!("signal {signal}"),
    };
    name.to_string()
}

/// Sends `signal` to the process group `pgid`; errors (no such group) are ignored.
pub fn signal_group(pgid: u32, signal: i32) {
    if pgid > 1 {
        // SAFETY: kill(2) with a negative pid signals a process group; it has no memory effects.
        unsafe {
            libc::kill(-(pgid as libc::pid_t), signal);
        }
    }
}

/// True when the child has exited (a zombie not yet reaped), without reaping it.
fn has_exited(pid: u32) -> bool {
    // SAFETY: waitid writes only into the zeroed siginfo_t we own.
    unsafe {
        let mut info: libc::siginfo_t = std::mem::zeroed();
        let r = libc::waitid(
            libc::P_PID,
            pid as libc::id_t,
            &mut info,
            libc::WEXITED | libc::WNOWAIT | libc::WNOHANG,
        );
        r == 0 && info.si_pid() != 0
    }
}

/// A pidfd of the child (when the kernel has them), readable once the child has exited.
struct ExitWaiter {
    pidfd: Option<libc::c_int>,
}

impl ExitWaiter {
    fn new(pid: u32) -> Self {
        // SAFETY: pidfd_open takes a pid and flags and returns a new descriptor or -1.
        let fd = unsafe { libc::syscall(libc::SYS_pidfd_open, pid as libc::pid_t, 0) };
        Self {
            pidfd: (fd >= 0).then_some(fd as libc::c_int),
        }
    }
}

impl Drop for ExitWaiter {
    fn drop(&mut self) {
        if let Some(fd) = self.pidfd {
            // SAFETY: closing the descriptor pidfd_open gave us.
            unsafe {
                libc::close(fd);
            }
        }
    }
}

/// Where a supervised process's standard output and error go: files created only when the
/// process writes something (a silent command leaves no empty log files behind, which saves two
/// file creations per run).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct OutputLogs {
    /// The standard-output log.
    pub stdout: std::path::PathBuf,
    /// The standard-error log.
    pub stderr: std::path::PathBuf,
    /// Bytes of standard error kept in memory for [`Supervised::stderr_tail`].
    pub tail_bytes: usize,
}

/// A supervised process's end and the tail of its standard error.
#[derive(Debug, Clone, PartialEq)]
pub struct Supervised {
    /// How it ended.
    pub exit: ProcessExit,
    /// The last bytes of its standard error (lossy UTF-8).
    pub stderr_tail: String,
}

/// A log file created on first write.
struct LazyLog<'a> {
    path: &'a Path,
    file: Option<std::fs::File>,
    failed: bool,
}

impl LazyLog<'_> {
    fn write(&mut self, data: &[u8]) {
        use std::io::Write;
        if self.failed {
            return;
        }
        if self.file.is_none() {
            match std::fs::File::create(self.path) {
                Ok(f) => self.file = Some(f),
                Err(_) => {
                    self.failed = true;
                    return;
                }
            }
        }
        if let Some(f) = &mut self.file {
            if f.write_all(data).is_err() {
                self.failed = true;
            }
        }
    }
}

/// Spawn `command` in a new process group and wait for it, enforcing `timeout` (SIGTERM to the
/// group, then SIGKILL after `grace`), copying its standard output and error into `logs`.
/// `on_start` is called with the pid right after the spawn. After the command ends, any process
/// left in its group is killed.
pub fn run_supervised(
    command: &mut Command,
    timeout: Option<Duration>,
    grace: Duration,
    logs: &OutputLogs,
    on_start: impl FnOnce(u32),
) -> std::io::Result<Supervised> {
    command
        .process_group(0)
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped());
    let started_at = unix_now();
    let start = Instant::now();
    let mut child: Child = command.spawn()?;
    let pid = child.id();
    let slot = register_group(pid);
    on_start(pid);
    let pipes = [
        child.stdout.take().map(|p| Box::new(p) as Box<dyn ReadFd>),
        child.stderr.take().map(|p| Box::new(p) as Box<dyn ReadFd>),
    ];
    let mut supervision = Supervision {
        pid,
        grace,
        logs,
        pipes,
        out_log: LazyLog {
            path: &logs.stdout,
            file: None,
            failed: false,
        },
        err_log: LazyLog {
            path: &logs.stderr,
            file: None,
            failed: false,
        },
        tail: Vec::new(),
        waiter: ExitWaiter::new(pid),
        timed_out: false,
        deadline: timeout.map(|t| start + t),
        killed: false,
        exited: false,
        drain_until: None,
        buf: vec![0u8; 64 * 1024],
    };
    while !supervision.finished() {
        supervision.poll_once();
    }
    drop(supervision.pipes);
    signal_group(pid, libc::SIGKILL);
    drop(supervision.waiter);
    // Before the reap: the group id cannot be reused while the handler may still signal it.
    if let Some(slot) = slot {
        SUPERVISED_GROUPS[slot].store(0, Ordering::SeqCst);
    }
    let status = child.wait()?;
    let mut tail = supervision.tail;
    if tail.len() > logs.tail_bytes {
        tail.drain(..tail.len() - logs.tail_bytes);
    }
    Ok(Supervised {
        exit: ProcessExit {
            pid,
            exit_code: status.code(),
            signal: status.signal(),
            timed_out: supervision.timed_out,
            started_at,
            finished_at: unix_now(),
        },
        stderr_tail: String::from_utf8_lossy(&tail).into_owned(),
    })
}

/// The descriptors of one `poll`: the open pipes, then the pidfd while the child runs.
struct PollSet {
    fds: Vec<libc::pollfd>,
    /// The pipe (0 stdout, 1 stderr) of each of the first entries of `fds`.
    which: Vec<usize>,
    /// The entry of the pidfd, if it is polled.
    pidfd_slot: Option<usize>,
}

/// The state of [`run_supervised`] while it waits for a spawned child: its pipes and logs, its
/// deadline, and how far its end has come.
struct Supervision<'a> {
    pid: u32,
    grace: Duration,
    logs: &'a OutputLogs,
    pipes: [Option<Box<dyn ReadFd>>; 2],
    out_log: LazyLog<'a>,
    err_log: LazyLog<'a>,
    /// The last bytes of standard error (up to twice `logs.tail_bytes` between trims).
    tail: Vec<u8>,
    waiter: ExitWaiter,
    timed_out: bool,
    /// When the timeout, then the grace period after SIGTERM, runs out.
    deadline: Option<Instant>,
    killed: bool,
    exited: bool,
    /// After the exit: how long the pipes are still read.
    drain_until: Option<Instant>,
    buf: Vec<u8>,
}

impl Supervision<'_> {
    /// The child has exited and its pipes are closed, or the drain time after its exit is up.
    fn finished(&self) -> bool {
        (self.exited && self.pipes.iter().all(Option::is_none))
            || self.drain_until.is_some_and(|d| Instant::now() >= d)
    }

    /// One `poll` and what follows it: output copied, the exit noticed, the timeout enforced.
    fn poll_once(&mut self) {
        let mut set = self.poll_set();
        let wait_ms = self.wait_ms(Instant::now());
        // SAFETY: poll on pollfds we own; every descriptor stays open during the call.
        let r = unsafe {
            libc::poll(
                set.fds.as_mut_ptr(),
                set.fds.len() as libc::nfds_t,
                wait_ms.clamp(-1, i32::MAX as i64) as i32,
            )
        };
        if r < 0 && std::io::Error::last_os_error().kind() != std::io::ErrorKind::Interrupted {
            std::thread::sleep(Duration::from_millis(5));
        }
        self.read_ready_pipes(&set, r);
        let pidfd_ready = set
            .pidfd_slot
            .is_some_and(|i| r > 0 && set.fds[i].revents != 0);
        self.notice_exit(pidfd_ready);
        self.enforce_deadline();
    }

    fn poll_set(&self) -> PollSet {
        let mut fds: Vec<libc::pollfd> = Vec::with_capacity(3);
        let mut which: Vec<usize> = Vec::with_capacity(3);
        for (k, p) in self.pipes.iter().enumerate() {
            if let Some(p) = p {
                fds.push(libc::pollfd {
                    fd: p.raw_fd(),
                    events: libc::POLLIN,
                    revents: 0,
                });
                which.push(k);
            }
        }
        let pidfd_slot = match (self.exited, self.waiter.pidfd) {
            (false, Some(fd)) => {
                fds.push(libc::pollfd {
                    fd,
                    events: libc::POLLIN,
                    revents: 0,
                });
                Some(fds.len() - 1)
            }
            _ => None,
        };
        PollSet {
            fds,
            which,
            pidfd_slot,
        }
    }

    /// The poll timeout in milliseconds (−1: none): up to the deadline, a few milliseconds
    /// without a pidfd, and no later than the end of the drain.
    fn wait_ms(&self, now: Instant) -> i64 {
        let mut wait_ms: i64 = -1;
        if let Some(d) = self.deadline.filter(|_| !self.exited) {
            let left = d.saturating_duration_since(now);
            wait_ms = left.as_millis() as i64 + 1;
        }
        if !self.exited && self.waiter.pidfd.is_none() {
            wait_ms = if wait_ms < 0 { 5 } else { wait_ms.min(5) };
        }
        if let Some(d) = self.drain_until {
            let left = d.saturating_duration_since(now).as_millis() as i64 + 1;
            wait_ms = if wait_ms < 0 { left } else { wait_ms.min(left) };
        }
        wait_ms
    }

    /// Copies what the pipes `poll` found readable into the logs (and standard error's tail);
    /// a pipe at its end is closed.
    fn read_ready_pipes(&mut self, set: &PollSet, r: libc::c_int) {
        use std::io::Read;
        for (slot, &k) in set.which.iter().enumerate() {
            if r > 0 && set.fds[slot].revents != 0 {
                let n = match self.pipes[k].as_mut().map(|p| p.read(&mut self.buf)) {
                    Some(Ok(n)) => n,
                    Some(Err(e)) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                    _ => 0,
                };
                if n == 0 {
                    self.pipes[k] = None;
                } else if k == 0 {
                    self.out_log.write(&self.buf[..n]);
                } else {
                    self.err_log.write(&self.buf[..n]);
                    self.tail.extend_from_slice(&self.buf[..n]);
                    let tail_bytes = self.logs.tail_bytes;
                    if self.tail.len() > 2 * tail_bytes.max(1) {
                        self.tail.drain(..self.tail.len() - tail_bytes);
                    }
                }
            }
        }
    }

    fn notice_exit(&mut self, pidfd_ready: bool) {
        if !self.exited && (pidfd_ready || self.waiter.pidfd.is_none()) && has_exited(self.pid) {
            self.exited = true;
            // The leader is a zombie: its pid still names the group, so stragglers (which may
            // hold the pipes open) can be killed safely.
            signal_group(self.pid, libc::SIGKILL);
            self.drain_until = Some(Instant::now() + Duration::from_secs(2));
        }
    }

    /// Past the deadline of a running child: SIGTERM to its group, and SIGKILL once the grace
    /// period has run out too.
    fn enforce_deadline(&mut self) {
        if !self.exited && self.deadline.is_some_and(|d| Instant::now() >= d) {
            if !self.timed_out {
                self.timed_out = true;
                signal_group(self.pid, libc::SIGTERM);
                self.deadline = Some(Instant::now() + self.grace);
            } else if !self.killed {
                self.killed = true;
                signal_group(self.pid, libc::SIGKILL);
                self.deadline = None;
            }
        }
    }
}

/// A readable pipe with its descriptor.
trait ReadFd: std::io::Read {
    fn raw_fd(&self) -> libc::c_int;
}

impl ReadFd for std::process::ChildStdout {
    fn raw_fd(&self) -> libc::c_int {
        std::os::unix::io::AsRawFd::as_raw_fd(self)
    }
}

impl ReadFd for std::process::ChildStderr {
    fn raw_fd(&self) -> libc::c_int {
        std::os::unix::io::AsRawFd::as_raw_fd(self)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(
        script: &str,
        timeout: Option<Duration>,
        grace: Duration,
        logs: &OutputLogs,
    ) -> ProcessExit {
        run_supervised(
            Command::new("sh").args(["-c", script]),
            timeout,
            grace,
            logs,
            |_| {},
        )
        .unwrap()
        .exit
    }

    fn logs(name: &str) -> OutputLogs {
        let dir = std::env::temp_dir();
        OutputLogs {
            stdout: dir.join(format!("iuq-sp-{}-{name}.out", std::process::id())),
            stderr: dir.join(format!("iuq-sp-{}-{name}.err", std::process::id())),
            tail_bytes: 16,
        }
    }

    #[test]
    fn output_is_logged_lazily_and_the_stderr_tail_kept() {
        let l = logs("lazy");
        let _ = std::fs::remove_file(&l.stdout);
        let _ = std::fs::remove_file(&l.stderr);
        let s = run_supervised(
            &mut Command::new("true"),
            None,
            Duration::from_millis(100),
            &l,
            |_| {},
        )
        .unwrap();
        assert_eq!(s.exit.exit_code, Some(0));
        assert!(!l.stdout.exists() && !l.stderr.exists());
        let s = run_supervised(
            Command::new("sh").args(["-c", "echo out; echo 0123456789abcdefXYZ >&2"]),
            None,
            Duration::from_millis(100),
            &l,
            |_| {},
        )
        .unwrap();
        assert_eq!(std::fs::read_to_string(&l.stdout).unwrap(), "out\n");
        assert_eq!(
            std::fs::read_to_string(&l.stderr).unwrap(),
            "0123456789abcdefXYZ\n"
        );
        assert_eq!(s.stderr_tail, "456789abcdefXYZ\n");
        // A background process holding the pipes open does not keep the run alive.
        let t = Instant::now();
        let s = run_supervised(
            Command::new("sh").args(["-c", "sleep 30 & echo started"]),
            None,
            Duration::from_millis(100),
            &l,
            |_| {},
        )
        .unwrap();
        assert_eq!(s.exit.exit_code, Some(0));
        assert!(t.elapsed() < Duration::from_secs(5));
        let _ = std::fs::remove_file(&l.stdout);
        let _ = std::fs::remove_file(&l.stderr);
    }

    #[test]
    fn exit_codes_signals_and_timeouts() {
        let grace = Duration::from_millis(300);
        let l = logs("exits");
        let e = run("exit 3", None, grace, &l);
        assert_eq!((e.exit_code, e.signal, e.timed_out), (Some(3), None, false));
        let e = run("kill -SEGV $$", None, grace, &l);
        assert_eq!((e.exit_code, e.signal), (None, Some(libc::SIGSEGV)));
        let t = Instant::now();
        let e = run("sleep 30", Some(Duration::from_millis(200)), grace, &l);
        assert!(e.timed_out && e.signal == Some(libc::SIGTERM), "{e:?}");
        assert!(t.elapsed() < Duration::from_secs(5));
        // A command that ignores SIGTERM is killed after the grace period.
        let e = run(
            "trap '' TERM; while :; do sleep 0.05; done",
            Some(Duration::from_millis(200)),
            grace,
            &l,
        );
        assert!(e.timed_out && e.signal == Some(libc::SIGKILL), "{e:?}");
        assert_eq!(signal_name(9), "SIGKILL");
    }
}
