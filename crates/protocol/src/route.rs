//! A route: the adapter that runs an entry and its complete config, as the hub decided it and
//! as it travels to a daemon or a remote hub's client.

use envhub_core::EnvConfig;

/// An entry resolved to an adapter and a complete config.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Route {
    /// The adapter that runs it.
    pub adapter: String,
    /// The framework env id.
    pub env_id: String,
    /// The entry's settings merged with the caller's.
    pub config: EnvConfig,
    /// The Python environment its workers run in, provisioned (the entry's `python_env`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub python: Option<envhub_shm::WorkerPython>,
}
