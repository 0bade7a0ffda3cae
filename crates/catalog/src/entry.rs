//! One environment of the catalog, in RoboSmith's format plus envhub's extensions.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

fn default_obs_type() -> String {
    "state".to_string()
}

fn default_action_type() -> String {
    "continuous".to_string()
}

/// An environment of the registry.
///
/// The first twelve fields are RoboSmith's, with its defaults, so a RoboSmith registry loads
/// unchanged. `kwargs`, `max_episode_steps`, `asset_path`, `adapter` and `python_env` are
/// envhub's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvEntry {
    /// Unique id in the registry (`mujoco-ant`).
    pub id: String,
    /// Display name.
    pub name: String,
    /// Framework that provides the env (`gymnasium`, `maniskill`, ...; aliases allowed).
    pub framework: String,
    /// The framework's own id (`Ant-v5`).
    pub env_id: String,
    /// Robot morphology (`arm`, `quadruped`, `biped`, `dexterous_hand`, `mobile_base`, `custom`).
    pub robot_type: String,
    /// Specific robot (`franka`, `ant`).
    #[serde(default)]
    pub robot_model: String,
    /// Environment category (`tabletop`, `floor`, `terrain`, `aerial`, `aquatic`).
    pub env_type: String,
    /// Words that describe the task, used by search and matching.
    #[serde(default)]
    pub task_tags: Vec<String>,
    /// `state`, `image`, ...
    #[serde(default = "default_obs_type")]
    pub obs_type: String,
    /// `continuous` or `discrete`.
    #[serde(default = "default_action_type")]
    pub action_type: String,
    /// One line for people.
    #[serde(default)]
    pub description: String,
    /// Where it comes from (a package name).
    #[serde(default)]
    pub source: String,
    /// Arguments passed when the env is created (Gymnasium's `make(id, **kwargs)`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub kwargs: BTreeMap<String, serde_json::Value>,
    /// Episode limit, overriding the framework's default.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_episode_steps: Option<u32>,
    /// Model file; a relative path is relative to the registry file that names it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub asset_path: Option<PathBuf>,
    /// Pins the adapter that runs this entry (otherwise the hub picks the best one).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub adapter: Option<String>,
    /// The Python environment (`python_envs:` of the registry) its workers run in; otherwise
    /// its framework's (`frameworks:`), else the hub's interpreter.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub python_env: Option<String>,
}

impl EnvEntry {
    /// The value of a filterable field by its YAML name.
    pub(crate) fn field(&self, name: &str) -> &str {
        match name {
            "framework" => &self.framework,
            "robot_type" => &self.robot_type,
            "robot_model" => &self.robot_model,
            "env_type" => &self.env_type,
            "action_type" => &self.action_type,
            "obs_type" => &self.obs_type,
            other => unreachable!("no filterable field `{other}`"),
        }
    }

    /// A one-line summary: `[framework] name (env_id) — description`.
    pub fn summary(&self) -> String {
        format!(
            "[{}] {} ({}) — {}",
            self.framework, self.name, self.env_id, self.description
        )
    }
}
