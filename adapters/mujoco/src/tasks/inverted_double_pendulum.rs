//! `InvertedDoublePendulum-v5`: balance two poles on a cart
//! (`gymnasium/envs/mujoco/inverted_double_pendulum_v5.py`).

use super::{CameraConfig, EnvEntry, Task, normal_noise, uniform_noise};
use crate::numeric::{clip, py_square};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{Info, NumpyRng};

/// Gymnasium's default `default_camera_config` is `None`: the free camera as
/// `OffScreenViewer._init_camera` aims it.
/// (The module's `DEFAULT_CAMERA_CONFIG` is not what `__init__` defaults to, so
/// Gymnasium does not use it.)
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig::NONE;

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "InvertedDoublePendulum-v5",
    xml_file: "inverted_double_pendulum.xml",
    frame_skip: 5,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &["healthy_reward", "reset_noise_scale"],
    make: |keys, _| {
        Ok(Box::new(InvertedDoublePendulum {
            healthy_reward: keys.f64("healthy_reward", 10.0)?,
            reset_noise_scale: keys.f64("reset_noise_scale", 0.1)?,
        }))
    },
};

struct InvertedDoublePendulum {
    healthy_reward: f64,
    reset_noise_scale: f64,
}

impl Task for InvertedDoublePendulum {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        let q = sim.qpos();
        obs.push(q[0]);
        obs.extend(q[1..].iter().map(|x| x.sin()));
        obs.extend(q[1..].iter().map(|x| x.cos()));
        obs.extend(sim.qvel().iter().map(|v| clip(*v, -10.0, 10.0)));
        obs.push(clip(sim.data.qfrc_constraint()[0], -10.0, 10.0));
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        normal_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let [x, _, y] = sim.data.site_xpos()[0];
        let terminated = y <= 1.0;
        let (v1, v2) = (sim.qvel()[1], sim.qvel()[2]);
        let dist_penalty = 0.01 * py_square(x) + py_square(y - 2.0);
        let vel_penalty = 1e-3 * py_square(v1) + 5e-3 * py_square(v2);
        let alive_bonus = self.healthy_reward * f64::from(u8::from(!terminated));
        let reward = alive_bonus - dist_penalty - vel_penalty;
        info.set_f64("reward_survive", alive_bonus);
        info.set_f64("distance_penalty", -dist_penalty);
        info.set_f64("velocity_penalty", -vel_penalty);
        (reward, terminated)
    }
}
