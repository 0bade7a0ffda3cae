//! `InvertedPendulum-v5`: balance a pole on a cart (`gymnasium/envs/mujoco/inverted_pendulum_v5.py`).

use super::{CameraConfig, EnvEntry, Task, uniform_noise};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{Info, InfoValue, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    trackbodyid: Some(0),
    distance: Some(2.04),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "InvertedPendulum-v5",
    xml_file: "inverted_pendulum.xml",
    frame_skip: 2,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &["reset_noise_scale"],
    make: |keys, _| {
        Ok(Box::new(InvertedPendulum {
            reset_noise_scale: keys.f64("reset_noise_scale", 0.01)?,
        }))
    },
};

struct InvertedPendulum {
    reset_noise_scale: f64,
}

impl Task for InvertedPendulum {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        obs.extend(sim.qpos().iter().copied());
        obs.extend(sim.qvel().iter().copied());
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        uniform_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        sim.do_simulation(action.iter().map(|a| *a as f64));
        // The observation is `qpos ++ qvel`; its element 1 is the pole's angle.
        let terminated = !sim.state_is_finite() || sim.qpos()[1].abs() > 0.2;
        let reward = i64::from(!terminated);
        info.insert("reward_survive", InfoValue::Int(reward));
        (reward as f64, terminated)
    }
}
