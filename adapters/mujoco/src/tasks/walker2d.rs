//! `Walker2d-v5`: a planar biped (`gymnasium/envs/mujoco/walker2d_v5.py`).

use super::hopper::Planar;
use super::{CameraConfig, EnvEntry, Task};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{Info, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    trackbodyid: Some(2),
    distance: Some(4.0),
    lookat: Some([0.0, 0.0, 1.15]),
    elevation: Some(-20.0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "Walker2d-v5",
    xml_file: "walker2d_v5.xml",
    frame_skip: 4,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "forward_reward_weight",
        "ctrl_cost_weight",
        "healthy_reward",
        "terminate_when_unhealthy",
        "healthy_z_range",
        "healthy_angle_range",
        "reset_noise_scale",
        "exclude_current_positions_from_observation",
    ],
    make: |keys, _| {
        Ok(Box::new(Walker2d(Planar::new(
            keys,
            (0.8, 2.0),
            (-1.0, 1.0),
        )?)))
    },
};

struct Walker2d(Planar);

impl Task for Walker2d {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        self.0.write_obs(sim, obs);
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        self.0.reset_model(sim, rng, qpos, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        let planar = &self.0;
        planar.step(sim, action, info, |sim| planar.z_and_angle_healthy(sim))
    }

    fn reset_info(&self, sim: &Sim, info: &mut Info) {
        self.0.reset_info(sim, info);
    }
}
