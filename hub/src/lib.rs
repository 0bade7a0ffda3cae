//! envhub: the environment registry, task matching and (soon) the hub and its client.
//!
//! The registry is plain data: RoboSmith-format YAML, loaded strictly (an unknown field or a
//! duplicate id is an error with file and line, never silently ignored) and searched in
//! memory. It is small (tens to hundreds of entries), so search is a linear scan that keeps
//! file order as the tie-breaker, which makes results predictable for people.

mod async_step;
mod batch;
mod bounded;
mod builtin_assets;
mod catalog;
mod daemon;
mod daemon_client;
mod daemon_guard;
mod entry;
mod env;
pub mod env_vars;
mod error;
#[cfg(test)]
mod fuzz;
mod hub;
mod launcher;
mod matching;
mod placement;
mod python_host;
mod registry;
mod remote;
mod results;
mod routing;
mod session_options;
mod settings;
mod tags;
mod vec_env;
mod worker_binary;
mod worker_link;

pub use batch::{Batch, Frame};
pub use catalog::{AdapterInfo, Host, refresh_adapters};
pub use daemon::{default_socket, serve};
pub use daemon_client::DaemonClient;
pub use entry::EnvEntry;
pub use env::{Env, Step};
pub use envhub_core::{AutoresetMode, EnvConfig, ResetOptions, Space};
pub use envhub_shm::SlotLease;
pub use error::HubError;
pub use hub::{Hub, make, make_vec};
pub use matching::{Candidate, MatchError, TaskMatch, TaskSpec, match_task};
pub use placement::{LOCAL, Placement};
pub use python_host::{python_interpreter, set_default_python};
pub use registry::{DEFAULT_REGISTRY_NAME, Registry, RegistryError, SearchHit, SearchQuery};
pub use remote::client::Network;
pub use remote::net::{ENVHUB_CONNECT, ENVHUB_MULTICAST, NetConfig};
pub use remote::serve::{HubInfo, HubNode, ServePolicy, host_name, join};
pub use routing::{Route, merge_config};
pub use session_options::SessionOptions;
pub use settings::{CONFIG_FILE_NAME, OneOrMany, Settings, SettingsError};
pub use vec_env::VecEnv;
pub use worker_binary::{set_default_worker_binary, worker_binary};
pub use worker_link::InterruptCheck;
