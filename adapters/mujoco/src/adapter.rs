//! The two adapters, `mujoco` (Gymnasium's v5 suite) and `custom_mjcf` (a user's model file),
//! and what they say about themselves when libmujoco is not linked in.

use crate::modes::RGB_ARRAY;
use envhub_core::{Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec};

/// The libmujoco version this crate binds (mujoco-rs 7.0), the `mujoco` wheel's version too.
pub const LIBMUJOCO_VERSION: &str = "3.17.0";

/// Every env id of the `mujoco` adapter, with Gymnasium's registered episode limit. The same
/// list as `tasks::ENVS` (a test checks), kept here so that a build without libmujoco can
/// still say which envs it would run.
const ENV_IDS: &[(&str, u32)] = &[
    ("Ant-v5", 1000),
    ("HalfCheetah-v5", 1000),
    ("Hopper-v5", 1000),
    ("Walker2d-v5", 1000),
    ("Humanoid-v5", 1000),
    ("HumanoidStandup-v5", 1000),
    ("Swimmer-v5", 1000),
    ("Reacher-v5", 50),
    ("Pusher-v5", 100),
    ("InvertedPendulum-v5", 1000),
    ("InvertedDoublePendulum-v5", 1000),
];

/// What one of the two adapters says about itself, as a constant. `envhub-worker`, which
/// links no libmujoco so that it starts where the library is missing, describes the adapters
/// from these: it may take only constants from this crate (they are copied into the binary),
/// since calling any of its code would link libmujoco into it.
pub struct AdapterInfo {
    /// [`EnvAdapter::name`].
    pub name: &'static str,
    /// [`EnvAdapter::frameworks`].
    pub frameworks: &'static [&'static str],
    /// [`EnvAdapter::requires`].
    pub requires: &'static [&'static str],
    /// [`EnvAdapter::description`].
    pub description: &'static str,
    /// [`EnvAdapter::render_modes`].
    pub render_modes: &'static [&'static str],
    /// [`EnvAdapter::list_envs`], with each env's episode limit.
    pub env_ids: &'static [(&'static str, u32)],
    /// Whether any env id is accepted ([`EnvAdapter::supports`]): the model comes from
    /// `asset_path`.
    pub any_env_id: bool,
}

/// The `mujoco` adapter's self-description.
pub const MUJOCO_INFO: AdapterInfo = AdapterInfo {
    name: "mujoco",
    frameworks: &["gymnasium"],
    requires: &[
        "libmujoco 3.17.0 (`pip install 'envhub[mujoco]'`; in the repository `make build`)",
        "python: gymnasium 1.4 (for its MJCF assets)",
    ],
    description: "Gymnasium 1.4 MuJoCo v5 suite (Ant, HalfCheetah, Hopper, Humanoid, ...), native on MuJoCo 3.17",
    render_modes: &[RGB_ARRAY],
    env_ids: ENV_IDS,
    any_env_id: false,
};

/// The `custom_mjcf` adapter's self-description.
pub const CUSTOM_MJCF_INFO: AdapterInfo = AdapterInfo {
    name: "custom_mjcf",
    frameworks: &["custom_mjcf"],
    requires: &[
        "libmujoco 3.17.0 (`pip install 'envhub[mujoco]'`; in the repository `make build`)",
    ],
    description: "any MJCF or URDF model (`asset_path`) on MuJoCo 3.17: obs qpos+qvel, action scaled ctrl",
    render_modes: &[RGB_ARRAY],
    env_ids: &[],
    any_env_id: true,
};

/// Gymnasium 1.4's MuJoCo `-v5` envs, stepped natively on libmujoco 3.17 with Gymnasium's own
/// model files. Available when the worker links libmujoco and the `gymnasium` package (for its
/// MJCF assets) can be found; see [`crate`] for how.
#[derive(Default)]
pub struct Mujoco {
    #[cfg(feature = "libmujoco")]
    models: crate::sim::ModelCache,
}

