//! `MountainCar-v0`: drive an underpowered car up a hill by rocking it, with discrete pushes.

use crate::classic_env::{EnvEntry, check_render_mode, classic_env, not_reset};
use crate::layout::{read_discrete, write_f32s};
use crate::reset_options;
use crate::rng::{NumpyRng, reseed};
use envhub_core::{EnvConfig, EnvError, Info, ResetOptions, Space, Transition};

const ID: &str = "MountainCar-v0";

/// Gymnasium's `metadata["render_fps"]`.
const RENDER_FPS: f64 = 30.0;

const OPTIONS: &[&str] = &["goal_velocity"];
const STATE_NAMES: &[&str] = &["position", "velocity"];

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: ID,
    max_episode_steps: 200,
    options: OPTIONS,
    make: |config| Ok(Box::new(MountainCar::new(config)?)),
};

pub(crate) const MIN_POSITION: f64 = -1.2;
pub(crate) const MAX_POSITION: f64 = 0.6;
pub(crate) const MAX_SPEED: f64 = 0.07;
const GOAL_POSITION: f64 = 0.5;
const FORCE: f64 = 0.001;
const GRAVITY: f64 = 0.0025;

/// The observation space both mountain cars share: position in `[-1.2, 0.6]`, velocity in
/// `[-0.07, 0.07]`, bounds rounded to float32 as Gymnasium stores them.
pub(crate) fn observation_space() -> Space {
    let low = [MIN_POSITION, -MAX_SPEED].map(|v| v as f32 as f64);
    let high = [MAX_POSITION, MAX_SPEED].map(|v| v as f32 as f64);
    Space::box_f32_bounds(low.to_vec(), high.to_vec())
}

/// `MountainCar-v0` as in Gymnasium 1.4: state `[position, velocity]` in float64, observation
/// the same as float32, `Discrete(3)` actions (push left, none, right), reward -1 per step,
/// termination when `position >= 0.5` and `velocity >= goal_velocity`.
///
/// Option (`extra`): `goal_velocity` (default 0). Reset options: `low`, `high` (default -0.6,
/// -0.4), the range the position is drawn from; the velocity starts at 0.
pub struct MountainCar {
    goal_velocity: f64,
    observation_space: Space,
    action_space: Space,
    rng: Option<NumpyRng>,
    state: Option<[f64; 2]>,
}

impl MountainCar {
    /// Creates the env from `config` (`extra` may hold `goal_velocity`).
    pub fn new(config: &EnvConfig) -> Result<Self, EnvError> {
        check_render_mode(ID, config)?;
        let keys = config.extra_keys(ID, OPTIONS)?;
        Ok(MountainCar {
            goal_velocity: keys.f64("goal_velocity", 0.0)?,
            observation_space: observation_space(),
            action_space: Space::discrete(3),
            rng: None,
            state: None,
        })
    }
}

classic_env!(MountainCar {
    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<(), EnvError> {
        let (low, high) = reset_options::bounds(ID, options, -0.6, -0.4)?;
        let state = [reseed(&mut self.rng, seed).uniform(low, high), 0.0];
        write_f32s(obs, &state.map(|v| v as f32));
        self.state = Some(state);
        Ok(())
    }

    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<Transition, EnvError> {
        let [position, velocity] = self.state.ok_or_else(|| not_reset(ID))?;
        let push = (read_discrete(action) - 1) as f64;
        let velocity = velocity + (push * FORCE + (3.0 * position).cos() * -GRAVITY);
        let mut velocity = velocity.clamp(-MAX_SPEED, MAX_SPEED);
        let position = (position + velocity).clamp(MIN_POSITION, MAX_POSITION);
        if position == MIN_POSITION && velocity < 0.0 {
            velocity = 0.0;
        }
        let terminated = position >= GOAL_POSITION && velocity >= self.goal_velocity;

        let state = [position, velocity];
        write_f32s(obs, &state.map(|v| v as f32));
        self.state = Some(state);
        Ok(Transition {
            reward: -1.0,
            terminated,
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

    fn make(goal_velocity: Option<f64>) -> MountainCar {
        let mut config = EnvConfig::default();
        if let Some(v) = goal_velocity {
            config.extra.insert("goal_velocity".into(), json!(v));
        }
        MountainCar::new(&config).unwrap()
    }

    fn step(env: &mut MountainCar, action: i64) -> Transition {
        env.step(&action.to_le_bytes(), &mut [0u8; 8], &mut Info::default())
            .unwrap()
    }

    #[test]
    fn spaces_match_gymnasium() {
        let env = make(None);
        assert_eq!(env.action_space(), &Space::discrete(3));
        let Space::Box { low, high, .. } = env.observation_space() else {
            panic!("not a box")
        };
        assert_eq!(low, &[-1.2f32 as f64, -0.07f32 as f64]);
        assert_eq!(high, &[0.6f32 as f64, 0.07f32 as f64]);
    }

    #[test]
    fn reset_draws_within_bounds() {
        let mut env = make(None);
        for seed in 0..50 {
            env.reset(
                Some(seed),
                &ResetOptions::new(),
                &mut [0u8; 8],
                &mut Info::default(),
            )
            .unwrap();
            let [p, v] = env.state().try_into().unwrap();
            assert!((-0.6..-0.4).contains(&p) && v == 0.0);
        }
    }

    #[test]
    fn terminates_at_the_goal_with_goal_velocity() {
        let mut env = make(None);
        env.set_state(&[0.49, 0.02]).unwrap();
        assert!(step(&mut env, 2).terminated);
        env.set_state(&[0.3, 0.0]).unwrap();
        let t = step(&mut env, 2);
        assert!(!t.terminated && t.reward == -1.0);

        let mut env = make(Some(0.05));
        env.set_state(&[0.49, 0.02]).unwrap();
        assert!(!step(&mut env, 2).terminated);
    }

    #[test]
    fn left_wall_stops_the_car() {
        let mut env = make(None);
        env.set_state(&[-1.19, -0.07]).unwrap();
        step(&mut env, 0);
        assert_eq!(env.state(), [MIN_POSITION, 0.0]);
    }

    #[test]
    fn option_errors() {
        let mut config = EnvConfig::default();
        config.extra.insert("goal_speed".into(), json!(0.1));
        let err = MountainCar::new(&config).err().unwrap().to_string();
        assert!(err.contains("valid options are: goal_velocity"), "{err}");
        config.extra.clear();
        config.extra.insert("goal_velocity".into(), json!(true));
        assert!(MountainCar::new(&config).is_err());
    }
}
