//! Warm starts for the workers of a suite's Python environment: a fork server per
//! environment and adapter, started on first use and kept for this process's later sessions.
//!
//! A suite's worker spends most of its start importing the suite (Meta-World: mujoco,
//! Gymnasium's MuJoCo envs, its own tasks). The fork server (`python -m envhub.worker
//! forkserver`, started exactly as a worker is: same interpreter, variables, bootstrap and
//! hold on the environment) imports it once; each worker is then a `fork` of it that makes
//! its envs and serves them. The server lives in this process's user and hub (the embedded
//! hub of one program, or an `envhub serve` daemon, which only its own user reaches), so it
//! is never shared across users, and workers keep every check of a cold start (the ready line
//! read from a FIFO only this hub can open, the identity check of the provisioned
//! environment). Its workers are not this process's children: they are held by pidfds, as a
//! daemon's workers are, and their exit status stays with the server. A daemon's clients
//! accept a worker whose parent is a fork server of the daemon.

use crate::python_host::UserAdapters;
use envhub_protocol::HubError;
use envhub_shm::{PidFd, ReadySpec, WorkerJob, WorkerReply};
use std::collections::HashMap;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::process::CommandExt;
use std::process::{Child, ChildStdin, Stdio};
use std::sync::{Arc, Mutex, mpsc};
use std::time::{Duration, Instant};

/// How long a fork request may take to be answered with the child's pid.
const FORK_TIMEOUT: Duration = Duration::from_secs(10);

/// A running fork server.
struct ForkServer {
    child: Child,
    requests: ChildStdin,
    /// Its stdout, line by line (a thread reads it).
    answers: mpsc::Receiver<String>,
}

impl Drop for ForkServer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// This process's fork servers, by the command that starts a worker and the adapter, with
/// the pid they belong to (a forked client, Python's `multiprocessing`, starts its own).
type Servers = HashMap<String, Arc<Mutex<ForkServer>>>;
static SERVERS: Mutex<Option<(u32, Servers)>> = Mutex::new(None);

/// The worker subcommand that runs a fork server (`python -m envhub.worker forkserver`).
pub(crate) const SUBCOMMAND: &str = "forkserver";

/// How the end of a forked worker is reported: its exit status went to its server.
pub(crate) const EXITED: &str = "exited (its status went to the suite's fork server)";

/// Whether warm starts are on (`ENVHUB_WARM_WORKERS=0` turns them off).
fn enabled() -> bool {
    std::env::var(crate::env_vars::ENVHUB_WARM_WORKERS).map_or(true, |v| v.trim() != "0")
}

/// A worker for `job` forked from its environment's fork server: its pidfd and ready spec.
/// `None` when it has no suite environment, warm starts are off, or no fork server could serve
/// the request (it could not start, or died): the caller then starts the worker cold, which
/// reports any real problem in full.
pub(crate) fn launch(
    job: &WorkerJob,
    user: &UserAdapters,
    start_timeout: Duration,
) -> Option<Result<(PidFd, ReadySpec), HubError>> {
    if job.python.is_none() || !enabled() {
        return None;
    }
    let mut command = crate::python_host::worker_command_in(job.python.as_ref(), user);
    command.arg(SUBCOMMAND).arg("--adapter").arg(&job.adapter);
    // Each worker holds the environment itself, as a cold one does (the server does not:
    // an idle server never keeps `envhub env remove` from it).
    if let Some(env) = &job.python
        && let Some(hold) = &env.hold
    {
        command
            .arg("--hold")
            .arg(hold)
            .arg("--removed")
            .arg(crate::python_host::removed_message(env));
    }
    let key = format!("{command:?}");
    let server = server_for(&key, command, start_timeout)?;
    let mut server = server.lock().unwrap_or_else(|e| e.into_inner());
    let forked = fork(&mut server, job);
    drop(server);
    match forked {
        Ok((pidfd, reply)) => Some(read_ready(job, pidfd, reply, start_timeout)),
        Err(why) => {
            tracing::warn!(%why, "the fork server failed; starting the worker cold");
            forget(&key);
            None
        }
    }
}

