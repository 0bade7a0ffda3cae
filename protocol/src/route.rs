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
}
