//! `MountainCarContinuous-v0`: the mountain car with a continuous force and an energy penalty.

use crate::classic_env::{EnvEntry, check_render_mode, classic_env, not_reset};
use crate::layout::{read_f32, write_f32s};
use crate::mountain_car::{MAX_POSITION, MAX_SPEED, MIN_POSITION, observation_space};
use crate::numeric::{as_f32, py_square};
use crate::reset_options;
use crate::rng::{NumpyRng, reseed};
use envhub_core::{EnvConfig, EnvError, Info, ResetOptions, Space, Transition};

const ID: &str = "MountainCarContinuous-v0";

/// Gymnasium's `metadata["render_fps"]`.
const RENDER_FPS: f64 = 30.0;

const OPTIONS: &[&str] = &["goal_velocity"];
const STATE_NAMES: &[&str] = &["position", "velocity"];

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: ID,
    max_episode_steps: 999,
    options: OPTIONS,
    make: |config| Ok(Box::new(MountainCarContinuous::new(config)?)),
};

const GOAL_POSITION: f64 = 0.45;
const POWER: f64 = 0.0015;
const MIN_ACTION: f32 = -1.0;
const MAX_ACTION: f32 = 1.0;

/// The force of one step, `min(max(action[0], min_action), max_action)` in Gymnasium. Python's
/// `max` and `min` return the bound itself, a Python float, for an action beyond it, so NumPy
/// then computes the push in float64; an action within the bounds stays a float32 scalar.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Force {
    /// The action itself, within the bounds.
    Float32(f32),
    /// A bound, for an action beyond it.
    Bound(f64),
}

impl Force {
    fn of(action: f32) -> Force {
        if action < MIN_ACTION {
            Force::Bound(MIN_ACTION as f64)
        } else if action > MAX_ACTION {
            Force::Bound(MAX_ACTION as f64)
        } else {
            Force::Float32(action)
        }
    }
}

/// `MountainCarContinuous-v0` as in Gymnasium 1.4: a `Box(-1, 1, (1,), float32)` force,
/// reward `-0.1·action²` per step plus 100 on reaching `position >= 0.45` with
/// `velocity >= goal_velocity`, which terminates.
///
/// An action beyond the bounds pushes with the bound's force, while the penalty uses the action as
/// given, as in Gymnasium.
///
/// Gymnasium stores this env's state as a float32 array after every step, so NumPy computes the
/// next step in float32 (the first step after a reset, from the float64 reset state, in
/// float64). This env does the same: [`MountainCarContinuous::set_state_float32`] restores a
/// state saved after a step exactly; [`ClassicEnv::set_state`] sets a float64 state as `reset`
/// does.
///
/// Option (`extra`): `goal_velocity` (default 0). Reset options: `low`, `high` (default -0.6, -0.4), the range the
/// position is drawn from; the velocity starts at 0.
pub struct MountainCarContinuous {
    goal_velocity: f64,
    observation_space: Space,
    action_space: Space,
    rng: Option<NumpyRng>,
    state: Option<[f64; 2]>,
    /// Whether the state is a float32 array (after a step) rather than float64.
    float32: bool,
}

impl MountainCarContinuous {
    /// Creates the env from `config` (`extra` may hold `goal_velocity`).
    pub fn new(config: &EnvConfig) -> Result<Self, EnvError> {
        check_render_mode(ID, config)?;
        let keys = config.extra_keys(ID, OPTIONS)?;
        Ok(MountainCarContinuous {
            goal_velocity: keys.f64("goal_velocity", 0.0)?,
            observation_space: observation_space(),
            action_space: Space::box_f32(&[1], MIN_ACTION as f64, MAX_ACTION as f64),
            rng: None,
            state: None,
            float32: false,
        })
    }

    /// Sets a float32 state, as Gymnasium holds it after a step, so the next step is computed
    /// in float32 exactly as Gymnasium would.
    pub fn set_state_float32(&mut self, [position, velocity]: [f32; 2]) {
        self.state = Some([position as f64, velocity as f64]);
        self.float32 = true;
    }

    /// Whether the state is held as float32 (see [`Self::set_state_float32`]).
    pub fn state_is_float32(&self) -> bool {
        self.float32
    }

    /// One step from a float64 state, as NumPy runs it: a float32 force term in float32, the
    /// rest in float64. Returns the new position, velocity and whether the goal is reached.
    fn step_float64(&self, position: f64, velocity: f64, force: Force) -> (f64, f64, bool) {
        let gravity = 0.0025 * (3.0 * position).cos();
        let velocity = velocity
            + match force {
                Force::Float32(force) => (force * as_f32(POWER) - as_f32(gravity)) as f64,
                Force::Bound(force) => force * POWER - gravity,
            };
        let mut velocity = velocity.clamp(-MAX_SPEED, MAX_SPEED);
        let position = (position + velocity).clamp(MIN_POSITION, MAX_POSITION);
        if position == MIN_POSITION && velocity < 0.0 {
            velocity = 0.0;
        }
        let done = position >= GOAL_POSITION && velocity >= self.goal_velocity;
        (position, velocity, done)
    }

