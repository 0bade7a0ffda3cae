//! What a worker is asked to do, and what it answers when it starts.
//!
//! The owner (client or hub daemon) starts `envhub-worker serve --job '<json>'`; the worker
//! creates its envs, opens the channel and prints one [`WorkerReply`] line on stdout. Only
//! then does the data plane start.

use crate::ChannelName;
use envhub_core::{EnvConfig, Space};
use serde::{Deserialize, Serialize};

/// The work of one worker process.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkerJob {
    /// Adapter name (`classic_control`).
    pub adapter: String,
    /// Framework env id (`CartPole-v1`).
    pub env_id: String,
    /// How to create each env.
    pub config: EnvConfig,
    /// Index of this worker's first env in the session.
    pub env_offset: usize,
    /// Envs this worker hosts.
    pub num_envs: usize,
    /// The channel the owner created.
    pub channel: ChannelName,
    /// The process whose exit ends this worker (the client that uses it).
    pub owner_pid: u32,
    /// Spin at least this long before blocking, in microseconds (0: never spin).
    pub spin_us: u64,
    /// Spin at most this long before blocking, in microseconds.
    #[serde(default)]
    pub max_spin_us: u64,
}

/// The spec a ready worker reports.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ReadySpec {
    /// Observation space of one env.
    pub observation_space: Space,
    /// Action space of one env.
    pub action_space: Space,
    /// Episode limit applied (truncation), if any.
    pub max_episode_steps: Option<u32>,
    /// The worker's pid.
    pub pid: u32,
}

/// The one line a worker prints on stdout when it has started, or failed to.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WorkerReply {
    /// Envs created, channel open.
    Ready(ReadySpec),
    /// It could not start; the message says why and how to fix it.
    Error(String),
}