/// The running fork server for `key`, started if there is none.
fn server_for(
    key: &str,
    command: std::process::Command,
    start_timeout: Duration,
) -> Option<Arc<Mutex<ForkServer>>> {
    let mut servers = SERVERS.lock().unwrap_or_else(|e| e.into_inner());
    let pid = std::process::id();
    if servers.as_ref().is_none_or(|(owner, _)| *owner != pid) {
        // A forked process's copies are its parent's: forgotten, never killed.
        if let Some((_, old)) = servers.take() {
            std::mem::forget(old);
        }
        *servers = Some((pid, HashMap::new()));
    }
    let (_, map) = servers.as_mut().expect("set above");
    if let Some(server) = map.get(key) {
        let alive = server
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .child
            .try_wait()
            .is_ok_and(|s| s.is_none());
        if alive {
            return Some(server.clone());
        }
        map.remove(key);
    }
    match start(command, start_timeout) {
        Ok(server) => {
            let server = Arc::new(Mutex::new(server));
            map.insert(key.to_string(), server.clone());
            Some(server)
        }
        Err(why) => {
            tracing::warn!(%why, "no fork server; workers start cold");
            None
        }
    }
}

fn forget(key: &str) {
    let mut servers = SERVERS.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, map)) = servers.as_mut() {
        map.remove(key);
    }
}

/// Starts a fork server with `command` (a worker's, asking for `forkserver`) and waits
/// until it has imported the adapter's suite.
fn start(
    mut command: std::process::Command,
    start_timeout: Duration,
) -> Result<ForkServer, String> {
    command
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        .process_group(0);
    let parent = std::process::id();
    // SAFETY: as for a worker (`launch_local`): only the system calls of `die_with_parent`.
    unsafe {
        command.pre_exec(move || envhub_shm::die_with_parent(parent));
    }
    let mut child = crate::spawner::spawn(command).map_err(|e| e.to_string())?;
    let requests = child.stdin.take().ok_or("no stdin")?;
    let stdout = child.stdout.take().ok_or("no stdout")?;
    let (tx, answers) = mpsc::channel();
    std::thread::Builder::new()
        .name("envhub-fork-server".into())
        .spawn(move || {
            for line in BufReader::new(stdout).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        })
        .map_err(|e| e.to_string())?;
    let server = ForkServer {
        child,
        requests,
        answers,
    };
    let ready = server
        .answers
        .recv_timeout(start_timeout)
        .map_err(|_| format!("it did not report ready within {start_timeout:?}"))?;
    let ready: serde_json::Value =
        serde_json::from_str(&ready).map_err(|e| format!("unreadable ready line: {e}"))?;
    if ready.get("ready").is_none() {
        return Err(format!("it answered {ready} instead of ready"));
    }
    tracing::debug!(pid = server.child.id(), %ready, "fork server ready");
    Ok(server)
}

/// A forked worker's reply channel: a FIFO in a private folder (mode 0700), removed with it.
struct Reply {
    fifo: std::fs::File,
    _folder: Folder,
}

/// A private folder, removed with what it holds when dropped.
struct Folder(std::path::PathBuf);

impl Folder {
    fn new() -> std::io::Result<Folder> {
        use std::os::unix::fs::DirBuilderExt;
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let path = std::env::temp_dir().join(format!("envhub-fork-{}-{n}", std::process::id()));
        std::fs::DirBuilder::new().mode(0o700).create(&path)?;
        Ok(Folder(path))
    }
}

