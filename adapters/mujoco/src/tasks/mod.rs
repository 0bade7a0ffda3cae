//! Tasks: what distinguishes one MuJoCo env from another (observation, reward, termination,
//! reset distribution), one file per Gymnasium env, and the list of them.

mod ant;
mod half_cheetah;
mod hopper;
mod humanoid;
mod humanoid_standup;
mod inverted_double_pendulum;
mod inverted_pendulum;
mod pusher;
mod reacher;
mod swimmer;
mod walker2d;

use crate::obs::ObsWriter;
pub(crate) use crate::render::CameraConfig;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng, Space};

/// The task half of a Gymnasium MuJoCo env (its `MujocoEnv` subclass).
pub(crate) trait Task: Send {
    /// `_get_obs`: appends the observation of the current state.
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter);

    /// `reset_model`: draws the initial `qpos`/`qvel` with `rng`, in Gymnasium's order.
    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]);

    /// `step` without the observation: simulates `action`, fills `info`, returns the reward and
    /// whether the episode terminated.
    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool);

    /// `_get_reset_info`.
    fn reset_info(&self, _sim: &Sim, _info: &mut Info) {}

    /// `_set_action_space`: the actuators' `ctrlrange`, as float32.
    fn action_space(&self, sim: &Sim) -> Space {
        ctrl_space(sim)
    }
}

/// `Box(ctrlrange[:, 0], ctrlrange[:, 1], float32)`.
pub(crate) fn ctrl_space(sim: &Sim) -> Space {
    let range = sim.model().actuator_ctrlrange();
    Space::box_f32_bounds(
        range.iter().map(|r| r[0] as f32 as f64).collect(),
        range.iter().map(|r| r[1] as f32 as f64).collect(),
    )
}

/// One env of the `mujoco` adapter. Each task file defines one as `ENTRY`.
pub(crate) struct EnvEntry {
    /// The Gymnasium id.
    pub(crate) id: &'static str,
    /// The default `xml_file`, in Gymnasium's assets folder.
    pub(crate) xml_file: &'static str,
    /// The default `frame_skip`.
    pub(crate) frame_skip: u64,
    /// `max_episode_steps` as Gymnasium registers the id.
    pub(crate) max_episode_steps: u32,
    /// The camera Gymnasium renders from: its `default_camera_config` default (which the
    /// `default_camera_config` option replaces).
    pub(crate) default_camera_config: CameraConfig,
    /// The task's own `extra` keys (its `__init__` kwargs).
    pub(crate) options: &'static [&'static str],
    /// Creates the task for a loaded model, reading its options.
    pub(crate) make: MakeTask,
}

/// Creates a task for a loaded model, reading its options.
pub(crate) type MakeTask = fn(&ExtraKeys, &Sim) -> Result<Box<dyn Task>, EnvError>;

/// Every env of the adapter. Adding one is a file with its `ENTRY` and a line here.
pub(crate) const ENVS: &[EnvEntry] = &[
    ant::ENTRY,
    half_cheetah::ENTRY,
    hopper::ENTRY,
    walker2d::ENTRY,
    humanoid::ENTRY,
    humanoid_standup::ENTRY,
    swimmer::ENTRY,
    reacher::ENTRY,
    pusher::ENTRY,
    inverted_pendulum::ENTRY,
    inverted_double_pendulum::ENTRY,
];

/// The entry of `env_id`.
pub(crate) fn entry(env_id: &str) -> Option<&'static EnvEntry> {
    ENVS.iter().find(|e| e.id == env_id)
}

/// `init + uniform(-scale, scale, size=n)` into `out`.
pub(crate) fn uniform_noise(rng: &mut NumpyRng, init: &[f64], scale: f64, out: &mut [f64]) {
    rng.uniform_fill(-scale, scale, out);
    for (o, i) in out.iter_mut().zip(init) {
        *o += i;
    }
}

/// `init + scale * standard_normal(n)` into `out`.
pub(crate) fn normal_noise(rng: &mut NumpyRng, init: &[f64], scale: f64, out: &mut [f64]) {
    rng.standard_normal_fill(out);
    for (o, i) in out.iter_mut().zip(init) {
        *o = i + scale * *o;
    }
}
