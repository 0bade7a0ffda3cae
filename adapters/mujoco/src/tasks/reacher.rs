//! `Reacher-v5`: a two-joint planar arm reaching a random target
//! (`gymnasium/envs/mujoco/reacher_v5.py`).

use super::{CameraConfig, EnvEntry, Task};
use crate::numeric::{norm, sum_squares_f32};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    trackbodyid: Some(0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "Reacher-v5",
    xml_file: "reacher.xml",
    frame_skip: 2,
    max_episode_steps: 50,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &["reward_dist_weight", "reward_control_weight"],
    make: |keys, sim| Ok(Box::new(Reacher::new(keys, sim)?)),
};

struct Reacher {
    reward_dist_weight: f64,
    reward_control_weight: f64,
    fingertip: usize,
    target: usize,
}

impl Reacher {
    fn new(keys: &ExtraKeys, sim: &Sim) -> Result<Self, EnvError> {
        Ok(Reacher {
            reward_dist_weight: keys.f64("reward_dist_weight", 1.0)?,
            reward_control_weight: keys.f64("reward_control_weight", 1.0)?,
            fingertip: sim.body_id(ENTRY.id, "fingertip")?,
            target: sim.body_id(ENTRY.id, "target")?,
        })
    }

    /// `get_body_com("fingertip") - get_body_com("target")`.
    fn to_target(&self, sim: &Sim) -> [f64; 3] {
        let (f, t) = (sim.body_xpos(self.fingertip), sim.body_xpos(self.target));
        [f[0] - t[0], f[1] - t[1], f[2] - t[2]]
    }
}

impl Task for Reacher {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        let q = sim.qpos();
        obs.extend(q[..2].iter().map(|t| t.cos()));
        obs.extend(q[..2].iter().map(|t| t.sin()));
        obs.extend(q[2..].iter().copied());
        obs.extend(sim.qvel()[..2].iter().copied());
        obs.extend(self.to_target(sim)[..2].iter().copied());
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        rng.uniform_fill(-0.1, 0.1, qpos);
        for (q, i) in qpos.iter_mut().zip(&sim.init_qpos) {
            *q += i;
        }
        let goal = loop {
            let goal = [rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2)];
            if norm(&goal) < 0.2 {
                break goal;
            }
        };
        let n = qpos.len();
        qpos[n - 2..].copy_from_slice(&goal);
        super::uniform_noise(rng, &sim.init_qvel, 0.005, qvel);
        let n = qvel.len();
        qvel[n - 2..].fill(0.0);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let reward_dist = -norm(&self.to_target(sim)) * self.reward_dist_weight;
        // float32: `-np.square(action).sum() * weight` with a float32 action.
        let reward_ctrl = (-sum_squares_f32(action) * self.reward_control_weight as f32) as f64;
        info.set_f64("reward_dist", reward_dist);
        info.set_f64("reward_ctrl", reward_ctrl);
        (reward_dist + reward_ctrl, false)
    }
}
