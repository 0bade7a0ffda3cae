//! `Task`: what one robot task defines (its world, action, observation, reward and end), and
//! `TaskEnv`, the one `Env` implementation every task shares (seeding, byte layouts, info,
//! rendering).

use crate::render::{Camera, RenderOptions, Renderer};
use envhub_core::{Env, EnvError, Info, InfoValue, NumpyRng, ResetOptions, Space, Transition};
use rapier3d::prelude::PhysicsWorld;

/// The outcome of one step of a task.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct StepResult {
    /// The reward.
    pub(crate) reward: f64,
    /// The episode ended in a terminal state (goal reached, fallen, flipped).
    pub(crate) terminated: bool,
}

/// One robot task on a rapier world. Its world is rebuilt at every reset, so an episode
/// depends only on the seed and the actions.
pub(crate) trait Task: Send {
    /// Length of the `float32` observation vector.
    fn obs_dim(&self) -> usize;

    /// Number of actions, each in `[-1, 1]`.
    fn act_dim(&self) -> usize;

    /// Seconds of simulated time per `step` (Gymnasium's `dt`).
    fn dt(&self) -> f64;

    /// Builds a new world for an episode, drawing the random start from `rng`.
    fn reset(&mut self, rng: &mut NumpyRng);

    /// Applies `action` (in `[-1, 1]`) and advances the world by `dt`. Writes the reward terms
    /// and `is_success` into `info`.
    fn step(&mut self, action: &[f32], info: &mut Info) -> StepResult;

    /// Writes the observation.
    fn observe(&self, obs: &mut [f32]);

    /// Whether the task is solved in the current state (what `info["is_success"]` reports).
    fn is_success(&self) -> bool;

    /// The world to draw.
    fn world(&self) -> &PhysicsWorld;

    /// Where the camera looks from and at in the current state.
    fn camera(&self) -> Camera;
}

/// A task served as a Gymnasium env.
pub(crate) struct TaskEnv<T: Task> {
    env_id: &'static str,
    task: T,
    rng: Option<NumpyRng>,
    observation_space: Space,
    action_space: Space,
    obs: Vec<f32>,
    action: Vec<f32>,
    renderer: Option<Renderer>,
    has_reset: bool,
}

impl<T: Task> TaskEnv<T> {
    /// Wraps `task`; `render` is `Some` when `render_mode` is `rgb_array`.
    pub(crate) fn new(env_id: &'static str, task: T, render: Option<RenderOptions>) -> Self {
        let obs_dim = task.obs_dim();
        let act_dim = task.act_dim();
        TaskEnv {
            env_id,
            observation_space: Space::box_f32(&[obs_dim], f64::NEG_INFINITY, f64::INFINITY),
            action_space: Space::box_f32(&[act_dim], -1.0, 1.0),
            obs: vec![0.0; obs_dim],
            action: vec![0.0; act_dim],
            renderer: render.map(Renderer::new),
            task,
            rng: None,
            has_reset: false,
        }
    }

    fn write_obs(&mut self, out: &mut [u8]) {
        self.task.observe(&mut self.obs);
        for (bytes, v) in out.chunks_exact_mut(4).zip(&self.obs) {
            bytes.copy_from_slice(&v.to_le_bytes());
        }
    }
}

impl<T: Task> Env for TaskEnv<T> {
    fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    fn action_space(&self) -> &Space {
        &self.action_space
    }

    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<(), EnvError> {
        if let Some(key) = options.keys().next() {
            return Err(EnvError::InvalidReset {
                env_id: self.env_id.to_string(),
                reason: format!("unknown reset option `{key}`; this env takes none"),
            });
        }
        let rng = NumpyRng::reseed(&mut self.rng, seed);
        self.task.reset(rng);
        self.has_reset = true;
        self.write_obs(obs);
        info.clear();
        info.insert("is_success", InfoValue::Bool(self.task.is_success()));
        Ok(())
    }

    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        info: &mut Info,
    ) -> Result<Transition, EnvError> {
        if !self.has_reset {
            return Err(EnvError::Simulator {
                env_id: self.env_id.to_string(),
                reason: "`step` called before `reset`\nhint: call `reset` first".into(),
            });
        }
        for (a, bytes) in self.action.iter_mut().zip(action.chunks_exact(4)) {
            *a = f32::from_le_bytes(bytes.try_into().expect("4 bytes")).clamp(-1.0, 1.0);
        }
        info.clear();
        let result = self.task.step(&self.action, info);
        info.insert("is_success", InfoValue::Bool(self.task.is_success()));
        self.write_obs(obs);
        let quarantined = self.task.world().quarantine().bodies().len();
        if quarantined > 0 || !self.obs.iter().all(|x| x.is_finite()) {
            return Err(EnvError::Simulator {
                env_id: self.env_id.to_string(),
                reason: format!(
                    "the simulation diverged (non-finite state; rapier disabled {quarantined} bodies)"
                ),
            });
        }
        Ok(Transition {
            reward: result.reward,
            terminated: result.terminated,
            truncated: false,
        })
    }

    fn render(&mut self) -> Result<Option<(usize, usize, Vec<u8>)>, EnvError> {
        let Some(renderer) = &self.renderer else {
            return Ok(None);
        };
        if !self.has_reset {
            return Err(EnvError::Simulator {
                env_id: self.env_id.to_string(),
                reason: "`render` called before `reset`\nhint: call `reset` first".into(),
            });
        }
        Ok(Some(
            renderer.render(self.task.world(), &self.task.camera()),
        ))
    }

    fn render_fps(&self) -> Option<f64> {
        Some((1.0 / self.task.dt()).round())
    }
}
