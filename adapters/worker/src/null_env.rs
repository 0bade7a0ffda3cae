//! `null`: an env that does no work, for measuring the data plane alone.

use envhub_core::{
    Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec, Info, ResetOptions, Space,
    Transition,
};

const ENV_ID: &str = "Null-v0";

/// Adapter with one env, `Null-v0`: CartPole-sized spaces, no computation.
pub struct NullAdapter;

fn spaces() -> (Space, Space) {
    (Space::box_f32(&[4], -1.0, 1.0), Space::discrete(2))
}

impl EnvAdapter for NullAdapter {
    fn name(&self) -> &'static str {
        "null"
    }

    fn frameworks(&self) -> &'static [&'static str] {
        &["envhub"]
    }

    fn requires(&self) -> &'static [&'static str] {
        &[]
    }

    fn description(&self) -> &'static str {
        "an env that does no work, for measuring the data plane"
    }

    fn availability(&self) -> Availability {
        Availability::Available
    }

    fn list_envs(&self) -> Vec<String> {
        vec![ENV_ID.to_string()]
    }

    fn spec(&self, env_id: &str, config: &EnvConfig) -> Result<EnvSpec, EnvError> {
        if env_id != ENV_ID {
            return Err(self.unknown_env(env_id));
        }
        config.extra_keys(env_id, &[])?;
        let (observation_space, action_space) = spaces();
        Ok(EnvSpec {
            env_id: ENV_ID.to_string(),
            observation_space,
            action_space,
            max_episode_steps: None,
            options: Vec::new(),
        })
    }

    fn make(&self, env_id: &str, config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        self.spec(env_id, config)?;
        let (obs, act) = spaces();
        Ok(Box::new(NullEnv { obs, act, t: 0 }))
    }
}

struct NullEnv {
    obs: Space,
    act: Space,
    t: u32,
}

impl Env for NullEnv {
    fn observation_space(&self) -> &Space {
        &self.obs
    }

    fn action_space(&self) -> &Space {
        &self.act
    }

    fn reset(
        &mut self,
        _seed: Option<u64>,
        _options: &ResetOptions,
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<(), EnvError> {
        self.t = 0;
        obs.fill(0);
        Ok(())
    }

    fn step(
        &mut self,
        _action: &[u8],
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<Transition, EnvError> {
        self.t = self.t.wrapping_add(1);
        // The step count in the first float, so a test can see the env really stepped.
        obs[..4].copy_from_slice(&(self.t as f32).to_le_bytes());
        Ok(Transition {
            reward: 1.0,
            terminated: false,
            truncated: false,
        })
    }
}
