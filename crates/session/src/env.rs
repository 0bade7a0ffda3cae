//! `Env`: one environment in a worker process, with Gymnasium's single-env contract.

use crate::vec_env::VecEnv;
use envhub_core::{ResetOptions, Space};
use envhub_protocol::HubError;

/// What `step` returns; the observation is viewed in place in shared memory.
#[derive(Debug)]
pub struct Step<'a> {
    /// The observation (`observation_space().byte_len()` bytes).
    pub obs: &'a [u8],
    /// The reward.
    pub reward: f64,
    /// The episode reached a terminal state.
    pub terminated: bool,
    /// The episode was cut short.
    pub truncated: bool,
    /// The env's info (`Null` if none).
    pub info: &'a serde_json::Value,
}

impl Step<'_> {
    /// The observation as `f32`.
    pub fn obs_f32(&self) -> &[f32] {
        bytemuck::cast_slice(self.obs)
    }
}

/// One env. Episodes do not reset themselves: after `terminated` or `truncated`, call
/// `reset` (as with a Gymnasium env).
pub struct Env {
    inner: VecEnv,
}

impl Env {
    /// A single env over a session of one env.
    pub fn new(inner: VecEnv) -> Env {
        Env { inner }
    }

    /// Observation space.
    pub fn observation_space(&self) -> &Space {
        self.inner.observation_space()
    }

    /// Action space.
    pub fn action_space(&self) -> &Space {
        self.inner.action_space()
    }

    /// The worker's pid.
    pub fn worker_pid(&self) -> u32 {
        self.inner.worker_pids()[0]
    }

    /// The episode limit applied, if any.
    pub fn max_episode_steps(&self) -> Option<u32> {
        self.inner.max_episode_steps()
    }

    /// Frames per second of the env's rendering (Gymnasium's `metadata["render_fps"]`), if
    /// the env says.
    pub fn render_fps(&self) -> Option<f64> {
        self.inner.render_fps()
    }

    /// Starts an episode: returns the first observation and the info.
    pub fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
    ) -> Result<Step<'_>, HubError> {
        let b = self.inner.reset_with(&[seed], None, options)?;
        Ok(Step {
            obs: b.obs,
            reward: 0.0,
            terminated: false,
            truncated: false,
            info: b.info(0),
        })
    }

    /// Advances one step with `action` (bytes in the action space's layout).
    pub fn step(&mut self, action: &[u8]) -> Result<Step<'_>, HubError> {
        let b = self.inner.step(action)?;
        Ok(Step {
            obs: b.obs,
            reward: b.rewards[0],
            terminated: b.terminated[0],
            truncated: b.truncated[0],
            info: b.info(0),
        })
    }

    /// Renders the env (`render_mode = "rgb_array"`); `None` if it renders nothing.
    pub fn render(&mut self) -> Result<Option<envhub_protocol::Frame>, HubError> {
        Ok(self.inner.render()?.pop().flatten())
    }

    /// A random action.
    pub fn sample_action(&self, rng: &mut impl rand::Rng) -> Vec<u8> {
        self.inner.sample_actions(rng)
    }

    /// Stops the worker. Later calls are errors.
    pub fn close(&mut self) {
        self.inner.close();
    }
}
