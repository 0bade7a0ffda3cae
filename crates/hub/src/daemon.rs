//! `envhub serve`: the hub as a daemon that many client processes share.
//!
//! Control only: clients ask it to route ids and start workers, then talk to those workers
//! directly over shared memory; the daemon is never on the per-step path. Each client
//! connection owns the workers started through it, and closing it (the client exits or
//! crashes) stops them. A client that crashes does not disturb the daemon or other clients.
//!
//! A request that fails is answered with the error serialized (`error`: its variant and
//! fields, as [`HubError`] serializes) beside its text (`err`), so a client raises what an
//! embedded hub would have.
//!
//! Workers start from the daemon's environment, so a client's own user adapters (its
//! `ENVHUB_ADAPTERS`, set by `AdapterRegistry().register`) travel with its `adapters`, `route`
//! and `launch` requests as `user_adapters` (absent: none); the daemon routes and starts
//! Python workers with them beside its own.

use crate::hub::Hub;
use crate::launcher::launch_local;
use envhub_protocol::HubError;
use envhub_protocol::daemon::{self, Request};
use serde_json::{Value, json};
use std::collections::HashMap;
use std::io::{BufReader, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::process::Child;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

/// The default control socket: `envhub.sock` in this user's private folder
/// (`$XDG_RUNTIME_DIR/envhub`, else `~/.cache/envhub/run`, [`envhub_core::private_dir`]),
/// made and checked on every component (a socket in a folder of the world-writable `/tmp`
/// could be taken first by another user), or why there is none.
pub fn default_socket() -> Result<PathBuf, envhub_core::private_dir::PrivateDirError> {
    envhub_core::private_dir::runtime_dir("").map(|dir| dir.join("envhub.sock"))
}

/// Binds `socket` (replacing a stale one, refusing a live one) and serves clients until the
/// process is stopped. `on_ready` runs once the socket accepts connections.
pub fn serve(socket: &Path, hub: Arc<Hub>, on_ready: impl FnOnce()) -> Result<(), HubError> {
    let fail = |reason: String| HubError::Daemon {
        socket: socket.display().to_string(),
        reason,
    };
    if crate::daemon_guard::in_default_dir(socket)
        && let Some(dir) = socket.parent()
    {
        envhub_core::private_dir::ensure(dir).map_err(|e| fail(e.to_string()))?;
    }
    if socket.exists() {
        if UnixStream::connect(socket).is_ok() {
            return Err(fail("another hub is already serving here".into()));
        }
        std::fs::remove_file(socket)
            .map_err(|e| fail(format!("cannot remove the stale socket: {e}")))?;
    }
    let listener = UnixListener::bind(socket).map_err(|e| fail(format!("cannot listen: {e}")))?;
    crate::daemon_guard::restrict_socket(socket).map_err(fail)?;
    // A restarted hub starts clean: remove what crashed processes left in shared memory.
    if let Err(e) = envhub_shm::cleanup_dead_nodes(&hub.options().namespace) {
        tracing::warn!(error = %e, "could not clean up dead nodes");
    }
    // Resolve the adapter catalog once, before clients ask.
    hub.adapters()?;
    let workers = Arc::new(AtomicUsize::new(0));
    on_ready();
    for stream in listener.incoming() {
        let Ok(stream) = stream else { continue };
        match crate::daemon_guard::peer_uid(&stream) {
            Ok(peer) if crate::daemon_guard::peer_allowed(peer) => {}
            peer => {
                tracing::warn!(?peer, "refused a connection from another user");
                continue;
            }
        }
        let (hub, workers) = (hub.clone(), workers.clone());
        std::thread::spawn(move || {
            if let Err(e) = Connection::new(hub, workers).run(stream) {
                tracing::debug!(error = %e, "client connection ended");
            }
        });
    }
    Ok(())
}

struct Connection {
    hub: Arc<Hub>,
    workers: Arc<AtomicUsize>,
    children: HashMap<u32, Child>,
    /// Workers forked by a suite's fork server (its children, not the daemon's): held by
    /// pidfds, their exit status with the server.
    forked: HashMap<u32, envhub_shm::PidFd>,
}

impl Connection {
    fn new(hub: Arc<Hub>, workers: Arc<AtomicUsize>) -> Connection {
        Connection {
            hub,
            workers,
            children: HashMap::new(),
            forked: HashMap::new(),
        }
    }

    fn run(mut self, stream: UnixStream) -> std::io::Result<()> {
        let mut writer = stream.try_clone()?;
        let mut reader = BufReader::new(stream);
        let mut line = String::new();
        loop {
            use envhub_protocol::daemon::{MAX_LINE, read_line_bounded};
            match read_line_bounded(&mut reader, MAX_LINE, &mut line) {
                Ok(0) => break,
                Ok(_) => {}
                Err(e) => {
                    // The rest of an overlong line cannot be told from the next request.
                    tracing::warn!(error = %e, "unreadable request: closing the connection");
                    let reply = json!({ "err": format!("unreadable request: {e}") });
                    let _ = writer.write_all(format!("{reply}\n").as_bytes());
                    break;
                }
            }
            let reply = Request::parse(&line).and_then(|request| self.handle(request));
            let mut text = daemon::encode_reply(&reply);
            text.push('\n');
            writer.write_all(text.as_bytes())?;
        }
        Ok(())
    }

    fn handle(&mut self, request: Request) -> Result<Value, HubError> {
        match request {
            Request::Ping => Ok(json!("pong")),
            Request::Adapters { user } => {
                Ok(serde_json::to_value(self.hub.adapters_with(&user)?)
                    .expect("adapters serialize"))
            }
            Request::Status => Ok(json!({"workers": self.workers.load(Ordering::Relaxed)})),
            Request::Route { id, config, user } => Ok(serde_json::to_value(
                self.hub.route_with(&id, &config, &user)?,
            )
            .expect("routes serialize")),
            Request::Launch {
                job,
                start_timeout,
                user,
            } => {
                // A suite's worker forks from the suite's warm interpreter, which this daemon
                // (its user's own) keeps for later sessions of any of its clients.
                if let Some(forked) = crate::fork_server::launch(&job, &user, start_timeout) {
                    let (pidfd, spec) = forked?;
                    self.forked.insert(pidfd.pid(), pidfd);
                    self.workers.fetch_add(1, Ordering::Relaxed);
                    return Ok(serde_json::to_value(spec).expect("specs serialize"));
                }
                let (child, spec) = launch_local(&job, &user, start_timeout)?;
                self.children.insert(child.id(), child);
                self.workers.fetch_add(1, Ordering::Relaxed);
                Ok(serde_json::to_value(spec).expect("specs serialize"))
            }
            Request::ExitStatus { pid } => {
                if let Some(pidfd) = self.forked.get(&pid) {
                    if pidfd.is_alive() {
                        return Ok(Value::Null);
                    }
                    self.forked.remove(&pid);
                    self.workers.fetch_sub(1, Ordering::Relaxed);
                    return Ok(json!(crate::fork_server::EXITED));
                }
                let child = self
                    .children
                    .get_mut(&pid)
                    .ok_or_else(|| HubError::InvalidConfig {
                        what: "daemon request",
                        reason: format!("pid {pid} is no worker of this connection"),
                    })?;
                match child.try_wait() {
                    Ok(Some(status)) => {
                        // Reaped and reported: the worker is gone for good.
                        self.children.remove(&pid);
                        self.workers.fetch_sub(1, Ordering::Relaxed);
                        Ok(json!(status.to_string()))
                    }
                    _ => Ok(Value::Null),
                }
            }
        }
    }
}

impl Drop for Connection {
    fn drop(&mut self) {
        // The client is gone: its workers go too (they would notice on their own, but the
        // daemon must reap them either way).
        for (_, mut child) in self.children.drain() {
            if matches!(child.try_wait(), Ok(None)) {
                let _ = child.kill();
            }
            let _ = child.wait();
            self.workers.fetch_sub(1, Ordering::Relaxed);
        }
        for (_, pidfd) in self.forked.drain() {
            pidfd.kill();
            self.workers.fetch_sub(1, Ordering::Relaxed);
        }
    }
}
