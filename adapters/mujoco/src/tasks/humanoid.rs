//! `Humanoid-v5`: a 3D biped that learns to walk forward (`gymnasium/envs/mujoco/humanoid_v5.py`).

use super::{CameraConfig, EnvEntry, Task, uniform_noise};
use crate::numeric::{sum, sum_squares};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, InfoValue, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    trackbodyid: Some(1),
    distance: Some(4.0),
    lookat: Some([0.0, 0.0, 2.0]),
    elevation: Some(-20.0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "Humanoid-v5",
    xml_file: "humanoid.xml",
    frame_skip: 5,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "forward_reward_weight",
        "ctrl_cost_weight",
        "contact_cost_weight",
        "contact_cost_range",
        "healthy_reward",
        "terminate_when_unhealthy",
        "healthy_z_range",
        "reset_noise_scale",
        "exclude_current_positions_from_observation",
        "include_cinert_in_observation",
        "include_cvel_in_observation",
        "include_qfrc_actuator_in_observation",
        "include_cfrc_ext_in_observation",
    ],
    make: |keys, _| Ok(Box::new(Humanoid::new(keys)?)),
};

/// The observation Humanoid and HumanoidStandup share: positions, velocities, and optionally
/// the bodies' com-based inertia, velocity, actuator forces and external forces.
pub(super) struct HumanoidObs {
    exclude_current_positions: bool,
    cinert: bool,
    cvel: bool,
    qfrc_actuator: bool,
    cfrc_ext: bool,
}

impl HumanoidObs {
    pub(super) fn new(keys: &ExtraKeys) -> Result<Self, EnvError> {
        Ok(HumanoidObs {
            exclude_current_positions: keys
                .bool("exclude_current_positions_from_observation", true)?,
            cinert: keys.bool("include_cinert_in_observation", true)?,
            cvel: keys.bool("include_cvel_in_observation", true)?,
            qfrc_actuator: keys.bool("include_qfrc_actuator_in_observation", true)?,
            cfrc_ext: keys.bool("include_cfrc_ext_in_observation", true)?,
        })
    }

    pub(super) fn write(&self, sim: &Sim, obs: &mut ObsWriter) {
        let d = &sim.data;
        let skip = if self.exclude_current_positions { 2 } else { 0 };
        obs.extend(sim.qpos()[skip..].iter().copied());
        obs.extend(sim.qvel().iter().copied());
        if self.cinert {
            obs.extend(d.cinert()[1..].as_flattened().iter().copied());
        }
        if self.cvel {
            obs.extend(d.cvel()[1..].as_flattened().iter().copied());
        }
        if self.qfrc_actuator {
            obs.extend(d.qfrc_actuator()[6..].iter().copied());
        }
        if self.cfrc_ext {
            obs.extend(d.cfrc_ext()[1..].as_flattened().iter().copied());
        }
    }
}

/// `tendon_length` and `tendon_velocity`, as lists.
pub(super) fn tendon_info(sim: &Sim, info: &mut Info) {
    info.insert(
        "tendon_length",
        InfoValue::Floats(sim.data.ten_length().to_vec()),
    );
    info.insert(
        "tendon_velocity",
        InfoValue::Floats(sim.data.ten_velocity().to_vec()),
    );
}

/// `mass_center`: the bodies' mass-weighted mean position, x and y.
fn mass_center(sim: &Sim) -> [f64; 2] {
    let mass = sim.model().body_mass();
    let xipos = sim.data.xipos();
    let total = sum(mass);
    let mut num = [0.0; 2];
    for (m, p) in mass.iter().zip(xipos) {
        num[0] += m * p[0];
        num[1] += m * p[1];
    }
    [num[0] / total, num[1] / total]
}

struct Humanoid {
    obs: HumanoidObs,
    forward_reward_weight: f64,
    ctrl_cost_weight: f64,
    contact_cost_weight: f64,
    contact_cost_range: (f64, f64),
    healthy_reward: f64,
    terminate_when_unhealthy: bool,
    healthy_z_range: (f64, f64),
    reset_noise_scale: f64,
}

impl Humanoid {
    fn new(keys: &ExtraKeys) -> Result<Self, EnvError> {
        Ok(Humanoid {
            obs: HumanoidObs::new(keys)?,
            forward_reward_weight: keys.f64("forward_reward_weight", 1.25)?,
            ctrl_cost_weight: keys.f64("ctrl_cost_weight", 0.1)?,
            contact_cost_weight: keys.f64("contact_cost_weight", 5e-7)?,
            contact_cost_range: keys.range("contact_cost_range", (f64::NEG_INFINITY, 10.0))?,
            healthy_reward: keys.f64("healthy_reward", 5.0)?,
            terminate_when_unhealthy: keys.bool("terminate_when_unhealthy", true)?,
            healthy_z_range: keys.range("healthy_z_range", (1.0, 2.0))?,
            reset_noise_scale: keys.f64("reset_noise_scale", 1e-2)?,
        })
    }
}

impl Task for Humanoid {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        self.obs.write(sim, obs);
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        uniform_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        let before = mass_center(sim);
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let after = mass_center(sim);
        let dt = sim.dt();
        let x_velocity = (after[0] - before[0]) / dt;
        let y_velocity = (after[1] - before[1]) / dt;

        let (zlo, zhi) = self.healthy_z_range;
        let z = sim.qpos()[2];
        let healthy = zlo < z && z < zhi;
        let forward_reward = self.forward_reward_weight * x_velocity;
        let healthy_reward = if healthy { self.healthy_reward } else { 0.0 };
        // float64 here: the cost is of `data.ctrl`, not of the float32 action.
        let ctrl_cost = self.ctrl_cost_weight * sum_squares(sim.data.ctrl());
        let (lo, hi) = self.contact_cost_range;
        let contact_cost = crate::numeric::clip(
            self.contact_cost_weight * sum_squares(sim.data.cfrc_ext().as_flattened()),
            lo,
            hi,
        );
        let reward = (forward_reward + healthy_reward) - (ctrl_cost + contact_cost);

        super::ant::xy_info(sim, info);
        tendon_info(sim, info);
        info.set_f64("x_velocity", x_velocity);
        info.set_f64("y_velocity", y_velocity);
        info.set_f64("reward_survive", healthy_reward);
        info.set_f64("reward_forward", forward_reward);
        info.set_f64("reward_ctrl", -ctrl_cost);
        info.set_f64("reward_contact", -contact_cost);
        (reward, !healthy && self.terminate_when_unhealthy)
    }

    fn reset_info(&self, sim: &Sim, info: &mut Info) {
        super::ant::xy_info(sim, info);
        tendon_info(sim, info);
    }
}
