//! Errors of the hub and its client. Callers can react to each kind: a bad id or input is
//! the caller's to fix; a dead worker is the session's problem, never the hub's.
//!
//! A hub daemon sends its errors to clients serialized, variant and fields (`{"kind": ...,
//! "fields": ...}`), so a client rebuilds the error it would have got from an embedded hub.

use envhub_catalog::RegistryError;
use envhub_core::serde_text::{StaticName, interned};
use envhub_shm::DataPlaneError;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// An error from creating or using an env through the hub.
#[derive(Debug, thiserror::Error, Serialize, Deserialize)]
#[serde(tag = "kind", content = "fields", rename_all = "snake_case")]
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
    /// A Python environment an entry runs in could not be provided (not provisioned where
    /// provisioning is explicit or not allowed, or its build failed).
    #[error("{message}")]
    PythonEnv {
        /// The environment's name.
        name: String,
        /// Why, with the hint.
        message: String,
    },
    /// A session option is invalid.
    #[error("invalid {what}: {reason}")]
    InvalidConfig {
        /// The option.
        #[serde(deserialize_with = "interned")]
        what: StaticName,
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
    /// The call is not valid in the session's current state: calls out of order (`recv`
    /// before `send`, a step while results are still to be received, the EnvPool mode's
    /// rules). The caller fixes the order of its calls.
    #[error("{0}")]
    InvalidState(String),
    /// The session is closed (by `close`, or for good after a worker died without
    /// `restart_on_crash`): the caller makes a new one.
    #[error("`{id}` is closed; make a new env")]
    Closed {
        /// The session's id.
        id: String,
    },
    /// The session was never reset: the caller resets it before stepping.
    #[error("`{id}` must be reset before it is stepped")]
    NotReset {
        /// The session's id.
        id: String,
    },
    /// Envs whose last step or reset failed were asked to step: the caller resets them.
    #[error(
        "env {envs:?} of `{id}` failed in its last step or reset and must be reset first\nhint: reset them (a full reset, or `reset_with` a mask that selects them; in Python `reset(options={{\"reset_mask\": mask}})`)"
    )]
    MustReset {
        /// The session's id.
        id: String,
        /// The envs to reset.
        envs: Vec<usize>,
    },
    /// Workers or hubs report spaces the session cannot batch (they differ between hubs,
    /// or are too large for the batch slots): the hubs run different versions of an env.
    #[error("{0}")]
    SpacesDiffer(String),
    /// Something the caller cannot fix failed inside the hub or client: a thread could
    /// not start, the OS random source or the key exchange failed.
    #[error("{0}")]
    Internal(String),
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
    /// A remote hub went away (its process died, froze, or the network to it was cut): its
    /// envs are lost unless the session places them again (`restart_on_crash`).
    #[error(
        "hub `{hub}` (envs {envs}) was lost: {why}\nhint: the other hubs' envs are unaffected; enable `restart_on_crash` to place lost envs on the hubs that remain"
    )]
    HubLost {
        /// The hub's name.
        hub: String,
        /// Env range of the session it hosted, `a..b`.
        envs: String,
        /// What was seen.
        why: String,
    },
    /// A hub named by the caller is not among the live hubs.
    #[error(
        "no live hub named `{name}`{closest}; live hubs: {live}\nhint: `envhub hubs` lists them; check `--connect` / ENVHUB_CONNECT and the hub's `--name`"
    )]
    UnknownHub {
        /// The name asked for.
        name: String,
        /// The live hubs, comma-separated (`none` when none answered).
        live: String,
        /// ` (closest: a, b)` or empty.
        closest: String,
    },
    /// Reaching other hubs over the network failed.
    #[error("network: {reason}\nhint: {hint}")]
    Network {
        /// What failed.
        reason: String,
        /// What to check.
        hint: String,
    },
    /// A remote hub refused a request (security policy or its limits).
    #[error("hub `{hub}` refused: {reason}\nhint: {hint}")]
    Refused {
        /// The hub's name.
        hub: String,
        /// Why.
        reason: String,
        /// What is allowed.
        hint: String,
    },
    /// The shared-memory layer failed.
    #[error(transparent)]
    #[serde(with = "data_plane")]
    DataPlane(#[from] DataPlaneError),
    /// The hub daemon reported an error only as text (a daemon that predates structured
    /// errors): its message, with the hint.
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

/// [`DataPlaneError`] (of `envhub-shm`, which has no serde impls for it) on the wire.
mod data_plane {
    use super::*;

    #[derive(Serialize, Deserialize)]
    #[serde(tag = "kind", content = "fields", rename_all = "snake_case")]
    enum Wire {
        Ipc {
            #[serde(deserialize_with = "interned")]
            what: StaticName,
            detail: String,
        },
        Protocol(String),
        PeerGone(String),
        NoSpace {
            #[serde(deserialize_with = "interned")]
            what: StaticName,
            needed: u64,
            free: u64,
        },
    }

    pub fn serialize<S: Serializer>(e: &DataPlaneError, s: S) -> Result<S::Ok, S::Error> {
        match e {
            DataPlaneError::Ipc { what, detail } => Wire::Ipc {
                what,
                detail: detail.clone(),
            },
            DataPlaneError::Protocol(m) => Wire::Protocol(m.clone()),
            DataPlaneError::PeerGone(m) => Wire::PeerGone(m.clone()),
            DataPlaneError::NoSpace { what, needed, free } => Wire::NoSpace {
                what,
                needed: *needed,
                free: *free,
            },
        }
        .serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<DataPlaneError, D::Error> {
        Ok(match Wire::deserialize(d)? {
            Wire::Ipc { what, detail } => DataPlaneError::Ipc { what, detail },
            Wire::Protocol(m) => DataPlaneError::Protocol(m),
            Wire::PeerGone(m) => DataPlaneError::PeerGone(m),
            Wire::NoSpace { what, needed, free } => DataPlaneError::NoSpace { what, needed, free },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use envhub_shm::DataPlaneError;

    /// Every variant survives the daemon's wire: same variant, same message.
    #[test]
    fn errors_round_trip_through_json() {
        let errors = [
            HubError::Registry(RegistryError::UnknownId {
                id: "mujoco-antt".into(),
                closest: vec!["mujoco-ant".into()],
            }),
            HubError::Registry(RegistryError::Read {
                path: "/no/such.yaml".into(),
                source: std::io::Error::from(std::io::ErrorKind::NotFound),
            }),
            HubError::Unavailable {
                adapter: "maniskill".into(),
                reason: "`mani_skill` is not installed".into(),
                hint: "pip install mani_skill".into(),
            },
            HubError::InvalidConfig {
                what: "config",
                reason: "unknown field `wrokers`".into(),
            },
            HubError::WorkerDied {
                worker: 1,
                envs: "2..4".into(),
                pid: 42,
                why: "died (signal: 9 (SIGKILL))".into(),
            },
            HubError::MakeFailed("no".into()),
            HubError::InvalidState("nothing was sent; call `send` first".into()),
            HubError::Closed {
                id: "CartPole-v1".into(),
            },
            HubError::NotReset {
                id: "CartPole-v1".into(),
            },
            HubError::MustReset {
                id: "CartPole-v1".into(),
                envs: vec![1, 3],
            },
            HubError::SpacesDiffer("`x` has different spaces".into()),
            HubError::Internal("cannot start a session thread: x".into()),
            HubError::DataPlane(DataPlaneError::Ipc {
                what: "node",
                detail: "x".into(),
            }),
            HubError::DataPlane(DataPlaneError::PeerGone("gone".into())),
            HubError::DataPlane(DataPlaneError::NoSpace {
                what: "a batch slot",
                needed: 1 << 30,
                free: 1 << 20,
            }),
        ];
        for e in errors {
            let json = serde_json::to_value(&e).unwrap();
            let back: HubError = serde_json::from_value(json.clone()).unwrap();
            assert_eq!(back.to_string(), e.to_string(), "{json}");
            assert_eq!(
                std::mem::discriminant(&back),
                std::mem::discriminant(&e),
                "{json}"
            );
        }
    }
}
