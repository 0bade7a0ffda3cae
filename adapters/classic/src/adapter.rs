//! `ClassicControl`: the adapter, and the one list of the envs it provides.

use crate::classic_env::{ClassicEnv, EnvEntry};
use crate::{acrobot, cartpole, mountain_car, mountain_car_continuous, pendulum};
use envhub_core::{Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec};

/// Every env of the adapter. Adding one is a file with its `ENTRY` and a line here.
const ENVS: &[EnvEntry] = &[
    cartpole::ENTRY,
    pendulum::ENTRY,
    mountain_car::ENTRY,
    mountain_car_continuous::ENTRY,
    acrobot::ENTRY,
];

/// Gymnasium's classic-control envs, implemented natively. Always available: it needs nothing
/// outside this crate.
#[derive(Clone, Copy, Debug, Default)]
pub struct ClassicControl;

impl ClassicControl {
    /// Creates `env_id` as a [`ClassicEnv`], whose state can be read and set.
    pub fn make_classic(
        &self,
        env_id: &str,
        config: &EnvConfig,
    ) -> Result<Box<dyn ClassicEnv>, EnvError> {
        (self.entry(env_id)?.make)(config)
    }

    fn entry(&self, env_id: &str) -> Result<&'static EnvEntry, EnvError> {
        ENVS.iter()
            .find(|e| e.id == env_id)
            .ok_or_else(|| self.unknown_env(env_id))
    }
}

impl EnvAdapter for ClassicControl {
    fn name(&self) -> &'static str {
        "classic_control"
    }

    fn frameworks(&self) -> &'static [&'static str] {
        &["gymnasium"]
    }

    fn requires(&self) -> &'static [&'static str] {
        &[]
    }

    fn description(&self) -> &'static str {
        "Gymnasium 1.4 classic control (CartPole, Pendulum, MountainCar, Acrobot), native Rust"
    }

    fn availability(&self) -> Availability {
        Availability::Available
    }

    fn render_modes(&self) -> &'static [&'static str] {
        // Native classic-control envs do not draw: an entry made with a render mode goes to the
        // Gymnasium-hosted adapter (the same dynamics, bit for bit).
        &[]
    }

    fn list_envs(&self) -> Vec<String> {
        ENVS.iter().map(|e| e.id.to_string()).collect()
    }

    fn spec(&self, env_id: &str, config: &EnvConfig) -> Result<EnvSpec, EnvError> {
        let entry = self.entry(env_id)?;
        // Creating one is cheap (no simulator, no generator until the first reset) and
        // validates `config` exactly as `make` does.
        let env = (entry.make)(config)?;
        Ok(EnvSpec {
            env_id: entry.id.to_string(),
            observation_space: env.observation_space().clone(),
            action_space: env.action_space().clone(),
            max_episode_steps: Some(entry.max_episode_steps),
            options: entry.options.iter().map(|o| o.to_string()).collect(),
        })
    }

    fn make(&self, env_id: &str, config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        Ok(self.make_classic(env_id, config)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn lists_the_five_envs_with_gymnasium_limits() {
        let adapter = ClassicControl;
        assert_eq!(
            adapter.list_envs(),
            [
                "CartPole-v1",
                "Pendulum-v1",
                "MountainCar-v0",
                "MountainCarContinuous-v0",
                "Acrobot-v1"
            ]
        );
        let limits: Vec<_> = adapter
            .list_envs()
            .iter()
            .map(|id| {
                adapter
                    .spec(id, &EnvConfig::default())
                    .unwrap()
                    .max_episode_steps
                    .unwrap()
            })
            .collect();
        assert_eq!(limits, [500, 200, 200, 999, 500]);
        assert!(adapter.availability().is_available());
        assert_eq!(adapter.frameworks(), ["gymnasium"]);
    }

    #[test]
    fn spec_lists_options_and_validates_them() {
        let adapter = ClassicControl;
        let spec = adapter.spec("Pendulum-v1", &EnvConfig::default()).unwrap();
        assert_eq!(spec.options, ["g"]);
        let mut config = EnvConfig::default();
        config.extra.insert("gravity".into(), json!(9.8));
        assert!(adapter.spec("Pendulum-v1", &config).is_err());
        assert!(adapter.make("Pendulum-v1", &config).is_err());
    }

    #[test]
    fn unknown_env_suggests_the_closest() {
        let err = ClassicControl
            .make("CartPole-v0", &EnvConfig::default())
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("has no env `CartPole-v0`"), "{err}");
        assert!(err.contains("did you mean `CartPole-v1`"), "{err}");
    }

    #[test]
    fn refuses_render_modes() {
        let config = EnvConfig {
            render_mode: Some("rgb_array".into()),
            ..EnvConfig::default()
        };
        let err = ClassicControl
            .make("Acrobot-v1", &config)
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("render mode `rgb_array` is not supported"),
            "{err}"
        );
    }
}