/// A custom MuJoCo model: `asset_path` names an MJCF or URDF file. Observation `qpos ++ qvel`,
/// action the actuators' controls scaled from `[-1, 1]` to their `ctrlrange`, reward 0 unless
/// `extra` configures one (forward velocity of a body minus a control cost).
#[derive(Default)]
pub struct CustomMjcf {
    #[cfg(feature = "libmujoco")]
    models: crate::sim::ModelCache,
}

#[cfg(not(feature = "libmujoco"))]
fn not_linked() -> (String, String) {
    (
        "built without the `mujoco` feature: this `envhub-worker` does not link libmujoco".into(),
        "run `make build`: it copies libmujoco 3.17.0 from the `mujoco` wheel into `.build/mujoco/lib` \
         and builds the worker with `--features envhub-worker/mujoco`"
            .into(),
    )
}

#[cfg(not(feature = "libmujoco"))]
fn unavailable(adapter: &str) -> EnvError {
    let (reason, hint) = not_linked();
    EnvError::Unavailable {
        adapter: adapter.to_string(),
        reason,
        hint,
    }
}

impl Mujoco {
    /// Creates `env_id` as a [`crate::MujocoEnv`], whose simulator state can be read and set.
    #[cfg(feature = "libmujoco")]
    pub fn make_mujoco(
        &self,
        env_id: &str,
        config: &EnvConfig,
    ) -> Result<crate::MujocoEnv, EnvError> {
        let entry = crate::tasks::entry(env_id).ok_or_else(|| self.unknown_env(env_id))?;
        crate::MujocoEnv::new(entry, config, &self.models)
    }
}

impl EnvAdapter for Mujoco {
    fn name(&self) -> &'static str {
        MUJOCO_INFO.name
    }

    fn frameworks(&self) -> &'static [&'static str] {
        MUJOCO_INFO.frameworks
    }

    fn requires(&self) -> &'static [&'static str] {
        MUJOCO_INFO.requires
    }

    fn description(&self) -> &'static str {
        MUJOCO_INFO.description
    }

    fn availability(&self) -> Availability {
        #[cfg(feature = "libmujoco")]
        return crate::assets::availability();
        #[cfg(not(feature = "libmujoco"))]
        {
            let (reason, hint) = not_linked();
            Availability::Unavailable { reason, hint }
        }
    }

    fn render_modes(&self) -> &'static [&'static str] {
        &[RGB_ARRAY]
    }

    fn list_envs(&self) -> Vec<String> {
        ENV_IDS.iter().map(|(id, _)| id.to_string()).collect()
    }

    fn spec(&self, env_id: &str, config: &EnvConfig) -> Result<EnvSpec, EnvError> {
        let Some(&(id, limit)) = ENV_IDS.iter().find(|(id, _)| *id == env_id) else {
            return Err(self.unknown_env(env_id));
        };
        #[cfg(feature = "libmujoco")]
        {
            let env = self.make_mujoco(id, config)?;
            let _ = limit; // the same as the entry's (a test checks)
            Ok(EnvSpec {
                env_id: id.to_string(),
                observation_space: env.observation_space().clone(),
                action_space: env.action_space().clone(),
                max_episode_steps: crate::tasks::entry(id).map(|e| e.max_episode_steps),
                options: env.options(),
            })
        }
        #[cfg(not(feature = "libmujoco"))]
        {
            let _ = (id, limit, config);
            Err(unavailable(self.name()))
        }
    }

    fn make(&self, env_id: &str, config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        #[cfg(feature = "libmujoco")]
        return Ok(Box::new(self.make_mujoco(env_id, config)?));
        #[cfg(not(feature = "libmujoco"))]
        {
            if !self.supports(env_id) {
                return Err(self.unknown_env(env_id));
            }
            let _ = config;
            Err(unavailable(self.name()))
        }
    }
}

