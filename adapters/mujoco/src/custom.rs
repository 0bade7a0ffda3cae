//! `custom_mjcf`: any MJCF or URDF model as an env, configured through `extra`.
//!
//! Observation `qpos ++ qvel` (float64); action one value in `[-1, 1]` per actuator, scaled to
//! the actuator's `ctrlrange` (passed through unscaled for an actuator without one);
//! terminated when the state stops being finite, or when a configured body's height leaves
//! `healthy_z_range`. The reward is 0 unless configured:
//! `forward_reward_weight * x velocity of forward_reward_body + healthy_reward while healthy
//! - ctrl_cost_weight * sum(action²)`.

use crate::gym_env::MujocoEnv;
use crate::obs::ObsWriter;
use crate::render::{self, CameraConfig, RenderSetup};
use crate::sim::{ModelCache, Sim};
use crate::tasks::{Task, uniform_noise};
use envhub_core::{EnvConfig, EnvError, ExtraKeys, Info, NumpyRng, Space};

const OPTIONS: &[&str] = &[
    "frame_skip",
    "forward_reward_body",
    "forward_reward_weight",
    "ctrl_cost_weight",
    "healthy_reward",
    "healthy_z_range",
    "terminate_when_unhealthy",
    "reset_noise_scale",
];

/// MuJoCo steps per env step unless `frame_skip` says otherwise.
const DEFAULT_FRAME_SKIP: u64 = 5;

/// Creates the env of `config.asset_path`.
pub(crate) fn make(
    env_id: &str,
    config: &EnvConfig,
    models: &ModelCache,
) -> Result<MujocoEnv, EnvError> {
    let options: Vec<&str> = OPTIONS.iter().chain(render::OPTIONS).copied().collect();
    let keys = config.extra_keys(env_id, &options)?;
    let render = RenderSetup::from_config(env_id, config, &keys, CameraConfig::NONE)?;
    let path = config
        .asset_path
        .as_ref()
        .ok_or_else(|| EnvError::InvalidOption {
            env_id: env_id.to_string(),
            key: "asset_path".into(),
            reason: "a `custom_mjcf` env needs the model file: set `asset_path` to an MJCF or \
                     URDF file"
                .into(),
        })?;
    let frame_skip = keys.u64("frame_skip", DEFAULT_FRAME_SKIP)?;
    if frame_skip == 0 {
        return Err(keys.error("frame_skip", "must be at least 1"));
    }
    let model = models.load(path, render.as_ref().map(|r| (r.width, r.height)))?;
    let sim = Sim::new(model, frame_skip as usize);
    let task = Custom::new(env_id, &keys, &sim)?;
    MujocoEnv::from_parts(env_id, sim, Box::new(task), &options, render)
}

struct Custom {
    /// The body whose x velocity is rewarded, and whose height must stay in range.
    body: Option<usize>,
    forward_reward_weight: f64,
    ctrl_cost_weight: f64,
    healthy_reward: f64,
    healthy_z_range: Option<(f64, f64)>,
    terminate_when_unhealthy: bool,
    reset_noise_scale: f64,
    /// Per actuator: `ctrl = offset + scale * action`.
    ctrl_map: Vec<(f64, f64)>,
}

impl Custom {
    fn new(env_id: &str, keys: &ExtraKeys, sim: &Sim) -> Result<Self, EnvError> {
        let body = match keys.str("forward_reward_body")? {
            None => None,
            Some(name) => Some(sim.body_id(env_id, name).map_err(|_| {
                keys.error(
                    "forward_reward_body",
                    format!("the model has no body `{name}`"),
                )
            })?),
        };
        let healthy_z_range = match keys.value("healthy_z_range") {
            None => None,
            Some(_) => Some(keys.range("healthy_z_range", (0.0, 0.0))?),
        };
        if healthy_z_range.is_some() && body.is_none() {
            return Err(keys.error(
                "healthy_z_range",
                "needs `forward_reward_body`, the body whose height it bounds",
            ));
        }
        let model = sim.model();
        let limited = model.actuator_ctrllimited();
        let ctrl_map = model
            .actuator_ctrlrange()
            .iter()
            .zip(limited)
            .map(|(r, lim)| {
                if *lim && r[1] > r[0] {
                    ((r[0] + r[1]) / 2.0, (r[1] - r[0]) / 2.0)
                } else {
                    (0.0, 1.0)
                }
            })
            .collect();
        Ok(Custom {
            body,
            forward_reward_weight: keys.f64("forward_reward_weight", 1.0)?,
            ctrl_cost_weight: keys.f64("ctrl_cost_weight", 0.0)?,
            healthy_reward: keys.f64("healthy_reward", 0.0)?,
            healthy_z_range,
            terminate_when_unhealthy: keys.bool("terminate_when_unhealthy", true)?,
            reset_noise_scale: keys.f64("reset_noise_scale", 0.0)?,
            ctrl_map,
        })
    }

    fn healthy(&self, sim: &Sim) -> bool {
        match (self.body, self.healthy_z_range) {
            (Some(body), Some((lo, hi))) => {
                let z = sim.body_xpos(body)[2];
                lo < z && z < hi
            }
            _ => true,
        }
    }
}

impl Task for Custom {
    fn write_obs(&self, sim: &Sim, obs: &mut ObsWriter) {
        obs.extend(sim.qpos().iter().copied());
        obs.extend(sim.qvel().iter().copied());
    }

    fn reset_model(&mut self, sim: &Sim, rng: &mut NumpyRng, qpos: &mut [f64], qvel: &mut [f64]) {
        uniform_noise(rng, &sim.init_qpos, self.reset_noise_scale, qpos);
        uniform_noise(rng, &sim.init_qvel, self.reset_noise_scale, qvel);
    }

    fn step(&mut self, sim: &mut Sim, action: &[f32], info: &mut Info) -> (f64, bool) {
        let before = self.body.map(|b| sim.body_xpos(b)[0]);
        let ctrl = action
            .iter()
            .zip(&self.ctrl_map)
            .map(|(a, (offset, scale))| offset + scale * *a as f64);
        sim.do_simulation(ctrl);
        let finite = sim.state_is_finite();
        let healthy = finite && self.healthy(sim);
        let ctrl_cost = self.ctrl_cost_weight
            * action
                .iter()
                .map(|a| (*a as f64) * (*a as f64))
                .sum::<f64>();
        let mut reward = -ctrl_cost;
        if let (Some(body), Some(before)) = (self.body, before) {
            let x = sim.body_xpos(body)[0];
            let x_velocity = (x - before) / sim.dt();
            let forward = self.forward_reward_weight * x_velocity;
            let survive = if healthy { self.healthy_reward } else { 0.0 };
            reward += forward + survive;
            info.set_f64("x_position", x);
            info.set_f64("x_velocity", x_velocity);
            info.set_f64("reward_forward", forward);
            info.set_f64("reward_survive", survive);
        }
        info.set_f64("reward_ctrl", -ctrl_cost);
        let terminated = !finite || (!healthy && self.terminate_when_unhealthy);
        (if finite { reward } else { 0.0 }, terminated)
    }

    fn action_space(&self, sim: &Sim) -> Space {
        Space::box_f32(&[sim.nu()], -1.0, 1.0)
    }
}
