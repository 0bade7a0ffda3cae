//! `null`: an env that does no work, for measuring the data plane alone — and, through its
//! options, for misbehaving on purpose in failure tests (`sleep_ms`, `exit_after`) and for
//! observations of any size (`frame`: a `uint8` image, for data-plane benchmarks).

use envhub_core::{
    Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec, Info, ResetOptions, Space,
    Transition,
};

const ENV_ID: &str = "Null-v0";
const OPTIONS: &[&str] = &["sleep_ms", "exit_after", "error_after", "frame"];

/// Adapter with one env, `Null-v0`: CartPole-sized spaces, no computation. A test adapter:
/// the worker lists it only when asked to (see `adapters::listed`).
pub struct NullAdapter;

/// The observation's first float counts the env's steps (a `u32`, so up to 2^32); the others
/// stay 0. With `frame`, the observation is instead a `uint8` image of that shape, every byte
/// the step count's low byte.
fn spaces(frame: Option<&[usize]>) -> (Space, Space) {
    let steps_max = f64::from(u32::MAX) + 1.0;
    let obs = match frame {
        None => Space::box_f32_bounds(vec![0.0, -1.0, -1.0, -1.0], vec![steps_max, 1.0, 1.0, 1.0]),
        Some(shape) => {
            let n = shape.iter().product();
            Space::Box {
                dtype: envhub_core::DType::Uint8,
                shape: shape.to_vec(),
                low: vec![0.0; n],
                high: vec![255.0; n],
            }
        }
    };
    (obs, Space::discrete(2))
}

/// The `frame` option: a shape of 1 to 4 positive dimensions, at most 64 MiB in all.
fn frame_shape(config: &EnvConfig) -> Result<Option<Vec<usize>>, EnvError> {
    let keys = config.extra_keys(ENV_ID, OPTIONS)?;
    let Some(value) = keys.value("frame") else {
        return Ok(None);
    };
    let shape: Option<Vec<usize>> = value.as_array().and_then(|dims| {
        dims.iter()
            .map(|d| d.as_u64().filter(|&d| d > 0).map(|d| d as usize))
            .collect()
    });
    match shape {
        Some(s) if (1..=4).contains(&s.len()) && s.iter().product::<usize>() <= 64 << 20 => {
            Ok(Some(s))
        }
        _ => Err(keys.error(
            "frame",
            "must be a list of 1 to 4 positive dimensions of at most 64 MiB in all, e.g. [84, 84, 4]",
        )),
    }
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
        let (observation_space, action_space) = spaces(frame_shape(config)?.as_deref());
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
        let frame = frame_shape(config)?;
        let (obs, act) = spaces(frame.as_deref());
        Ok(Box::new(NullEnv {
            frame: frame.is_some(),
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
    /// The observation is a `uint8` image (`frame`).
    frame: bool,
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
        // The step count in the first float (every byte of a frame), so a test can see the env
        // really stepped; the whole observation is written, as its slot held an earlier step's.
        if self.frame {
            obs.fill(self.t as u8);
        } else {
            obs.fill(0);
            obs[..4].copy_from_slice(&(self.t as f32).to_le_bytes());
        }
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
    fn frames_of_any_shape_and_clear_errors() {
        let mut config = EnvConfig::default();
        config
            .extra
            .insert("frame".into(), serde_json::json!([84, 84, 4]));
        let mut env = NullAdapter.make(ENV_ID, &config).unwrap();
        assert_eq!(env.observation_space().byte_len(), 84 * 84 * 4);
        let mut obs = vec![0u8; 84 * 84 * 4];
        let mut info = Info::default();
        env.reset(None, &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        env.step(&0i64.to_le_bytes(), &mut obs, &mut info).unwrap();
        assert!(obs.iter().all(|&b| b == 1));
        assert!(env.observation_space().contains(&obs));
        for bad in [
            serde_json::json!([0]),
            serde_json::json!("84x84"),
            serde_json::json!([1, 2, 3, 4, 5]),
        ] {
            config.extra.insert("frame".into(), bad);
            let err = NullAdapter.make(ENV_ID, &config).err().unwrap().to_string();
            assert!(
                err.contains("frame") && err.contains("[84, 84, 4]"),
                "{err}"
            );
        }
    }

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
