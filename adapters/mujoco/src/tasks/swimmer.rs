//! `Swimmer-v5`: a three-link swimmer in a viscous fluid (`gymnasium/envs/mujoco/swimmer_v5.py`).

use super::{CameraConfig, EnvEntry, Task, uniform_noise};
use crate::numeric::{norm, sum_squares_f32};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng};

/// Gymnasium's default `default_camera_config` is `None`: the free camera as
/// `OffScreenViewer._init_camera` aims it.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig::NONE;

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "Swimmer-v5",
    xml_file: "swimmer.xml",
    frame_skip: 4,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "forward_reward_weight",
        "ctrl_cost_weight",
        "reset_noise_scale",
        "exclude_current_positions_from_observation",
    ],
    make: |keys, _| Ok(Box::new(Swimmer::new(keys)?)),
};

struct Swimmer {
    forward_reward_weight: f64,
    ctrl_cost_weight: f64,
    reset_noise_scale: f64,
    exclude_current_positions: bool,
}

impl Swimmer {
    fn new(keys: &ExtraKeys) -> Result<Self, EnvError> {
        Ok(Swimmer {
            forward_reward_weight: keys.f64("forward_reward_weight", 1.0)?,
            ctrl_cost_weight: keys.f64("ctrl_cost_weight", 1e-4)?,
            reset_noise_scale: keys.f64("reset_noise_scale", 0.1)?,
            exclude_current_positions: keys
                .bool("exclude_current_positions_from_observation", true)?,
        })
    }
}

impl Task for Swimmer {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        let skip = if self.exclude_current_positions { 2 } else { 0 };
        obs.extend(sim.qpos()[skip..].iter().copied());
        obs.extend(sim.qvel().iter().copied());
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        uniform_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        let before = [sim.qpos()[0], sim.qpos()[1]];
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let after = [sim.qpos()[0], sim.qpos()[1]];
        let dt = sim.dt();
        let x_velocity = (after[0] - before[0]) / dt;
        let y_velocity = (after[1] - before[1]) / dt;
        let forward_reward = self.forward_reward_weight * x_velocity;
        let ctrl_cost = (self.ctrl_cost_weight as f32 * sum_squares_f32(action)) as f64;
        info.set_f64("x_position", after[0]);
        info.set_f64("y_position", after[1]);
        info.set_f64("distance_from_origin", norm(&after));
        info.set_f64("x_velocity", x_velocity);
        info.set_f64("y_velocity", y_velocity);
        info.set_f64("reward_forward", forward_reward);
        info.set_f64("reward_ctrl", -ctrl_cost);
        (forward_reward - ctrl_cost, false)
    }

    fn reset_info(&self, sim: &Sim, info: &mut Info) {
        super::ant::xy_info(sim, info);
    }
}