impl Drop for Folder {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Asks `server` to fork a worker for `job`: the worker's pidfd and the FIFO it replies on.
fn fork(server: &mut ForkServer, job: &WorkerJob) -> Result<(PidFd, Reply), String> {
    let folder = Folder::new().map_err(|e| e.to_string())?;
    let path = folder.0.join("reply");
    let c_path =
        std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).map_err(|e| e.to_string())?;
    // SAFETY: a NUL-terminated path and a mode.
    if unsafe { libc::mkfifo(c_path.as_ptr(), 0o600) } != 0 {
        return Err(format!("mkfifo: {}", std::io::Error::last_os_error()));
    }
    // Opened for reading and writing: the open does not wait for the worker, and the FIFO
    // never reads as ended before it has written.
    let fifo = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&path)
        .map_err(|e| e.to_string());
    let fifo = fifo?;
    let request = serde_json::json!({
        "job": serde_json::to_string(job).expect("a job serializes"),
        "reply": path,
    });
    let sent = writeln!(server.requests, "{request}").and_then(|()| server.requests.flush());
    let answer = sent
        .map_err(|e| format!("cannot send it a request: {e}"))
        .and_then(|()| {
            server
                .answers
                .recv_timeout(FORK_TIMEOUT)
                .map_err(|_| format!("no answer within {FORK_TIMEOUT:?}"))
        });
    let answer = answer.and_then(|a| {
        serde_json::from_str::<serde_json::Value>(&a).map_err(|e| format!("unreadable: {e}"))
    });
    let pid = match answer {
        Ok(a) => a.get("pid").and_then(|p| p.as_u64()).ok_or(format!("{a}")),
        Err(e) => Err(e),
    };
    let pidfd = pid.and_then(|pid| PidFd::open(pid as u32).map_err(|e| e.to_string()))?;
    Ok((
        pidfd,
        Reply {
            fifo,
            _folder: folder,
        },
    ))
}

/// Reads a forked worker's ready line from its FIFO: the answer, its death, or the timeout.
fn read_ready(
    job: &WorkerJob,
    pidfd: PidFd,
    reply: Reply,
    start_timeout: Duration,
) -> Result<(PidFd, ReadySpec), HubError> {
    let pid = pidfd.pid();
    let Reply { fifo, _folder } = reply;
    let mut unblock = fifo.try_clone().ok();
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let read = BufReader::new(fifo).read_line(&mut line);
        let _ = tx.send(read.map(|_| line));
    });
    let deadline = Instant::now() + start_timeout;
    let died = |why: String| HubError::WorkerDied {
        worker: 0,
        envs: format!("{}..{}", job.env_offset, job.env_offset + job.worker_envs),
        pid,
        why: format!("failed to start: {why}"),
    };
    let line = loop {
        match rx.recv_timeout(Duration::from_millis(20)) {
            Ok(Ok(line)) => break Ok(line),
            Ok(Err(e)) => break Err(format!("cannot read its reply: {e}")),
            Err(_) if !pidfd.is_alive() => {
                break Err("it exited before reporting ready".into());
            }
            Err(_) if Instant::now() >= deadline => {
                break Err(format!("it did not report ready within {start_timeout:?}"));
            }
            Err(_) => {}
        }
    };
    let line = match line {
        Ok(line) => line,
        Err(why) => {
            pidfd.kill();
            // Ends the reading thread (the FIFO never reads as ended: this side holds it).
            if let Some(f) = unblock.as_mut() {
                let _ = f.write_all(b"\n");
            }
            return Err(died(why));
        }
    };
    match serde_json::from_str::<WorkerReply>(&line) {
        Ok(WorkerReply::Ready(spec)) => {
            // The same line as a cold start's (`launcher`), so logs read alike either way.
            tracing::debug!(pid = pidfd.pid(), worker = ?spec.worker, "worker ready");
            if let Some(env) = &job.python
                && let Err(e) = crate::python_host::check_identity(env, &spec)
            {
                pidfd.kill();
                return Err(e);
            }
            Ok((pidfd, spec))
        }
        Ok(WorkerReply::Error(message)) => {
            // It exits once it has said why; one that hangs on the way out is killed.
            let until = Instant::now() + Duration::from_secs(5);
            while pidfd.is_alive() && Instant::now() < until {
                std::thread::sleep(Duration::from_millis(10));
            }
            pidfd.kill();
            Err(HubError::MakeFailed(match &job.python {
                Some(env) => format!("in python env `{}`: {message}", env.name),
                None => message,
            }))
        }
        Err(e) => {
            pidfd.kill();
            Err(died(format!("unreadable reply `{}`: {e}", line.trim())))
        }
    }
}
