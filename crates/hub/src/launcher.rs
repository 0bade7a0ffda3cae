//! Starting worker processes: here (the embedded hub) or by the hub daemon on our behalf.

use crate::adapters::Host;
use crate::daemon_client::DaemonClient;
use crate::python_host::UserAdapters;
use crate::worker_binary::worker_binary;
use envhub_protocol::HubError;
use envhub_session::{Launch, Process};
use envhub_shm::{ReadySpec, WorkerJob, WorkerReply};
use std::io::BufRead;
use std::os::unix::process::CommandExt;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::Duration;

/// Who starts workers.
#[derive(Clone)]
pub(crate) enum Launcher {
    /// This process spawns them as its children.
    Local,
    /// The hub daemon spawns them (they still watch this process and exit with it).
    Daemon(Arc<DaemonClient>),
}

/// A started worker process.
pub(crate) enum WorkerProcess {
    /// Our child.
    Local(Child),
    /// Forked by this process's fork server of its suite's environment (`fork_server.rs`),
    /// held by a pidfd; its exit status stays with the server.
    Forked(envhub_shm::PidFd),
    /// The daemon's child.
    Daemon {
        /// The process, held by a pidfd: killing it can never hit a process that took its
        /// pid after the daemon reaped it.
        pidfd: envhub_shm::PidFd,
        /// The daemon that started it.
        daemon: Arc<DaemonClient>,
    },
}

impl Launcher {
    /// The launcher of the embedded hub, as the engine takes it.
    pub fn local() -> Arc<dyn Launch> {
        Arc::new(Launcher::Local)
    }
}

impl Process for WorkerProcess {
    fn pid(&self) -> u32 {
        match self {
            WorkerProcess::Local(child) => child.id(),
            WorkerProcess::Forked(pidfd) | WorkerProcess::Daemon { pidfd, .. } => pidfd.pid(),
        }
    }

    fn kill(&mut self) {
        self.kill_now();
        let _ = self.exit_status(Duration::from_secs(2));
    }

    /// Our own child is reaped, which takes no time once it is killed.
    fn kill_now(&mut self) {
        match self {
            // `Child::kill` after the child was reaped signals nothing.
            WorkerProcess::Local(child) => {
                let _ = child.kill();
                let _ = child.wait();
            }
            WorkerProcess::Forked(pidfd) | WorkerProcess::Daemon { pidfd, .. } => pidfd.kill(),
        }
    }

