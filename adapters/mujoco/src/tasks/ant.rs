//! `Ant-v5`: a four-legged robot that learns to move forward (`gymnasium/envs/mujoco/ant_v5.py`).

use super::{CameraConfig, EnvEntry, Task, normal_noise, uniform_noise};
use crate::numeric::{norm, sum_squares_clipped, sum_squares_f32};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    distance: Some(4.0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "Ant-v5",
    xml_file: "ant.xml",
    frame_skip: 5,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "forward_reward_weight",
        "ctrl_cost_weight",
        "contact_cost_weight",
        "healthy_reward",
        "main_body",
        "terminate_when_unhealthy",
        "healthy_z_range",
        "contact_force_range",
        "reset_noise_scale",
        "exclude_current_positions_from_observation",
        "include_cfrc_ext_in_observation",
    ],
    make: |keys, sim| Ok(Box::new(Ant::new(keys, sim)?)),
};

struct Ant {
    forward_reward_weight: f64,
    ctrl_cost_weight: f64,
    contact_cost_weight: f64,
    healthy_reward: f64,
    main_body: usize,
    terminate_when_unhealthy: bool,
    healthy_z_range: (f64, f64),
    contact_force_range: (f64, f64),
    reset_noise_scale: f64,
    exclude_current_positions: bool,
    include_cfrc_ext: bool,
}

/// A body given by id (`1`) or name (`"torso"`), as Gymnasium's `data.body(...)` takes it.
pub(super) fn body_option(
    keys: &ExtraKeys,
    sim: &Sim,
    key: &str,
    default: usize,
) -> Result<usize, EnvError> {
    let nbody = sim.model().ffi().nbody as usize;
    match keys.value(key) {
        None => Ok(default),
        Some(v) => match (v.as_u64(), v.as_str()) {
            (Some(id), _) if (id as usize) < nbody => Ok(id as usize),
            (_, Some(name)) => sim
                .model()
                .name_to_id(mujoco_rs::prelude::MjtObjBase::mjOBJ_BODY, name)
                .ok_or_else(|| keys.error(key, format!("the model has no body `{name}`"))),
            _ => Err(keys.error(
                key,
                format!("expected a body id below {nbody} or a body name, got `{v}`"),
            )),
        },
    }
}

impl Ant {
    fn new(keys: &ExtraKeys, sim: &Sim) -> Result<Self, EnvError> {
        Ok(Ant {
            forward_reward_weight: keys.f64("forward_reward_weight", 1.0)?,
            ctrl_cost_weight: keys.f64("ctrl_cost_weight", 0.5)?,
            contact_cost_weight: keys.f64("contact_cost_weight", 5e-4)?,
            healthy_reward: keys.f64("healthy_reward", 1.0)?,
            main_body: body_option(keys, sim, "main_body", 1)?,
            terminate_when_unhealthy: keys.bool("terminate_when_unhealthy", true)?,
            healthy_z_range: keys.range("healthy_z_range", (0.2, 1.0))?,
            contact_force_range: keys.range("contact_force_range", (-1.0, 1.0))?,
            reset_noise_scale: keys.f64("reset_noise_scale", 0.1)?,
            exclude_current_positions: keys
                .bool("exclude_current_positions_from_observation", true)?,
            include_cfrc_ext: keys.bool("include_cfrc_ext_in_observation", true)?,
        })
    }

    fn is_healthy(&self, sim: &Sim) -> bool {
        let (lo, hi) = self.healthy_z_range;
        let z = sim.qpos()[2];
        sim.state_is_finite() && lo <= z && z <= hi
    }
}

/// `x_position`, `y_position`, `distance_from_origin` (Ant, Humanoid, Swimmer).
pub(super) fn xy_info(sim: &Sim, info: &mut Info) {
    let q = sim.qpos();
    info.set_f64("x_position", q[0]);
    info.set_f64("y_position", q[1]);
    info.set_f64("distance_from_origin", norm(&q[..2]));
}

impl Task for Ant {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        let skip = if self.exclude_current_positions { 2 } else { 0 };
        obs.extend(sim.qpos()[skip..].iter().copied());
        obs.extend(sim.qvel().iter().copied());
        if self.include_cfrc_ext {
            let (lo, hi) = self.contact_force_range;
            let forces = sim.data.cfrc_ext()[1..].as_flattened();
            obs.extend(forces.iter().map(|f| crate::numeric::clip(*f, lo, hi)));
        }
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        normal_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        let before = sim.body_xpos(self.main_body);
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let after = sim.body_xpos(self.main_body);
        let dt = sim.dt();
        let x_velocity = (after[0] - before[0]) / dt;
        let y_velocity = (after[1] - before[1]) / dt;

        let healthy = self.is_healthy(sim);
        let forward_reward = x_velocity * self.forward_reward_weight;
        let healthy_reward = if healthy { self.healthy_reward } else { 0.0 };
        let rewards = forward_reward + healthy_reward;
        // float32: `weight * np.sum(np.square(action))` with a float32 action.
        let ctrl_cost = (self.ctrl_cost_weight as f32 * sum_squares_f32(action)) as f64;
        let (lo, hi) = self.contact_force_range;
        let contact_cost = self.contact_cost_weight
            * sum_squares_clipped(sim.data.cfrc_ext().as_flattened(), lo, hi);
        let reward = rewards - (ctrl_cost + contact_cost);

        xy_info(sim, info);
        info.set_f64("x_velocity", x_velocity);
        info.set_f64("y_velocity", y_velocity);
        info.set_f64("reward_forward", forward_reward);
        info.set_f64("reward_ctrl", -ctrl_cost);
        info.set_f64("reward_contact", -contact_cost);
        info.set_f64("reward_survive", healthy_reward);
        (reward, !healthy && self.terminate_when_unhealthy)
    }

    fn reset_info(&self, sim: &Sim, info: &mut Info) {
        xy_info(sim, info);
    }
}
