//! `null`: an env that does no work, for measuring the data plane alone — and, through its
//! options, for misbehaving on purpose in failure tests (`sleep_ms`, `exit_after`).

use envhub_core::{
    Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec, Info, ResetOptions, Space,
    Transition,
};

const ENV_ID: &str = "Null-v0";
const OPTIONS: &[&str] = &["sleep_ms", "exit_after", "error_after"];

/// Adapter with one env, `Null-v0`: CartPole-sized spaces, no computation. A test adapter:
/// the worker lists it only when asked to (see `adapters::listed`).
pub struct NullAdapter;

/// The observation's first float counts the env's steps (a `u32`, so up to 2^32); the others
/// stay 0.
fn spaces() -> (Space, Space) {
    let steps_max = f64::from(u32::MAX) + 1.0;
    (
        Space::box_f32_bounds(vec![0.0, -1.0, -1.0, -1.0], vec![steps_max, 1.0, 1.0, 1.0]),
        Space::discrete(2),
    )
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

    fn render_modes(&self) -> &'static [&'static str] {
        // Renders nothing; its env ignores `render_mode`.
        &[]
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
        // The step count in the first float, so a test can see the env really stepped; the
        // whole observation is written, as the slot it goes to holds an earlier step's.
        obs.fill(0);
        obs[..4].copy_from_slice(&(self.t as f32).to_le_bytes());
        Ok(Transition {
            reward: 1.0,
            terminated: false,
            truncated: false,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn observations_lie_in_the_declared_space() {
        let config = EnvConfig::default();
        let mut env = NullAdapter.make(ENV_ID, &config).unwrap();
        let space = NullAdapter.spec(ENV_ID, &config).unwrap().observation_space;
        // A slot that held something else before: the env must overwrite all of it.
        let mut obs = vec![0xAAu8; space.byte_len()];
        let mut info = Info::default();
        env.reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        assert!(space.contains(&obs), "after reset: {obs:?}");
        let action = 0i64.to_le_bytes();
        for t in 1..=50 {
            obs.fill(0xAA);
            env.step(&action, &mut obs, &mut info).unwrap();
            assert!(space.contains(&obs), "after step {t}: {obs:?}");
            assert_eq!(f32::from_le_bytes(obs[..4].try_into().unwrap()), t as f32);
        }
    }
}
