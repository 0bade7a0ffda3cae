//! The client side of the hub daemon's control socket: JSON lines over a Unix socket.
//!
//! The connection lives as long as the sessions started through it: when it closes (the
//! client exits or crashes), the daemon stops that client's workers. Requests that depend on
//! the adapters carry this process's user adapters (see `UserAdapters`), read at each call so
//! an adapter registered since is included.

use crate::adapters::AdapterInfo;
use crate::python_host::user_adapters_of_this_process;
use envhub_core::EnvConfig;
use envhub_protocol::HubError;
use envhub_protocol::Route;
use envhub_protocol::daemon::{self, ReplyError, Request};
use envhub_shm::{ReadySpec, WorkerJob};
use serde_json::Value;
use std::io::{BufReader, Write};
use std::os::unix::net::UnixStream;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::Duration;

/// A connection to `envhub serve`.
pub struct DaemonClient {
    socket: PathBuf,
    conn: Mutex<(BufReader<UnixStream>, UnixStream)>,
    /// The daemon's pid, from the kernel (`SO_PEERCRED`): the workers it reports must be its
    /// children.
    pid: u32,
}

impl std::fmt::Debug for DaemonClient {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("DaemonClient")
            .field("socket", &self.socket)
            .finish()
    }
}

impl DaemonClient {
    /// Connects to the daemon listening on `socket`.
    pub fn connect(socket: &Path) -> Result<Arc<DaemonClient>, HubError> {
        // The default folder must be this user's: else the socket in it may be another's.
        if crate::daemon_guard::in_default_dir(socket)
            && let Some(dir) = socket.parent()
            && let Err(e) = envhub_core::private_dir::check(dir)
        {
            return Err(HubError::Daemon {
                socket: socket.display().to_string(),
                reason: e.to_string(),
            });
        }
        let stream = UnixStream::connect(socket).map_err(|e| HubError::Daemon {
            socket: socket.display().to_string(),
            reason: format!("cannot connect: {e}"),
        })?;
        let fail = |reason: String| HubError::Daemon {
            socket: socket.display().to_string(),
            reason,
        };
        // Whoever listens there must be this user (or root): workers it starts run our jobs.
        let (pid, uid) = crate::daemon_guard::peer_cred(&stream)
            .map_err(|e| fail(format!("cannot ask who listens: {e}")))?;
        if !crate::daemon_guard::peer_allowed(uid) {
            return Err(fail(format!(
                "the socket is served by uid {uid}, not this user\nhint: start your own daemon (`envhub serve --socket PATH`) and set ENVHUB_HUB to its socket"
            )));
        }
        let reader = BufReader::new(stream.try_clone().map_err(|e| fail(e.to_string()))?);
        let client = DaemonClient {
            socket: socket.to_path_buf(),
            conn: Mutex::new((reader, stream)),
            pid,
        };
        client.call(Request::Ping)?;
        Ok(Arc::new(client))
    }

    /// How long a call may wait for its reply: a daemon that accepts and never answers (stuck,
    /// stopped, or not a daemon at all) must not hang its clients.
    fn time_limit(request: &Request) -> Duration {
        match request {
            // Starting a worker takes up to its start timeout.
            Request::Launch { start_timeout, .. } => {
                start_timeout.saturating_add(Duration::from_secs(10))
            }
            // May ask Python adapters what they host (an interpreter's start, imports).
            Request::Adapters { .. } | Request::Route { .. } => Duration::from_secs(120),
            _ => Duration::from_secs(5),
        }
    }

    /// A daemon's error as this process may raise it: kinds that describe the request or the
    /// daemon's envs pass; kinds that describe this process (`Interrupted`, which Python
    /// raises as `KeyboardInterrupt`, a lost or refusing hub) become text.
    fn checked(&self, error: HubError) -> HubError {
        match error {
            e if envhub_protocol::untrusted::describes_the_request(&e) => e,
            HubError::PythonEnv { .. }
            | HubError::WorkerBinary { .. }
            // A worker the daemon started for us that died starting: ours to report.
            | HubError::WorkerDied { .. }
            | HubError::DataPlane(_)
            | HubError::Daemon { .. }
            | HubError::Remote(_) => error,
            other => self.fail(format!("reported: {other}")),
        }
    }

    fn fail(&self, reason: impl std::fmt::Display) -> HubError {
        HubError::Daemon {
            socket: self.socket.display().to_string(),
            reason: reason.to_string(),
        }
    }

