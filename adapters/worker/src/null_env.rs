//! `null`: an env that does no work, for measuring the data plane alone — and, through its
//! options, for misbehaving on purpose in failure tests (`sleep_ms`, `exit_after`).

use envhub_core::{
    Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec, Info, ResetOptions, Space,
    Transition,
};

const ENV_ID: &str = "Null-v0";
const OPTIONS: &[&str] = &["sleep_ms", "exit_after", "error_after"];

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
        config.extra_keys(env_id, OPTIONS)?;
        let (observation_space, action_space) = spaces();
        Ok(EnvSpec {
            env_id: ENV_ID.to_string(),
            observation_space,
            action_space,
            max_episode_steps: None,
            options: OPTIONS.iter().map(|o| o.to_string()).collect(),
        })
    }

    fn make(&self, env_id: &str, config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        self.spec(env_id, config)?;
        let keys = config.extra_keys(env_id, OPTIONS)?;
        let (obs, act) = spaces();
        Ok(Box::new(NullEnv {
            obs,
            act,
            t: 0,
            sleep: std::time::Duration::from_millis(keys.u64("sleep_ms", 0)?),
            exit_after: keys.u64("exit_after", 0)?,
            error_after: keys.u64("error_after", 0)?,
            steps: 0,
        }))
    }
}

struct NullEnv {
    obs: Space,
    act: Space,
    t: u32,
    /// Sleep this long in every step (a slow or hung simulator).
    sleep: std::time::Duration,
    /// Exit the process abruptly at this step, counted over the env's life (0: never).
    exit_after: u64,
    /// Fail the step with an error at this step (0: never).
    error_after: u64,
    steps: u64,
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
        self.steps += 1;
        if !self.sleep.is_zero() {
            std::thread::sleep(self.sleep);
        }
        if self.exit_after == self.steps {
            // A simulator that segfaults gives no warning either.
            std::process::abort();
        }
        if self.error_after == self.steps {
            return Err(EnvError::Simulator {
                env_id: ENV_ID.to_string(),
                reason: format!("failed on purpose at step {}", self.steps),
            });
        }
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
