//! What a hub lets remote clients do, and the limits it keeps by default.
//!
//! Every limit is on unless the operator lifts it: a hub answers anyone who reaches it, and a
//! client (buggy or hostile) must not be able to exhaust its memory, processes or threads.
//! Each refusal names the limit and the `envhub serve` flag that changes it.

use std::time::Duration;

/// Envs a hub runs for remote clients at once, by default.
pub const DEFAULT_MAX_ENVS: usize = 4096;
/// Worker processes per core a hub runs for remote clients at once, by default.
pub const DEFAULT_WORKERS_PER_CORE: usize = 4;
/// Sessions one client may hold open on a hub at once, by default.
pub const DEFAULT_MAX_SESSIONS_PER_CLIENT: usize = 16;
/// The longest `step_timeout` a remote client may ask for, by default.
pub const DEFAULT_MAX_STEP_TIMEOUT: Duration = Duration::from_secs(300);
/// A remote session whose client sends nothing for this long is closed, by default.
pub const DEFAULT_IDLE_TIMEOUT: Duration = Duration::from_secs(900);
/// The largest message a hub accepts from the network, by default (requests carry actions:
/// 64 MiB is 16M float32 values).
pub const DEFAULT_MAX_REQUEST_BYTES: usize = 64 << 20;
/// Queries (info, catalog, open, ...) a hub answers at once; more are refused as busy.
pub const MAX_QUERIES_IN_FLIGHT: usize = 32;
/// Requests waiting for one session; a client sends one at a time (and resends it), so more
/// are a flood and are answered as busy.
pub const SESSION_QUEUE: usize = 8;

/// What a hub lets remote clients do.
#[derive(Clone, Debug)]
pub struct ServePolicy {
    /// Envs this hub hosts for remote clients at once, over all sessions (`None`: no limit).
    pub max_envs: Option<usize>,
    /// Worker processes it runs for remote clients at once (`None`: no limit).
    pub max_workers: Option<usize>,
    /// Envs one client (by its identity key) may hold at once (`None`: up to `max_envs`).
    pub max_envs_per_client: Option<usize>,
    /// Worker processes one client (by its identity key) may hold at once (`None`: up to
    /// `max_workers`). With the envs' share, what keeps one key from taking the whole hub
    /// and locking every other key out.
    pub max_workers_per_client: Option<usize>,
    /// Sessions one client (by its identity key) may hold at once (`None`: no limit).
    /// Identities are free to make: the per-client limits stop a runaway client and keep
    /// room for others against one key; the hub-wide limits bound many keys together.
    pub max_sessions_per_client: Option<usize>,
    /// The longest `step_timeout` a client may ask for.
    pub max_step_timeout: Duration,
    /// A session whose client sends nothing for this long is closed (`None`: never).
    pub idle_timeout: Option<Duration>,
    /// The largest message accepted from the network (Zenoh drops larger ones).
    pub max_request_bytes: usize,
    /// Let remote clients name files on this hub (`asset_path`, `xml_file`, ...).
    pub allow_remote_files: bool,
    /// Build the Python environment an entry needs for a remote client when it is not
    /// provisioned yet (installing packages is the operator's decision).
    pub allow_provision: bool,
    /// Listen beyond loopback without credentials (`--insecure-listen`).
    pub insecure_listen: bool,
    /// Send and answer multicast scouts without credentials (`--multicast-scouting`, with
    /// `--insecure-listen` on a listener beyond loopback).
    pub multicast_scouting: bool,
}

/// A client's default share of a hub-wide limit: half of it, rounded up, so that one key
/// always leaves room for another.
pub fn client_share(limit: Option<usize>) -> Option<usize> {
    limit.map(|max| max.div_ceil(2))
}

impl Default for ServePolicy {
    fn default() -> Self {
        let max_envs = Some(DEFAULT_MAX_ENVS);
        let max_workers = Some(DEFAULT_WORKERS_PER_CORE * envhub_session::cores());
        ServePolicy {
            max_envs,
            max_workers,
            max_envs_per_client: client_share(max_envs),
            max_workers_per_client: client_share(max_workers),
            max_sessions_per_client: Some(DEFAULT_MAX_SESSIONS_PER_CLIENT),
            max_step_timeout: DEFAULT_MAX_STEP_TIMEOUT,
            idle_timeout: Some(DEFAULT_IDLE_TIMEOUT),
            max_request_bytes: DEFAULT_MAX_REQUEST_BYTES,
            allow_remote_files: false,
            allow_provision: false,
            insecure_listen: false,
            multicast_scouting: false,
        }
    }
}

impl ServePolicy {
    /// No limits at all (tests of the limits' absence, trusted benchmarks).
    pub fn unlimited() -> Self {
        ServePolicy {
            max_envs: None,
            max_workers: None,
            max_envs_per_client: None,
            max_workers_per_client: None,
            max_sessions_per_client: None,
            max_step_timeout: Duration::MAX,
            idle_timeout: None,
            ..ServePolicy::default()
        }
    }
}
