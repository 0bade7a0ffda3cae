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

/// The largest open request a hub reads, in bytes. An open request names a registry id and a
/// config: a few hundred bytes, or some KiB of kwargs. Anything longer is refused by its length,
/// before a byte of it is decoded (session messages, which carry observations and actions,
/// are bounded apart: `envhub serve --max-request-bytes`).
pub const MAX_OPEN_REQUEST_BYTES: usize = 256 << 10;
/// The deepest nesting of lists and maps an open request may have (kwargs may nest 16 deep;
/// the request, its config and its kwargs map add three).
pub const MAX_OPEN_REQUEST_DEPTH: usize = 32;
/// The most values (a list's or map's items, counted by their separators, and the lists and
/// maps themselves) an open request may have: remote kwargs hold at most 10,000 values.
pub const MAX_OPEN_REQUEST_VALUES: usize = 16_384;

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

/// An open request as it travels: the request and the client's hello.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct OpenMessage {
    /// What to open.
    pub request: OpenRequest,
    /// The client's half of the key exchange.
    pub hello: crate::handshake::ClientHello,
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
    /// The hub's half of the key exchange that gives the session's key (the key itself never
    /// travels: [`crate::handshake`]).
    pub hello: crate::handshake::HubHello,
}
