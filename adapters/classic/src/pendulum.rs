//! `Pendulum-v1`: swing a pendulum up and keep it upright with a bounded torque.

use crate::classic_env::{EnvEntry, check_render_mode, classic_env, not_reset};
use crate::layout::{read_f32, write_f32s};
use crate::numeric::{as_f32, py_square, py_square_f32};
use crate::reset_options;
use crate::rng::{NumpyRng, reseed};
use envhub_core::{EnvConfig, EnvError, Info, ResetOptions, Space, Transition};
use std::f64::consts::PI;

const ID: &str = "Pendulum-v1";

/// Gymnasium's `metadata["render_fps"]`.
const RENDER_FPS: f64 = 30.0;

const OPTIONS: &[&str] = &["g"];
const STATE_NAMES: &[&str] = &["theta", "theta_dot"];

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: ID,
    max_episode_steps: 200,
    options: OPTIONS,
    make: |config| Ok(Box::new(Pendulum::new(config)?)),
};

const MAX_SPEED: f64 = 8.0;
const MAX_TORQUE: f32 = 2.0;
const DT: f64 = 0.05;
const M: f64 = 1.0;
const L: f64 = 1.0;
/// `0.001` and `3.0 / (m * l**2)` meet the float32 torque, so NumPy casts them to float32.
const TORQUE_COST: f32 = as_f32(0.001);
const TORQUE_GAIN: f32 = as_f32(3.0 / (M * L * L));

/// `Pendulum-v1` as in Gymnasium 1.4: state `[theta, theta_dot]` in float64, observation
/// `[cos theta, sin theta, theta_dot]` as float32, a `Box(-2, 2, (1,), float32)` torque, reward
/// `-(angle² + 0.1·theta_dot² + 0.001·torque²)` with the clipped torque, and no termination.
///
/// NumPy evaluates the torque terms in float32 (`u**2`, `3.0 * u` with `u` a float32 scalar)
/// and squares float64s with `pow`; both are reproduced here.
///
/// Option (`extra`): `g` (gravity, default 10.0). Reset options: `x_init` (default π) and
/// `y_init` (default 1.0), the half-widths of the ranges `theta` and `theta_dot` are drawn from.
pub struct Pendulum {
    g: f64,
    observation_space: Space,
    action_space: Space,
    rng: Option<NumpyRng>,
    state: Option<[f64; 2]>,
}

impl Pendulum {
    /// Creates the env from `config` (`extra` may hold `g`).
    pub fn new(config: &EnvConfig) -> Result<Self, EnvError> {
        check_render_mode(ID, config)?;
        let keys = config.extra_keys(ID, OPTIONS)?;
        Ok(Pendulum {
            g: keys.f64("g", 10.0)?,
            observation_space: Space::box_f32_bounds(
                vec![-1.0, -1.0, -MAX_SPEED],
                vec![1.0, 1.0, MAX_SPEED],
            ),
            action_space: Space::box_f32(&[1], -(MAX_TORQUE as f64), MAX_TORQUE as f64),
            rng: None,
            state: None,
        })
    }

    fn write_obs(&[theta, theta_dot]: &[f64; 2], obs: &mut [u8]) {
        write_f32s(
            obs,
            &[theta.cos() as f32, theta.sin() as f32, theta_dot as f32],
        );
    }
}

/// `((x + pi) % (2 * pi)) - pi` with Python's (NumPy's) floored modulo.
fn angle_normalize(x: f64) -> f64 {
    (x + PI).rem_euclid(2.0 * PI) - PI
}

