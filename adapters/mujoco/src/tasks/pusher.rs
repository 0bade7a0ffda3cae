//! `Pusher-v5`: a seven-joint arm pushing a cylinder to a goal
//! (`gymnasium/envs/mujoco/pusher_v5.py`).

use super::{CameraConfig, EnvEntry, Task};
use crate::numeric::{norm, sum_squares_f32};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    trackbodyid: Some(-1),
    distance: Some(4.0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "Pusher-v5",
    xml_file: "pusher_v5.xml",
    frame_skip: 5,
    max_episode_steps: 100,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "reward_near_weight",
        "reward_dist_weight",
        "reward_control_weight",
    ],
    make: |keys, sim| Ok(Box::new(Pusher::new(keys, sim)?)),
};

struct Pusher {
    reward_near_weight: f64,
    reward_dist_weight: f64,
    reward_control_weight: f64,
    tips_arm: usize,
    object: usize,
    goal: usize,
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

impl Pusher {
    fn new(keys: &ExtraKeys, sim: &Sim) -> Result<Self, EnvError> {
        Ok(Pusher {
            reward_near_weight: keys.f64("reward_near_weight", 0.5)?,
            reward_dist_weight: keys.f64("reward_dist_weight", 1.0)?,
            reward_control_weight: keys.f64("reward_control_weight", 0.1)?,
            tips_arm: sim.body_id(ENTRY.id, "tips_arm")?,
            object: sim.body_id(ENTRY.id, "object")?,
            goal: sim.body_id(ENTRY.id, "goal")?,
        })
    }
}

impl Task for Pusher {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        obs.extend(sim.qpos()[..7].iter().copied());
        obs.extend(sim.qvel()[..7].iter().copied());
        for body in [self.tips_arm, self.object, self.goal] {
            obs.extend(sim.body_xpos(body));
        }
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        qpos.copy_from_slice(&sim.init_qpos);
        let cylinder = loop {
            let c = [rng.uniform(-0.3, 0.0), rng.uniform(-0.2, 0.2)];
            if norm(&c) > 0.17 {
                break c;
            }
        };
        let n = qpos.len();
        qpos[n - 4..n - 2].copy_from_slice(&cylinder);
        qpos[n - 2..].fill(0.0);
        super::uniform_noise(rng, &sim.init_qvel, 0.005, qvel);
        let n = qvel.len();
        qvel[n - 4..].fill(0.0);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let object = sim.body_xpos(self.object);
        let near = sub(object, sim.body_xpos(self.tips_arm));
        let dist = sub(object, sim.body_xpos(self.goal));
        let reward_near = -norm(&near) * self.reward_near_weight;
        let reward_dist = -norm(&dist) * self.reward_dist_weight;
        let reward_ctrl = (-sum_squares_f32(action) * self.reward_control_weight as f32) as f64;
        info.set_f64("reward_dist", reward_dist);
        info.set_f64("reward_ctrl", reward_ctrl);
        info.set_f64("reward_near", reward_near);
        (reward_dist + reward_ctrl + reward_near, false)
    }
}
