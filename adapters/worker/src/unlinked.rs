//! The MuJoCo adapters in a worker that cannot load libmujoco: they list their envs and say
//! what is missing, from [`envhub_mujoco`]'s constants alone (see [`envhub_mujoco::AdapterInfo`]
//! for why constants only).

use envhub_core::{Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec};
use envhub_mujoco::AdapterInfo;

/// One MuJoCo adapter, unavailable for `reason` (fixed by `hint`).
pub struct Unlinked {
    info: &'static AdapterInfo,
    reason: String,
    hint: String,
}

impl Unlinked {
    /// Both MuJoCo adapters (`mujoco`, `custom_mjcf`), unavailable for the same reason.
    pub fn both(reason: &str, hint: &str) -> [Box<dyn EnvAdapter>; 2] {
        let one = |info| -> Box<dyn EnvAdapter> {
            Box::new(Unlinked {
                info,
                reason: reason.to_string(),
                hint: hint.to_string(),
            })
        };
        [
            one(&envhub_mujoco::MUJOCO_INFO),
            one(&envhub_mujoco::CUSTOM_MJCF_INFO),
        ]
    }

    fn unavailable(&self) -> EnvError {
        EnvError::Unavailable {
            adapter: self.info.name.to_string(),
            reason: self.reason.clone(),
            hint: self.hint.clone(),
        }
    }

    fn check(&self, env_id: &str) -> EnvError {
        if self.supports(env_id) {
            self.unavailable()
        } else {
            self.unknown_env(env_id)
        }
    }
}

impl EnvAdapter for Unlinked {
    fn name(&self) -> &'static str {
        self.info.name
    }

    fn frameworks(&self) -> &'static [&'static str] {
        self.info.frameworks
    }

    fn requires(&self) -> &'static [&'static str] {
        self.info.requires
    }

    fn description(&self) -> &'static str {
        self.info.description
    }

    fn availability(&self) -> Availability {
        Availability::Unavailable {
            reason: self.reason.clone(),
            hint: self.hint.clone(),
        }
    }

    fn render_modes(&self) -> &'static [&'static str] {
        self.info.render_modes
    }

    fn list_envs(&self) -> Vec<String> {
        self.info
            .env_ids
            .iter()
            .map(|(id, _)| id.to_string())
            .collect()
    }

    fn supports(&self, env_id: &str) -> bool {
        self.info.any_env_id || self.info.env_ids.iter().any(|(id, _)| *id == env_id)
    }

    fn spec(&self, env_id: &str, _config: &EnvConfig) -> Result<EnvSpec, EnvError> {
        Err(self.check(env_id))
    }

    fn make(&self, env_id: &str, _config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        Err(self.check(env_id))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_the_envs_and_says_why_it_cannot_make_them() {
        let [mujoco, custom] = Unlinked::both("libmujoco 3.17.0 not found", "pip install it");
        assert_eq!((mujoco.name(), custom.name()), ("mujoco", "custom_mjcf"));
        assert!(mujoco.list_envs().contains(&"Ant-v5".to_string()));
        assert!(custom.supports("AnyModel-v0") && !mujoco.supports("AnyModel-v0"));
        let err = mujoco
            .make("Ant-v5", &EnvConfig::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("libmujoco 3.17.0 not found") && err.contains("pip install it"),
            "{err}"
        );
        let err = mujoco
            .spec("Ant-v4", &EnvConfig::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("Ant-v5"),
            "an unknown id names the closest: {err}"
        );
    }
}
