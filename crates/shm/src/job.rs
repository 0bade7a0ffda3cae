//! What a worker is asked to do, and what it answers when it starts.
//!
//! The owner (client or hub daemon) starts `envhub-worker serve --job '<json>'`; the worker
//! creates its envs, opens the channel and prints one [`WorkerReply`] line on stdout. Only
//! then does the data plane start.

use crate::{ChannelName, SlotsName};
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
    /// How to create each env (its `num_envs`: this worker's, `worker_envs`: what the
    /// adapter builds).
    pub config: EnvConfig,
    /// Index of this worker's first env in the session (its first row in the batch slots).
    pub env_offset: usize,
    /// Envs this worker hosts (of the session's `session_envs`). `num_envs` on the wire, as
    /// the Python worker reads it.
    #[serde(rename = "num_envs")]
    pub worker_envs: usize,
    /// Envs of the whole session (rows of a batch slot).
    pub session_envs: usize,
    /// The channel the owner created.
    pub channel: ChannelName,
    /// The session's batch slots, which the worker writes its results into.
    pub slots: SlotsName,
    /// This worker's index in the session (its channel's doorbell).
    #[serde(default)]
    pub worker_index: usize,
    /// Workers of the session, hence doorbells (0: none, every send notifies).
    #[serde(default)]
    pub session_workers: usize,
    /// The process whose exit ends this worker (the client that uses it).
    pub owner_pid: u32,
    /// Spin at least this long before blocking, in microseconds (0: never spin).
    pub spin_us: u64,
    /// Spin at most this long before blocking, in microseconds.
    #[serde(default)]
    pub max_spin_us: u64,
    /// Bytes per env of the slots' typed info columns (0: none; only a client that reads
    /// them asks for them, and only the Python worker writes them).
    #[serde(default)]
    pub info_row_bytes: usize,
    /// The Python environment a Python-hosted adapter runs in (`None`: the hub's interpreter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub python: Option<WorkerPython>,
}

/// A provisioned Python environment that workers run in: its interpreter and variables.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorkerPython {
    /// Its name in the registry (`metaworld`).
    pub name: String,
    /// The venv's interpreter.
    pub interpreter: std::path::PathBuf,
    /// Variables its workers run with (`MUJOCO_GL=egl`).
    #[serde(default, skip_serializing_if = "std::collections::BTreeMap::is_empty")]
    pub env: std::collections::BTreeMap<String, String>,
    /// Folders put first on the worker's `sys.path`: the starting install's own overlay,
    /// through which the venv imports that install's `envhub` package.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sys_path: Vec<std::path::PathBuf>,
    /// The `envhub` package folder the worker must run (the starting install's), checked
    /// against what its ready line reports.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub package: Option<std::path::PathBuf>,
    /// A file in the venv each worker holds a shared `flock` on while it runs (its
    /// manifest), so that `envhub env remove` can tell the environment is in use.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hold: Option<std::path::PathBuf>,
}

/// The version of what the hub and its workers say to each other (the job, the ready line,
/// the data plane). The hub passes its own to Python workers (`ENVHUB_WORKER_PROTOCOL`),
/// which refuse another, and every worker reports its own in its ready line.
pub const WORKER_PROTOCOL: u32 = 1;

/// Who a started worker is: the protocol it speaks and where its code comes from.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct WorkerIdentity {
    /// Its [`WORKER_PROTOCOL`].
    pub protocol: u32,
    /// The `envhub` package folder it imported (a Python worker), or its executable.
    pub module: std::path::PathBuf,
    /// The envhub version it was built as.
    pub version: String,
}

impl WorkerIdentity {
    /// This build's identity, with `module` for where its code is.
    pub fn current(module: std::path::PathBuf) -> WorkerIdentity {
        WorkerIdentity {
            protocol: WORKER_PROTOCOL,
            module,
            version: env!("CARGO_PKG_VERSION").to_string(),
        }
    }
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
    /// Frames per second of the env's rendering (Gymnasium's `metadata["render_fps"]`), if it
    /// says. Absent from the lines of workers that predate it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_fps: Option<f64>,
    /// The worker's pid.
    pub pid: u32,
    /// Its protocol version and code. Absent from the lines of workers that predate it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub worker: Option<WorkerIdentity>,
}

/// The one line a worker prints on stdout when it has started, or failed to.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
#[expect(
    clippy::large_enum_variant,
    reason = "one reply per worker start, read once: boxing would save nothing"
)]
pub enum WorkerReply {
    /// Envs created, channel open.
    Ready(ReadySpec),
    /// It could not start; the message says why and how to fix it.
    Error(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn render_fps_is_optional_in_the_ready_line() {
        let spec = ReadySpec {
            observation_space: Space::box_f32(&[2], -1.0, 1.0),
            action_space: Space::discrete(2),
            max_episode_steps: Some(500),
            render_fps: Some(50.0),
            pid: 7,
            worker: None,
        };
        let line = serde_json::to_string(&WorkerReply::Ready(spec.clone())).unwrap();
        assert!(line.contains(r#""render_fps":50.0"#), "{line}");
        match serde_json::from_str(&line).unwrap() {
            WorkerReply::Ready(back) => assert_eq!(back, spec),
            WorkerReply::Error(e) => panic!("{e}"),
        }
        // A worker that predates the field (or an env that does not say) leaves it out.
        let old = line.replace(r#","render_fps":50.0"#, "");
        match serde_json::from_str(&old).unwrap() {
            WorkerReply::Ready(back) => assert_eq!(back.render_fps, None),
            WorkerReply::Error(e) => panic!("{e}"),
        }
        let none = ReadySpec {
            render_fps: None,
            ..spec
        };
        let line = serde_json::to_string(&none).unwrap();
        assert!(!line.contains("render_fps"), "{line}");
    }
}