    /// One step from a float32 state: every operation in float32 with the Python constants
    /// cast to float32, except where Gymnasium assigns a clipped velocity or the wall's 0 as
    /// a Python number, which it then compares with `goal_velocity` in float64.
    fn step_float32(&self, position: f32, velocity: f32, force: Force) -> (f64, f64, bool) {
        let max_speed = as_f32(MAX_SPEED);
        let gravity = 0.0025 * ((3.0 * position) as f64).cos();
        let mut velocity = velocity
            + match force {
                Force::Float32(force) => force * as_f32(POWER) - as_f32(gravity),
                // A Python float meets the float32 velocity.
                Force::Bound(force) => as_f32(force * POWER - gravity),
            };
        // Set when `velocity` has become a Python number (clipped, or stopped by the wall).
        let mut python_velocity = None;
        if velocity > max_speed {
            velocity = max_speed;
            python_velocity = Some(MAX_SPEED);
        } else if velocity < -max_speed {
            velocity = -max_speed;
            python_velocity = Some(-MAX_SPEED);
        }
        let position = (position + velocity).clamp(as_f32(MIN_POSITION), as_f32(MAX_POSITION));
        if position == as_f32(MIN_POSITION) && velocity < 0.0 {
            velocity = 0.0;
            python_velocity = Some(0.0);
        }
        let fast_enough = match python_velocity {
            Some(v) => v >= self.goal_velocity,
            None => velocity >= as_f32(self.goal_velocity),
        };
        let done = position >= as_f32(GOAL_POSITION) && fast_enough;
        (position as f64, velocity as f64, done)
    }
}

classic_env!(MountainCarContinuous {
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
        self.float32 = false;
        Ok(())
    }

    fn step(
        &mut self,
        action: &[u8],
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<Transition, EnvError> {
        let [position, velocity] = self.state.ok_or_else(|| not_reset(ID))?;
        let action = read_f32(action);
        let force = Force::of(action);
        let (position, velocity, terminated) = if self.float32 {
            self.step_float32(position as f32, velocity as f32, force)
        } else {
            self.step_float64(position, velocity, force)
        };
        // `math.pow(action[0], 2) * 0.1` in float64, on the unclipped action.
        let penalty = py_square(action as f64) * 0.1;
        let reward = if terminated { 100.0 } else { 0.0 } - penalty;

        let state = [position as f32, velocity as f32];
        write_f32s(obs, &state);
        self.state = Some(state.map(f64::from));
        self.float32 = true;
        Ok(Transition {
            reward,
            terminated,
            truncated: false,
        })
    }
} on_set_state(env) {
    // A float64 state, as `reset` leaves it; `set_state_float32` takes one after a step.
    env.float32 = false;
});

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ClassicEnv;
    use envhub_core::Env;
    use serde_json::json;

    fn make() -> MountainCarContinuous {
        MountainCarContinuous::new(&EnvConfig::default()).unwrap()
    }

    fn step(env: &mut MountainCarContinuous, force: f32) -> Transition {
        env.step(&force.to_le_bytes(), &mut [0u8; 8], &mut Info::default())
            .unwrap()
    }

    #[test]
    fn spaces_match_gymnasium() {
        let env = make();
        assert_eq!(env.action_space(), &Space::box_f32(&[1], -1.0, 1.0));
        assert_eq!(env.observation_space(), &observation_space());
    }

    #[test]
    fn reset_draws_within_bounds() {
        let mut env = make();
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
            assert!(!env.state_is_float32());
        }
        let options: ResetOptions = [("high".to_string(), json!(-0.7))].into();
        assert!(
            env.reset(None, &options, &mut [0u8; 8], &mut Info::default())
                .is_err()
        );
    }

    #[test]
    fn reward_has_action_penalty_and_goal_bonus() {
        let mut env = make();
        env.set_state(&[0.0, 0.0]).unwrap();
        let t = step(&mut env, 0.5);
        assert!(!t.terminated);
        assert_eq!(t.reward, -0.025);
        assert!(env.state_is_float32());

        env.set_state(&[0.44, 0.06]).unwrap();
        let t = step(&mut env, 1.0);
        assert!(t.terminated);
        assert_eq!(t.reward, 100.0 - 0.1);
    }

    #[test]
    fn float32_state_round_trips() {
        let mut a = make();
        a.set_state(&[-0.5, 0.0]).unwrap();
        step(&mut a, 1.0);
        let saved: [f64; 2] = a.state().try_into().unwrap();
        let mut b = make();
        b.set_state_float32(saved.map(|v| v as f32));
        for _ in 0..50 {
            step(&mut a, 0.3);
            step(&mut b, 0.3);
        }
        assert_eq!(a.state(), b.state());
    }

    #[test]
    fn an_action_beyond_the_bounds_pushes_with_the_bound_and_pays_in_full() {
        assert_eq!(Force::of(3.0), Force::Bound(1.0));
        assert_eq!(Force::of(-1.5), Force::Bound(-1.0));
        assert_eq!(Force::of(1.0), Force::Float32(1.0));
        assert_eq!(Force::of(-1.0), Force::Float32(-1.0));
        let mut env = make();
        env.set_state(&[-0.5, 0.0]).unwrap();
        let t = step(&mut env, 3.0);
        assert_eq!(t.reward, -(3.0f64.powi(2) * 0.1));
        let [_, velocity] = env.state().try_into().unwrap();
        assert_eq!(velocity, (0.0015 - 0.0025 * (-1.5f64).cos()) as f32 as f64);
    }
}