    fn exit_status(&mut self, timeout: Duration) -> Option<String> {
        let deadline = std::time::Instant::now() + timeout;
        loop {
            let status = match self {
                WorkerProcess::Local(child) => {
                    child.try_wait().ok().flatten().map(|s| s.to_string())
                }
                WorkerProcess::Daemon { pidfd, daemon } => {
                    daemon.exit_status(pidfd.pid()).ok().flatten()
                }
                WorkerProcess::Forked(pidfd) => {
                    (!pidfd.is_alive()).then(|| crate::fork_server::EXITED.to_string())
                }
            };
            if status.is_some() || std::time::Instant::now() >= deadline {
                return status;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl Launch for Launcher {
    fn launch(
        &self,
        job: &WorkerJob,
        start_timeout: Duration,
    ) -> Result<(Box<dyn Process>, ReadySpec), HubError> {
        match self {
            Launcher::Local => {
                // A suite's worker forks from the suite's warm interpreter where it can.
                if let Some(forked) =
                    crate::fork_server::launch(job, &UserAdapters::default(), start_timeout)
                {
                    let (pidfd, spec) = forked?;
                    return Ok((Box::new(WorkerProcess::Forked(pidfd)), spec));
                }
                let (child, spec) = launch_local(job, &UserAdapters::default(), start_timeout)?;
                Ok((Box::new(WorkerProcess::Local(child)), spec))
            }
            Launcher::Daemon(daemon) => {
                let spec = daemon.launch(job, start_timeout)?;
                let pidfd = daemon.hold_worker(spec.pid)?;
                Ok((
                    Box::new(WorkerProcess::Daemon {
                        pidfd,
                        daemon: daemon.clone(),
                    }),
                    spec,
                ))
            }
        }
    }
}

/// How long a worker that reported an error may take to exit before it is killed.
const EXIT_AFTER_ERROR: Duration = Duration::from_secs(5);

/// Spawns `envhub-worker serve` (or `python -m envhub.worker serve` for a Python-hosted
/// adapter, also hosting `user`'s adapters) for `job` and reads its ready line.
pub(crate) fn launch_local(
    job: &WorkerJob,
    user: &UserAdapters,
    start_timeout: Duration,
) -> Result<(Child, ReadySpec), HubError> {
    // A job in a provisioned environment runs in its interpreter, whatever hosts the adapter
    // in the hub's.
    if let Some(env) = &job.python
        && !env.interpreter.exists()
    {
        return Err(HubError::PythonEnv {
            name: env.name.clone(),
            message: crate::python_host::removed_message(env),
        });
    }
    let host = match &job.python {
        Some(_) => Host::Python,
        None => crate::adapters::host_of(&job.adapter, user),
    };
    let (mut command, path) = match host {
        Host::Native => {
            let path = worker_binary();
            let mut command = Command::new(&path);
            // As for `describe`: the hub's interpreter locates Gymnasium's assets.
            command.env(
                crate::env_vars::ENVHUB_PYTHON,
                crate::python_host::python_interpreter(),
            );
            (command, path)
        }
        Host::Python => (
            crate::python_host::worker_command_in(job.python.as_ref(), user),
            job.python
                .as_ref()
                .map(|p| p.interpreter.clone())
                .unwrap_or_else(crate::python_host::python_interpreter),
        ),
    };
    command
        .arg("serve")
        .arg("--job")
        .arg(serde_json::to_string(job).expect("a job serializes"))
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::inherit())
        // Its own process group: a Ctrl-C in the terminal goes to the client, which closes
        // its sessions, and never kills a worker mid-episode.
        .process_group(0);
    let parent = std::process::id();
    // SAFETY: the closure runs in the forked child before exec and only makes the system
    // calls of `die_with_parent`, which allocates nothing and takes no lock.
    unsafe {
        command.pre_exec(move || envhub_shm::die_with_parent(parent));
    }
    let mut child = crate::spawner::spawn(command).map_err(|e| HubError::WorkerBinary {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    let pid = child.id();
    match read_reply(&mut child, start_timeout) {
        Ok(WorkerReply::Ready(spec)) => {
            tracing::debug!(pid, worker = ?spec.worker, "worker ready");
            if let Some(env) = &job.python
                && let Err(e) = crate::python_host::check_identity(env, &spec)
            {
                let _ = child.kill();
                let _ = child.wait();
                return Err(e);
            }
            Ok((child, spec))
        }
        Ok(WorkerReply::Error(message)) => {
            // It exits once it has said why; one that hangs on the way out (a simulator's
            // teardown, a Python exit handler) is killed rather than waited on.
            if crate::bounded::wait_within(&mut child, EXIT_AFTER_ERROR).is_none() {
                tracing::warn!(
                    pid,
                    "the worker did not exit within {} of reporting an error; killed it",
                    crate::bounded::seconds(EXIT_AFTER_ERROR)
                );
            }
            Err(HubError::MakeFailed(match &job.python {
                // The suite's own packages raised: say in which environment.
                Some(env) => format!("in python env `{}`: {message}", env.name),
                None => message,
            }))
        }
        Err(why) => {
            let _ = child.kill();
            let status = child.wait().map(|s| s.to_string()).unwrap_or_default();
            Err(HubError::WorkerDied {
                worker: 0,
                envs: format!("{}..{}", job.env_offset, job.env_offset + job.worker_envs),
                pid,
                why: format!("failed to start: {why} ({status})"),
            })
        }
    }
}

/// Reads the worker's one-line reply, giving up after `timeout` or when it exits silently.
fn read_reply(child: &mut Child, timeout: Duration) -> Result<WorkerReply, String> {
    let stdout = child.stdout.take().ok_or("no stdout")?;
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let mut line = String::new();
        let read = std::io::BufReader::new(stdout).read_line(&mut line);
        let _ = tx.send(read.map(|_| line));
    });
    match rx.recv_timeout(timeout) {
        Ok(Ok(line)) if line.trim().is_empty() => Err("it exited before reporting ready".into()),
        Ok(Ok(line)) => serde_json::from_str(&line)
            .map_err(|e| format!("unreadable reply `{}`: {e}", line.trim())),
        Ok(Err(e)) => Err(format!("cannot read its reply: {e}")),
        Err(_) => Err(format!("it did not report ready within {timeout:?}")),
    }
}