classic_env!(Pendulum {
    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<(), EnvError> {
        reset_options::check_keys(ID, options, &["x_init", "y_init"])?;
        let x = reset_options::number(ID, options, "x_init", PI)?;
        let y = reset_options::number(ID, options, "y_init", 1.0)?;
        let rng = reseed(&mut self.rng, seed);
        let state = [rng.uniform(-x, x), rng.uniform(-y, y)];
        Self::write_obs(&state, obs);
        self.state = Some(state);
        Ok(())
    }

    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<Transition, EnvError> {
        let [th, thdot] = self.state.ok_or_else(|| not_reset(ID))?;
        let u = read_f32(action).clamp(-MAX_TORQUE, MAX_TORQUE);
        let angle = angle_normalize(th);
        let costs =
            py_square(angle) + 0.1 * py_square(thdot) + (py_square_f32(u) * TORQUE_COST) as f64;

        let newthdot =
            thdot + (3.0 * self.g / (2.0 * L) * th.sin() + (TORQUE_GAIN * u) as f64) * DT;
        let newthdot = newthdot.clamp(-MAX_SPEED, MAX_SPEED);
        let newth = th + newthdot * DT;

        let state = [newth, newthdot];
        Self::write_obs(&state, obs);
        self.state = Some(state);
        Ok(Transition {
            reward: -costs,
            terminated: false,
            truncated: false,
        })
    }
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ClassicEnv;
    use envhub_core::Env;
    use serde_json::json;

    fn step(env: &mut Pendulum, torque: f32) -> (Transition, [f32; 3]) {
        let mut obs = [0u8; 12];
        let t = env
            .step(&torque.to_le_bytes(), &mut obs, &mut Info::default())
            .unwrap();
        (t, bytemuck::cast(obs))
    }

    #[test]
    fn spaces_match_gymnasium() {
        let env = Pendulum::new(&EnvConfig::default()).unwrap();
        assert_eq!(env.action_space(), &Space::box_f32(&[1], -2.0, 2.0));
        assert_eq!(
            env.observation_space(),
            &Space::box_f32_bounds(vec![-1.0, -1.0, -8.0], vec![1.0, 1.0, 8.0])
        );
    }

    #[test]
    fn reset_draws_within_bounds() {
        let mut env = Pendulum::new(&EnvConfig::default()).unwrap();
        let mut obs = [0u8; 12];
        for seed in 0..50 {
            env.reset(
                Some(seed),
                &ResetOptions::new(),
                &mut obs,
                &mut Info::default(),
            )
            .unwrap();
            let [th, thdot] = env.state().try_into().unwrap();
            assert!((-PI..PI).contains(&th) && (-1.0..1.0).contains(&thdot));
        }
        let options: ResetOptions = [("x_init".to_string(), json!(0.1))].into();
        env.reset(None, &options, &mut obs, &mut Info::default())
            .unwrap();
        assert!(env.state()[0].abs() <= 0.1);
        let options: ResetOptions = [("low".to_string(), json!(0.1))].into();
        let err = env
            .reset(None, &options, &mut obs, &mut Info::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("valid reset options are `x_init`, `y_init`"),
            "{err}"
        );
    }

    #[test]
    fn reward_uses_the_clipped_torque_and_never_terminates() {
        let mut env = Pendulum::new(&EnvConfig::default()).unwrap();
        env.set_state(&[0.0, 0.0]).unwrap();
        let (t, obs) = step(&mut env, 5.0);
        assert!(!t.terminated);
        assert_eq!(t.reward, -((4.0f32 * TORQUE_COST) as f64));
        assert_eq!(obs[2], (6.0f32 as f64 * DT) as f32);
        env.set_state(&[PI, 100.0]).unwrap();
        let (_, obs) = step(&mut env, 0.0);
        assert_eq!(obs[2], 8.0, "speed is clipped");
    }

    #[test]
    fn gravity_option() {
        let mut config = EnvConfig::default();
        config.extra.insert("g".into(), json!(9.81));
        let mut env = Pendulum::new(&config).unwrap();
        env.set_state(&[1.0, 0.0]).unwrap();
        let (_, obs) = step(&mut env, 0.0);
        assert_eq!(obs[2], ((3.0 * 9.81 / 2.0 * 1f64.sin()) * DT) as f32);

        config.extra.insert("g".into(), json!("strong"));
        let err = Pendulum::new(&config).err().unwrap().to_string();
        assert!(err.contains("invalid option `g`"), "{err}");
    }
}
