//! `HalfCheetah-v5`: a planar two-legged runner (`gymnasium/envs/mujoco/half_cheetah_v5.py`).

use super::{CameraConfig, EnvEntry, Task, normal_noise, uniform_noise};
use crate::numeric::sum_squares_f32;
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    distance: Some(4.0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "HalfCheetah-v5",
    xml_file: "half_cheetah.xml",
    frame_skip: 5,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "forward_reward_weight",
        "ctrl_cost_weight",
        "reset_noise_scale",
        "exclude_current_positions_from_observation",
    ],
    make: |keys, _| Ok(Box::new(HalfCheetah::new(keys)?)),
};

struct HalfCheetah {
    forward_reward_weight: f64,
    ctrl_cost_weight: f64,
    reset_noise_scale: f64,
    exclude_current_positions: bool,
}

impl HalfCheetah {
    fn new(keys: &ExtraKeys) -> Result<Self, EnvError> {
        Ok(HalfCheetah {
            forward_reward_weight: keys.f64("forward_reward_weight", 1.0)?,
            ctrl_cost_weight: keys.f64("ctrl_cost_weight", 0.1)?,
            reset_noise_scale: keys.f64("reset_noise_scale", 0.1)?,
            exclude_current_positions: keys
                .bool("exclude_current_positions_from_observation", true)?,
        })
    }
}

impl Task for HalfCheetah {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        let skip = usize::from(self.exclude_current_positions);
        obs.extend(sim.qpos()[skip..].iter().copied());
        obs.extend(sim.qvel().iter().copied());
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        normal_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        let x_before = sim.qpos()[0];
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let x_after = sim.qpos()[0];
        let x_velocity = (x_after - x_before) / sim.dt();
        let forward_reward = self.forward_reward_weight * x_velocity;
        let ctrl_cost = (self.ctrl_cost_weight as f32 * sum_squares_f32(action)) as f64;
        info.set_f64("x_position", x_after);
        info.set_f64("x_velocity", x_velocity);
        info.set_f64("reward_forward", forward_reward);
        info.set_f64("reward_ctrl", -ctrl_cost);
        (forward_reward - ctrl_cost, false)
    }

    fn reset_info(&self, sim: &Sim, info: &mut Info) {
        info.set_f64("x_position", sim.qpos()[0]);
    }
}
