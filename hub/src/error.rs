//! Errors of the hub and its client. Callers can react to each kind: a bad id or input is
//! the caller's to fix; a dead worker is the session's problem, never the hub's.

use crate::RegistryError;
use envhub_shm::DataPlaneError;

/// An error from creating or using an env through the hub.
#[derive(Debug, thiserror::Error)]
pub enum HubError {
    /// Registry lookup failed (unknown id, with the closest ones).
    #[error(transparent)]
    Registry(#[from] RegistryError),
    /// No adapter can run the entry.
    #[error("no adapter can run `{env_id}` (framework `{framework}`){detail}\nhint: {hint}")]
    NoAdapter {
        /// The framework env id.
        env_id: String,
        /// The entry's framework.
        framework: String,
        /// What was found instead.
        detail: String,
        /// What to do.
        hint: String,
    },
    /// The adapter exists but cannot run here.
    #[error("adapter `{adapter}` is unavailable: {reason}\nhint: {hint}")]
    Unavailable {
        /// The adapter.
        adapter: String,
        /// What is missing.
        reason: String,
        /// How to install it.
        hint: String,
    },
    /// A session option is invalid.
    #[error("invalid {what}: {reason}")]
    InvalidConfig {
        /// The option.
        what: &'static str,
        /// What is wrong and what is valid.
        reason: String,
    },
    /// The worker binary could not be found or started.
    #[error(
        "cannot start the worker `{path}`: {reason}\nhint: `make build` builds it and sets up the libraries it links; or set ENVHUB_WORKER to its path"
    )]
    WorkerBinary {
        /// The path tried.
        path: String,
        /// The OS error.
        reason: String,
    },
    /// The worker started but could not create the envs.
    #[error("{0}")]
    MakeFailed(String),
    /// An action batch of the wrong size or type.
    #[error("invalid actions: {reason}\nhint: {hint}")]
    InvalidAction {
        /// What is wrong.
        reason: String,
        /// What is expected.
        hint: String,
    },
    /// The call is not valid in the env's current state.
    #[error("{0}")]
    InvalidState(String),
    /// A worker died or hung; its envs are lost (unless restarted).
    #[error(
        "worker {worker} (envs {envs}, pid {pid}) {why}\nhint: the hub and other sessions are unaffected; make a new env, or enable `restart_on_crash`"
    )]
    WorkerDied {
        /// Worker index in the session.
        worker: usize,
        /// Env range, `a..b`.
        envs: String,
        /// Its pid.
        pid: u32,
        /// What happened (exit status, timeout).
        why: String,
    },
    /// An env raised an error while stepping or resetting. The other envs of the call
    /// stepped as usual (their results are in `VecEnv::last_batch`); the failed ones must be
    /// reset before they step again.
    #[error(
        "env error in worker {worker} (envs {envs:?}): {message}\nhint: the other envs stepped as usual; reset envs {envs:?} before stepping them again"
    )]
    EnvFailed {
        /// Worker index.
        worker: usize,
        /// The envs (session indices) that failed.
        envs: Vec<usize>,
        /// The env's message.
        message: String,
    },
    /// A wait on the workers was interrupted (Ctrl-C); the session was aborted.
    #[error("interrupted while waiting for the workers; the session was closed")]
    Interrupted,
    /// The shared-memory layer failed.
    #[error(transparent)]
    DataPlane(#[from] DataPlaneError),
    /// The hub daemon reported an error (its message, with the hint).
    #[error("{0}")]
    Remote(String),
    /// Talking to the hub daemon failed.
    #[error(
        "hub daemon at `{socket}`: {reason}\nhint: start it with `envhub serve`, or unset ENVHUB_HUB to use the embedded hub"
    )]
    Daemon {
        /// Its socket.
        socket: String,
        /// What went wrong.
        reason: String,
    },
}
