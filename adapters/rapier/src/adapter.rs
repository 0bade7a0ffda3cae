//! `Rapier`: the adapter, and the one list of the tasks it provides.

use crate::render::{self, RenderOptions};
use crate::task::TaskEnv;
use crate::tasks::{ant, push, reach, rover};
use envhub_core::{Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec};

/// One task of the adapter: its id, episode limit, options and constructor.
pub(crate) struct EnvEntry {
    /// The env id.
    pub(crate) id: &'static str,
    /// Default `max_episode_steps`.
    pub(crate) max_episode_steps: u32,
    /// The task's own `extra` keys (the render keys `width`, `height` come on top).
    pub(crate) options: &'static [&'static str],
    /// Creates the env, validating `config`.
    pub(crate) make: fn(&EnvConfig) -> Result<Box<dyn Env>, EnvError>,
}

macro_rules! entry {
    ($module:ident, $task:ident) => {
        EnvEntry {
            id: $module::ID,
            max_episode_steps: $module::MAX_EPISODE_STEPS,
            options: $module::OPTIONS,
            make: |config| {
                let known: Vec<&str> = $module::OPTIONS
                    .iter()
                    .chain(render::OPTIONS)
                    .copied()
                    .collect();
                let keys = config.extra_keys($module::ID, &known)?;
                let render =
                    RenderOptions::from_config($module::ID, config.render_mode.as_deref(), &keys)?;
                let task = $module::$task::new(config, &keys)?;
                Ok(Box::new(TaskEnv::new($module::ID, task, render)))
            },
        }
    };
}

/// Every task of the adapter. Adding one is a file in `tasks/` and a line here.
const ENVS: &[EnvEntry] = &[
    entry!(reach, Reach),
    entry!(push, Push),
    entry!(ant, Ant),
    entry!(rover, Rover),
];

/// Robot tasks on rapier3d, implemented natively. Always available: rapier is pure Rust and
/// compiled in.
#[derive(Clone, Copy, Debug, Default)]
pub struct Rapier;

impl Rapier {
    fn entry(&self, env_id: &str) -> Result<&'static EnvEntry, EnvError> {
        ENVS.iter()
            .find(|e| e.id == env_id)
            .ok_or_else(|| self.unknown_env(env_id))
    }
}

impl EnvAdapter for Rapier {
    fn name(&self) -> &'static str {
        "rapier"
    }

    fn frameworks(&self) -> &'static [&'static str] {
        &["rapier"]
    }

    fn requires(&self) -> &'static [&'static str] {
        &[]
    }

    fn description(&self) -> &'static str {
        "robot tasks on rapier3d 0.36 (arm reach and push, quadruped, wheeled base on terrain), native Rust"
    }

    fn availability(&self) -> Availability {
        Availability::Available
    }

    fn render_modes(&self) -> &'static [&'static str] {
        &[crate::render::RGB_ARRAY]
    }

    fn list_envs(&self) -> Vec<String> {
        ENVS.iter().map(|e| e.id.to_string()).collect()
    }

    fn spec(&self, env_id: &str, config: &EnvConfig) -> Result<EnvSpec, EnvError> {
        let entry = self.entry(env_id)?;
        // Creating one builds no world (that happens at reset) and validates `config` as
        // `make` does.
        let env = (entry.make)(config)?;
        Ok(EnvSpec {
            env_id: entry.id.to_string(),
            observation_space: env.observation_space().clone(),
            action_space: env.action_space().clone(),
            max_episode_steps: Some(entry.max_episode_steps),
            options: entry
                .options
                .iter()
                .chain(render::OPTIONS)
                .map(|o| o.to_string())
                .collect(),
        })
    }

    fn make(&self, env_id: &str, config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        (self.entry(env_id)?.make)(config)
    }
}
