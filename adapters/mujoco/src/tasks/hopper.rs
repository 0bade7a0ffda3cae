//! `Hopper-v5`: a planar one-legged hopper (`gymnasium/envs/mujoco/hopper_v5.py`).

use super::{CameraConfig, EnvEntry, Task, uniform_noise};
use crate::numeric::{clip, sum_squares_f32};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    trackbodyid: Some(2),
    distance: Some(3.0),
    lookat: Some([0.0, 0.0, 1.15]),
    elevation: Some(-20.0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "Hopper-v5",
    xml_file: "hopper.xml",
    frame_skip: 4,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "forward_reward_weight",
        "ctrl_cost_weight",
        "healthy_reward",
        "terminate_when_unhealthy",
        "healthy_state_range",
        "healthy_z_range",
        "healthy_angle_range",
        "reset_noise_scale",
        "exclude_current_positions_from_observation",
    ],
    make: |keys, _| Ok(Box::new(Hopper::new(keys)?)),
};

/// What Hopper and Walker2d share: forward reward, a survival bonus while healthy, a control
/// cost, velocities clipped to ±10 in the observation.
pub(super) struct Planar {
    pub(super) forward_reward_weight: f64,
    pub(super) ctrl_cost_weight: f64,
    pub(super) healthy_reward: f64,
    pub(super) terminate_when_unhealthy: bool,
    pub(super) healthy_z_range: (f64, f64),
    pub(super) healthy_angle_range: (f64, f64),
    pub(super) reset_noise_scale: f64,
    pub(super) exclude_current_positions: bool,
}

impl Planar {
    pub(super) fn new(
        keys: &ExtraKeys,
        healthy_z_range: (f64, f64),
        healthy_angle_range: (f64, f64),
    ) -> Result<Self, EnvError> {
        Ok(Planar {
            forward_reward_weight: keys.f64("forward_reward_weight", 1.0)?,
            ctrl_cost_weight: keys.f64("ctrl_cost_weight", 1e-3)?,
            healthy_reward: keys.f64("healthy_reward", 1.0)?,
            terminate_when_unhealthy: keys.bool("terminate_when_unhealthy", true)?,
            healthy_z_range: keys.range("healthy_z_range", healthy_z_range)?,
            healthy_angle_range: keys.range("healthy_angle_range", healthy_angle_range)?,
            reset_noise_scale: keys.f64("reset_noise_scale", 5e-3)?,
            exclude_current_positions: keys
                .bool("exclude_current_positions_from_observation", true)?,
        })
    }

    /// `min_z < z < max_z and min_angle < angle < max_angle`.
    pub(super) fn z_and_angle_healthy(&self, sim: &Sim) -> bool {
        let (z, angle) = (sim.qpos()[1], sim.qpos()[2]);
        let (zlo, zhi) = self.healthy_z_range;
        let (alo, ahi) = self.healthy_angle_range;
        zlo < z && z < zhi && alo < angle && angle < ahi
    }

    pub(super) fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        let skip = usize::from(self.exclude_current_positions);
        obs.extend(sim.qpos()[skip..].iter().copied());
        obs.extend(sim.qvel().iter().map(|v| clip(*v, -10.0, 10.0)));
    }

    pub(super) fn reset_model(
        &self,
        sim: &Sim,
        rng: &mut NumpyRng,
        qpos: &mut [f64],
        qvel: &mut [f64],
    ) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        uniform_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    /// The step, with `healthy` judging the state after it.
    pub(super) fn step(
        &self,
        sim: &mut Sim,
        action: &[f32],
        info: &mut Info,
        healthy: impl Fn(&Sim) -> bool,
    ) -> (f64, bool) {
        let x_before = sim.qpos()[0];
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let x_after = sim.qpos()[0];
        let x_velocity = (x_after - x_before) / sim.dt();
        let healthy = healthy(sim);
        let forward_reward = self.forward_reward_weight * x_velocity;
        let healthy_reward = if healthy { self.healthy_reward } else { 0.0 };
        let ctrl_cost = (self.ctrl_cost_weight as f32 * sum_squares_f32(action)) as f64;
        let reward = forward_reward + healthy_reward - ctrl_cost;
        self.reset_info(sim, info);
        info.set_f64("x_velocity", x_velocity);
        info.set_f64("reward_forward", forward_reward);
        info.set_f64("reward_ctrl", -ctrl_cost);
        info.set_f64("reward_survive", healthy_reward);
        (reward, !healthy && self.terminate_when_unhealthy)
    }

    pub(super) fn reset_info(&self, sim: &Sim, info: &mut Info) {
        info.set_f64("x_position", sim.qpos()[0]);
        info.set_f64("z_distance_from_origin", sim.qpos()[1] - sim.init_qpos[1]);
    }
}

struct Hopper {
    planar: Planar,
    healthy_state_range: (f64, f64),
}

impl Hopper {
    fn new(keys: &ExtraKeys) -> Result<Self, EnvError> {
        Ok(Hopper {
            planar: Planar::new(keys, (0.7, f64::INFINITY), (-0.2, 0.2))?,
            healthy_state_range: keys.range("healthy_state_range", (-100.0, 100.0))?,
        })
    }
}

impl Task for Hopper {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        self.planar.write_obs(sim, obs);
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        self.planar.reset_model(sim, rng, qpos, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        let (lo, hi) = self.healthy_state_range;
        let planar = &self.planar;
        planar.step(sim, action, info, |sim| {
            // `state_vector()[2:]`: qpos without x and z, then qvel.
            let state_ok = sim.qpos()[2..]
                .iter()
                .chain(sim.qvel())
                .all(|s| lo < *s && *s < hi);
            state_ok && planar.z_and_angle_healthy(sim)
        })
    }

    fn reset_info(&self, sim: &Sim, info: &mut Info) {
        self.planar.reset_info(sim, info);
    }
}
