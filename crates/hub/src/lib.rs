//! envhub: the facade — [`Hub`] (the catalog, routing ids to adapters, starting workers here
//! or through a hub daemon, placing envs over a directory of hubs), the servers (`envhub
//! serve`: the daemon's control socket, a hub on the network) and the `envhub` CLI.
//!
//! The layers below, each a crate of one concept (arrows point down only; see
//! `docs/design/architecture.md`, checked by `scripts/check_layers.py`):
//! - `envhub-catalog`: registry files, entries, search, matching (pure logic);
//! - `envhub-protocol`: the messages between processes and their validation (no I/O);
//! - `envhub-session`: the session engine (slots, worker links, batches, async steps);
//! - `envhub-net`: hubs across machines over Zenoh.
//!
//! This crate re-exports what a Rust user needs, so `envhub_hub::{Hub, VecEnv, Registry, ...}`
//! is the whole public API.

mod adapters;
mod bounded;
mod daemon;
mod daemon_client;
mod daemon_guard;
mod fork_server;
#[cfg(test)]
mod fuzz;
mod hub;
mod hub_node;
mod launcher;
mod placement;
pub mod provision;
mod python_host;
mod routing;
mod settings;
mod spawner;
mod worker_binary;

pub use adapters::{AdapterInfo, Host, refresh_adapters};
pub use daemon::{default_socket, serve};
pub use daemon_client::DaemonClient;
pub use envhub_catalog::{
    Candidate, DEFAULT_REGISTRY_NAME, EnvEntry, FrameworkDefaults, MatchError, PythonEnvs,
    Registry, RegistryError, SearchHit, SearchQuery, TaskMatch, TaskSpec, match_task,
};
pub use envhub_core::env_vars;
pub use envhub_core::{AutoresetMode, EnvConfig, ResetOptions, Space};
pub use envhub_net::local;
pub use envhub_net::{
    DEFAULT_IDLE_TIMEOUT, DEFAULT_MAX_ENVS, DEFAULT_MAX_REQUEST_BYTES,
    DEFAULT_MAX_SESSIONS_PER_CLIENT, DEFAULT_MAX_STEP_TIMEOUT, ENVHUB_CONNECT, ENVHUB_MULTICAST,
    NetConfig, Network, RESENT, ServePolicy, UNSEALED, client_share,
};
pub use envhub_protocol::{Frame, HubError, HubInfo, Route};
pub use envhub_session::{Batch, Env, InterruptCheck, LOCAL, SessionOptions, Step, VecEnv};
pub use envhub_shm::SlotLease;
pub use hub::{Hub, make, make_vec};
pub use hub_node::{HubNode, host_name, join};
pub use placement::Placement;
pub use python_host::{python_interpreter, set_default_python};
pub use routing::merge_config;
pub use settings::{CONFIG_FILE_NAME, OneOrMany, Settings, SettingsError};
pub use worker_binary::{set_default_worker_binary, worker_binary};
