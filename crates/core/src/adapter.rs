//! The `EnvAdapter` trait: one simulator family, and whether it can run here.

use crate::{Env, EnvConfig, EnvError, Space};
use serde::{Deserialize, Serialize};

/// Whether an adapter's dependencies are present.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "status", rename_all = "snake_case")]
pub enum Availability {
    /// Everything it needs is here.
    Available,
    /// Something is missing.
    Unavailable {
        /// What is missing, concretely (`libmujoco.so not found in ...`).
        reason: String,
        /// The command or step that fixes it.
        hint: String,
    },
}

impl Availability {
    /// Whether the adapter can run.
    pub fn is_available(&self) -> bool {
        matches!(self, Availability::Available)
    }
}

/// What an adapter says about one of its envs before creating it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EnvSpec {
    /// The framework's env id (`CartPole-v1`).
    pub env_id: String,
    /// Observation space with the default options.
    pub observation_space: Space,
    /// Action space with the default options.
    pub action_space: Space,
    /// The env's own episode limit, as the framework registers it.
    pub max_episode_steps: Option<u32>,
    /// Options the env takes through `kwargs`/`extra`.
    pub options: Vec<String>,
}

/// A simulator family: it knows which envs it provides and creates them.
pub trait EnvAdapter: Send + Sync {
    /// Unique adapter name (`classic_control`, `mujoco`, `gymnasium`).
    fn name(&self) -> &'static str;

    /// Canonical framework names it serves; the first is its main one.
    fn frameworks(&self) -> &'static [&'static str];

    /// What must be installed, in words (`libmujoco 3.17`, `python: gymnasium`).
    fn requires(&self) -> &'static [&'static str];

    /// One line for `envhub adapters`.
    fn description(&self) -> &'static str;

    /// Whether its dependencies are present, and if not, why and how to fix it.
    fn availability(&self) -> Availability;

    /// The render modes its envs draw (`rgb_array`); empty when none renders. The hub routes
    /// an entry made with another mode to an adapter that draws it, unless the entry pins
    /// this one.
    fn render_modes(&self) -> &'static [&'static str];

    /// Every env id it implements natively. Empty for a generic adapter that forwards any id
    /// to its framework.
    fn list_envs(&self) -> Vec<String>;

    /// Whether it can create `env_id` (a generic adapter may accept ids it does not list).
    fn supports(&self, env_id: &str) -> bool {
        self.list_envs().iter().any(|e| e == env_id)
    }

    /// The spaces and defaults of `env_id` under `config`, without creating a simulator
    /// where that can be avoided.
    fn spec(&self, env_id: &str, config: &EnvConfig) -> Result<EnvSpec, EnvError>;

    /// Creates one env instance. Options in `config.extra` that the env does not know are an
    /// error naming the valid ones. Time limits are applied by the caller.
    fn make(&self, env_id: &str, config: &EnvConfig) -> Result<Box<dyn Env>, EnvError>;

    /// The error for an id this adapter does not provide, with the closest ones it does.
    fn unknown_env(&self, env_id: &str) -> EnvError {
        let known = self.list_envs();
        EnvError::UnknownEnv {
            adapter: self.name().to_string(),
            env_id: env_id.to_string(),
            closest: crate::closest(env_id, known.iter().map(String::as_str), 3),
            known,
        }
    }
}