    /// Sends one request and reads its reply: `{"ok": ...}`, or `{"err": "...", "error":
    /// {...}}` (the error rebuilt as the daemon had it; text only from an older daemon).
    fn call(&self, request: Request) -> Result<Value, HubError> {
        let mut conn = self
            .conn
            .lock()
            .map_err(|_| self.fail("connection poisoned"))?;
        let (reader, writer) = &mut *conn;
        let limit = Self::time_limit(&request);
        writer
            .set_read_timeout(Some(limit))
            .map_err(|e| self.fail(format!("set a time limit: {e}")))?;
        let mut line = request.encode();
        line.push('\n');
        writer
            .write_all(line.as_bytes())
            .map_err(|e| self.fail(format!("send: {e}")))?;
        let mut reply = String::new();
        let n = daemon::read_line_bounded(reader, daemon::MAX_LINE, &mut reply)
        .map_err(|e| {
            if matches!(
                e.kind(),
                std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
            ) {
                // A late reply would pass for the next call's: this connection is done.
                let _ = writer.shutdown(std::net::Shutdown::Both);
                self.fail(format!(
                    "no reply to `{}` within {limit:?}; the daemon is stuck, stopped or not an envhub daemon",
                    request.op()
                ))
            } else {
                self.fail(format!("receive: {e}"))
            }
        })?;
        if n == 0 {
            return Err(self.fail("the daemon closed the connection"));
        }
        daemon::parse_reply(&reply).map_err(|e| match e {
            ReplyError::Unreadable(why) => self.fail(format!("unreadable reply: {why}")),
            ReplyError::Error(error) => self.checked(error),
            ReplyError::Text(text) => HubError::Remote(text),
        })
    }

    /// Holds the worker the daemon reports as `pid` by a pidfd, once it is checked to be the
    /// daemon's child (alive and unreaped, so its pid cannot have been reused yet).
    pub(crate) fn hold_worker(&self, pid: u32) -> Result<envhub_shm::PidFd, HubError> {
        let fd = envhub_shm::PidFd::open(pid).map_err(|e| {
            self.fail(format!(
                "reported worker pid {pid}, which has no process: {e}"
            ))
        })?;
        match fd.parent() {
            Some(parent) if parent == self.pid => Ok(fd),
            // A suite's warm worker: forked by the daemon's fork server of that suite.
            Some(parent) if fork_server_of(parent) == Some(self.pid) => Ok(fd),
            Some(parent) => Err(self.fail(format!(
                "reported worker pid {pid}, whose parent is {parent}, not the daemon ({}) or a fork server of it",
                self.pid
            ))),
            None => Err(self.fail(format!("reported worker pid {pid}, which has exited"))),
        }
    }

    /// Asks the daemon to start a worker for `job`.
    pub(crate) fn launch(
        &self,
        job: &WorkerJob,
        start_timeout: Duration,
    ) -> Result<ReadySpec, HubError> {
        let ok = self.call(Request::Launch {
            job: Box::new(job.clone()),
            start_timeout,
            user: user_adapters_of_this_process(),
        })?;
        serde_json::from_value(ok).map_err(|e| self.fail(format!("unreadable ready spec: {e}")))
    }

    /// How a worker the daemon started has ended (`None`: still running).
    pub(crate) fn exit_status(&self, pid: u32) -> Result<Option<String>, HubError> {
        let ok = self.call(Request::ExitStatus { pid })?;
        Ok(ok.as_str().map(str::to_string))
    }

    /// Routes a registry id with the daemon's registry and adapters.
    pub(crate) fn route(&self, id: &str, config: &EnvConfig) -> Result<Route, HubError> {
        let ok = self.call(Request::Route {
            id: id.to_string(),
            config: config.clone(),
            user: user_adapters_of_this_process(),
        })?;
        serde_json::from_value(ok).map_err(|e| self.fail(format!("unreadable route: {e}")))
    }

    /// The daemon's adapters.
    pub fn adapters(&self) -> Result<Vec<AdapterInfo>, HubError> {
        let ok = self.call(Request::Adapters {
            user: user_adapters_of_this_process(),
        })?;
        serde_json::from_value(ok).map_err(|e| self.fail(format!("unreadable adapters: {e}")))
    }

    /// Workers the daemon runs, over all clients.
    pub fn worker_count(&self) -> Result<usize, HubError> {
        let ok = self.call(Request::Status)?;
        Ok(ok["workers"].as_u64().unwrap_or(0) as usize)
    }
}

/// The parent of `pid` when `pid` is a suite's fork server (`envhub.worker forkserver`).
fn fork_server_of(pid: u32) -> Option<u32> {
    let held = envhub_shm::PidFd::open(pid).ok()?;
    let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).ok()?;
    let is_server = cmdline
        .split(|&b| b == 0)
        .any(|arg| arg == crate::fork_server::SUBCOMMAND.as_bytes());
    // Read after the cmdline, while the fd holds the process: both are the same process's.
    let parent = held.parent()?;
    is_server.then_some(parent)
}