impl CustomMjcf {
    /// Creates the env for `config.asset_path` as a [`crate::MujocoEnv`].
    #[cfg(feature = "libmujoco")]
    pub fn make_mujoco(
        &self,
        env_id: &str,
        config: &EnvConfig,
    ) -> Result<crate::MujocoEnv, EnvError> {
        crate::custom::make(env_id, config, &self.models)
    }
}

impl EnvAdapter for CustomMjcf {
    fn name(&self) -> &'static str {
        CUSTOM_MJCF_INFO.name
    }

    fn frameworks(&self) -> &'static [&'static str] {
        CUSTOM_MJCF_INFO.frameworks
    }

    fn requires(&self) -> &'static [&'static str] {
        CUSTOM_MJCF_INFO.requires
    }

    fn description(&self) -> &'static str {
        CUSTOM_MJCF_INFO.description
    }

    fn availability(&self) -> Availability {
        #[cfg(feature = "libmujoco")]
        return Availability::Available;
        #[cfg(not(feature = "libmujoco"))]
        {
            let (reason, hint) = not_linked();
            Availability::Unavailable { reason, hint }
        }
    }

    fn render_modes(&self) -> &'static [&'static str] {
        &[RGB_ARRAY]
    }

    /// Generic: any env id names the model given by `asset_path`.
    fn list_envs(&self) -> Vec<String> {
        Vec::new()
    }

    fn supports(&self, _env_id: &str) -> bool {
        true
    }

    fn spec(&self, env_id: &str, config: &EnvConfig) -> Result<EnvSpec, EnvError> {
        #[cfg(feature = "libmujoco")]
        {
            let env = self.make_mujoco(env_id, config)?;
            Ok(EnvSpec {
                env_id: env_id.to_string(),
                observation_space: env.observation_space().clone(),
                action_space: env.action_space().clone(),
                max_episode_steps: None,
                options: env.options(),
            })
        }
        #[cfg(not(feature = "libmujoco"))]
        {
            let _ = (env_id, config);
            Err(unavailable(self.name()))
        }
    }

    fn make(&self, env_id: &str, config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        #[cfg(feature = "libmujoco")]
        return Ok(Box::new(self.make_mujoco(env_id, config)?));
        #[cfg(not(feature = "libmujoco"))]
        {
            let _ = (env_id, config);
            Err(unavailable(self.name()))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lists_the_v5_suite_either_way() {
        let ids = Mujoco::default().list_envs();
        assert_eq!(ids.len(), 11);
        assert!(ids.contains(&"Ant-v5".to_string()));
        #[cfg(feature = "libmujoco")]
        {
            let listed: Vec<&str> = crate::tasks::ENVS.iter().map(|e| e.id).collect();
            let here: Vec<&str> = ENV_IDS.iter().map(|(id, _)| *id).collect();
            assert_eq!(listed, here, "ENV_IDS and tasks::ENVS differ");
            for e in crate::tasks::ENVS {
                let limit = ENV_IDS.iter().find(|(id, _)| *id == e.id).unwrap().1;
                assert_eq!(e.max_episode_steps, limit, "{}", e.id);
            }
        }
    }

    #[cfg(not(feature = "libmujoco"))]
    #[test]
    fn unlinked_build_says_how_to_fix_it() {
        for adapter in [
            &Mujoco::default() as &dyn EnvAdapter,
            &CustomMjcf::default(),
        ] {
            match adapter.availability() {
                Availability::Unavailable { reason, hint } => {
                    assert!(reason.contains("built without the `mujoco` feature"));
                    assert!(hint.contains("make build"));
                }
                Availability::Available => panic!("available without libmujoco"),
            }
        }
        let err = Mujoco::default()
            .make("Ant-v5", &EnvConfig::default())
            .err()
            .unwrap()
            .to_string();
        assert!(
            err.contains("unavailable") && err.contains("make build"),
            "{err}"
        );
    }
}
