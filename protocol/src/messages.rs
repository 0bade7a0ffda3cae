//! The control messages between a client and a remote hub (JSON over Zenoh queries): what a
//! hub says of itself, and the request and reply that open a session on it.

use envhub_core::EnvConfig;
use serde::{Deserialize, Serialize};

/// One hub as `envhub hubs` shows it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HubInfo {
    /// Its name (`--name`, default the host name).
    pub name: String,
    /// The machine's host name.
    pub host: String,
    /// CPU cores of the machine.
    pub cores: usize,
    /// envhub version.
    pub version: String,
    /// Adapters that can run there.
    pub adapters: Vec<String>,
    /// Registry entries of its catalog.
    pub catalog: usize,
    /// Envs it runs for remote clients now.
    pub envs: usize,
    /// Worker processes it runs for remote clients now.
    pub workers: usize,
    /// Remote sessions open now.
    pub sessions: usize,
    /// One-minute load average of the machine.
    pub load: f64,
    /// Its limits, if set.
    pub max_envs: Option<usize>,
    /// Its limits, if set.
    pub max_workers: Option<usize>,
}

/// A request to open a session, as a client sends it.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpenRequest {
    /// Registry id in the hub's catalog.
    pub id: String,
    /// The session's config (its `num_envs`: the envs asked of this hub).
    pub config: EnvConfig,
    /// The client's liveliness key: the session ends when it goes.
    pub client: String,
    /// Restart crashed workers on the hub.
    pub restart_on_crash: bool,
    /// The step timeout the client asks for, in milliseconds.
    pub step_timeout_ms: u64,
}

/// The hub's answer to an open request.
#[derive(Debug, Serialize, Deserialize)]
pub struct OpenReply {
    /// Session key (see [`crate::keys`]).
    pub session: String,
    /// The envs' spec (spaces, fps, ...).
    pub spec: envhub_shm::ReadySpec,
    /// How the hub routed the id.
    pub route: crate::Route,
    /// Worker processes it started for the session.
    pub workers: usize,
    /// The session's secret key, 64 hex digits: every request and response of the session is
    /// sealed with it ([`crate::seal`]). Only the client that asked gets this reply.
    pub key: String,
}
