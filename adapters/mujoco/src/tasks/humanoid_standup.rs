//! `HumanoidStandup-v5`: a humanoid lying down learns to stand up
//! (`gymnasium/envs/mujoco/humanoidstandup_v5.py`).

use super::humanoid::{HumanoidObs, tendon_info};
use super::{CameraConfig, EnvEntry, Task, uniform_noise};
use crate::numeric::{clip, sum_squares};
use crate::obs::ObsWriter;
use crate::sim::Sim;
use envhub_core::{EnvError, ExtraKeys, Info, NumpyRng};

/// Gymnasium's `DEFAULT_CAMERA_CONFIG`.
const DEFAULT_CAMERA_CONFIG: CameraConfig = CameraConfig {
    trackbodyid: Some(1),
    distance: Some(4.0),
    lookat: Some([0.0, 0.0, 0.8925]),
    elevation: Some(-20.0),
    ..CameraConfig::NONE
};

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: "HumanoidStandup-v5",
    xml_file: "humanoidstandup.xml",
    frame_skip: 5,
    max_episode_steps: 1000,
    default_camera_config: DEFAULT_CAMERA_CONFIG,
    options: &[
        "uph_cost_weight",
        "ctrl_cost_weight",
        "impact_cost_weight",
        "impact_cost_range",
        "reset_noise_scale",
        "exclude_current_positions_from_observation",
        "include_cinert_in_observation",
        "include_cvel_in_observation",
        "include_qfrc_actuator_in_observation",
        "include_cfrc_ext_in_observation",
    ],
    make: |keys, _| Ok(Box::new(HumanoidStandup::new(keys)?)),
};

struct HumanoidStandup {
    obs: HumanoidObs,
    uph_cost_weight: f64,
    ctrl_cost_weight: f64,
    impact_cost_weight: f64,
    impact_cost_range: (f64, f64),
    reset_noise_scale: f64,
}

impl HumanoidStandup {
    fn new(keys: &ExtraKeys) -> Result<Self, EnvError> {
        Ok(HumanoidStandup {
            obs: HumanoidObs::new(keys)?,
            uph_cost_weight: keys.f64("uph_cost_weight", 1.0)?,
            ctrl_cost_weight: keys.f64("ctrl_cost_weight", 0.1)?,
            impact_cost_weight: keys.f64("impact_cost_weight", 5e-7)?,
            impact_cost_range: keys.range("impact_cost_range", (f64::NEG_INFINITY, 10.0))?,
            reset_noise_scale: keys.f64("reset_noise_scale", 1e-2)?,
        })
    }

    fn info(&self, sim: &Sim, info: &mut Info) {
        let q = sim.qpos();
        info.set_f64("x_position", q[0]);
        info.set_f64("y_position", q[1]);
        info.set_f64("z_distance_from_origin", q[2] - sim.init_qpos[2]);
        tendon_info(sim, info);
    }
}

impl Task for HumanoidStandup {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        self.obs.write(sim, obs);
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        uniform_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        sim.do_simulation(action.iter().map(|a| *a as f64));
        let pos_after = sim.qpos()[2];
        // Gymnasium 1.4 computes `uph_cost_weight` but does not apply it.
        let _ = self.uph_cost_weight;
        let uph_cost = (pos_after - 0.0) / sim.model().opt().timestep;
        let quad_ctrl_cost = self.ctrl_cost_weight * sum_squares(sim.data.ctrl());
        let (lo, hi) = self.impact_cost_range;
        let quad_impact_cost = clip(
            self.impact_cost_weight * sum_squares(sim.data.cfrc_ext().as_flattened()),
            lo,
            hi,
        );
        let reward = uph_cost - quad_ctrl_cost - quad_impact_cost + 1.0;
        self.info(sim, info);
        info.set_f64("reward_linup", uph_cost);
        info.set_f64("reward_quadctrl", -quad_ctrl_cost);
        info.set_f64("reward_impact", -quad_impact_cost);
        (reward, false)
    }

    fn reset_info(&self, sim: &Sim, info: &mut Info) {
        self.info(sim, info);
    }
}
