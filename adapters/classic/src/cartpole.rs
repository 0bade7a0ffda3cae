//! `CartPole-v1`: balance a pole on a cart pushed left or right (Barto, Sutton & Anderson).

use crate::classic_env::{EnvEntry, check_render_mode, classic_env, not_reset};
use crate::layout::{read_discrete, write_f32s};
use crate::reset_options;
use crate::rng::{NumpyRng, reseed};
use envhub_core::{EnvConfig, EnvError, Info, ResetOptions, Space, Transition};

const ID: &str = "CartPole-v1";

/// Gymnasium's `metadata["render_fps"]`.
const RENDER_FPS: f64 = 50.0;

const OPTIONS: &[&str] = &["sutton_barto_reward"];
const STATE_NAMES: &[&str] = &["x", "x_dot", "theta", "theta_dot"];

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: ID,
    max_episode_steps: 500,
    options: OPTIONS,
    make: |config| Ok(Box::new(CartPole::new(config)?)),
};

const GRAVITY: f64 = 9.8;
const MASSCART: f64 = 1.0;
const MASSPOLE: f64 = 0.1;
const TOTAL_MASS: f64 = MASSPOLE + MASSCART;
/// Half the pole's length.
const LENGTH: f64 = 0.5;
const POLEMASS_LENGTH: f64 = MASSPOLE * LENGTH;
const FORCE_MAG: f64 = 10.0;
/// Seconds between state updates.
const TAU: f64 = 0.02;
const THETA_THRESHOLD_RADIANS: f64 = 12.0 * 2.0 * std::f64::consts::PI / 360.0;
const X_THRESHOLD: f64 = 2.4;

/// `CartPole-v1` as in Gymnasium 1.4: Euler integration in float64, observation
/// `[x, x_dot, theta, theta_dot]` as float32, `Discrete(2)` actions (0 pushes left, 1 right),
/// reward 1 per step (or Sutton & Barto's 0 / -1 at termination with `sutton_barto_reward`),
/// termination when `|x| > 2.4` or `|theta| > 12°`.
///
/// Option (`extra`): `sutton_barto_reward` (bool, default `false`). Reset options: `low`,
/// `high` (default ∓0.05), the range each state variable is drawn from.
///
/// Unlike Gymnasium, stepping past termination is not tracked: it keeps the reward of a
/// terminating step instead of warning and returning 0.
pub struct CartPole {
    sutton_barto_reward: bool,
    observation_space: Space,
    action_space: Space,
    rng: Option<NumpyRng>,
    state: Option<[f64; 4]>,
}

impl CartPole {
    /// Creates the env from `config` (`extra` may hold `sutton_barto_reward`).
    pub fn new(config: &EnvConfig) -> Result<Self, EnvError> {
        check_render_mode(ID, config)?;
        let keys = config.extra_keys(ID, OPTIONS)?;
        let high = [
            X_THRESHOLD * 2.0,
            f64::INFINITY,
            THETA_THRESHOLD_RADIANS * 2.0,
            f64::INFINITY,
        ]
        .map(|h| h as f32 as f64);
        Ok(CartPole {
            sutton_barto_reward: keys.bool("sutton_barto_reward", false)?,
            observation_space: Space::box_f32_bounds(high.map(|h| -h).to_vec(), high.to_vec()),
            action_space: Space::discrete(2),
            rng: None,
            state: None,
        })
    }

    fn write_obs(state: &[f64; 4], obs: &mut [u8]) {
        write_f32s(obs, &state.map(|v| v as f32));
    }
}

classic_env!(CartPole {
    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<(), EnvError> {
        let (low, high) = reset_options::bounds(ID, options, -0.05, 0.05)?;
        let rng = reseed(&mut self.rng, seed);
        let state = [(); 4].map(|_| rng.uniform(low, high));
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
        let [x, x_dot, theta, theta_dot] = self.state.ok_or_else(|| not_reset(ID))?;
        let force = if read_discrete(action) == 1 {
            FORCE_MAG
        } else {
            -FORCE_MAG
        };
        let costheta = theta.cos();
        let sintheta = theta.sin();
        let temp = (force + POLEMASS_LENGTH * (theta_dot * theta_dot) * sintheta) / TOTAL_MASS;
        let thetaacc = (GRAVITY * sintheta - costheta * temp)
            / (LENGTH * (4.0 / 3.0 - MASSPOLE * (costheta * costheta) / TOTAL_MASS));
        let xacc = temp - POLEMASS_LENGTH * thetaacc * costheta / TOTAL_MASS;

        let state = [
            x + TAU * x_dot,
            x_dot + TAU * xacc,
            theta + TAU * theta_dot,
            theta_dot + TAU * thetaacc,
        ];
        let [x, _, theta, _] = state;
        #[expect(
            clippy::manual_range_contains,
            reason = "Gymnasium's comparisons, under which a NaN state does not terminate"
        )]
        let terminated = x < -X_THRESHOLD
            || x > X_THRESHOLD
            || theta < -THETA_THRESHOLD_RADIANS
            || theta > THETA_THRESHOLD_RADIANS;
        let reward = match (self.sutton_barto_reward, terminated) {
            (false, _) => 1.0,
            (true, false) => 0.0,
            (true, true) => -1.0,
        };
        Self::write_obs(&state, obs);
        self.state = Some(state);
        Ok(Transition {
            reward,
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

    fn env(extra: &[(&str, serde_json::Value)]) -> CartPole {
        let mut config = EnvConfig::default();
        for (k, v) in extra {
            config.extra.insert(k.to_string(), v.clone());
        }
        CartPole::new(&config).unwrap()
    }

    fn step(env: &mut CartPole, action: i64) -> Transition {
        let mut obs = [0u8; 16];
        env.step(&action.to_le_bytes(), &mut obs, &mut Info::default())
            .unwrap()
    }

    #[test]
    fn spaces_match_gymnasium() {
        let env = env(&[]);
        assert_eq!(env.action_space(), &Space::discrete(2));
        let Space::Box { high, dtype, .. } = env.observation_space() else {
            panic!("not a box")
        };
        assert_eq!(*dtype, envhub_core::DType::Float32);
        assert_eq!(high[0], 4.8f32 as f64);
        assert_eq!(high[2], 0.41887903f32 as f64);
        assert!(high[1].is_infinite() && high[3].is_infinite());
    }

    #[test]
    fn reset_draws_within_bounds() {
        let mut env = env(&[]);
        let mut obs = [0u8; 16];
        let mut options = ResetOptions::new();
        for seed in 0..50 {
            env.reset(Some(seed), &options, &mut obs, &mut Info::default())
                .unwrap();
            assert!(env.state().iter().all(|v| (-0.05..0.05).contains(v)));
        }
        options.insert("low".into(), json!(0.5));
        options.insert("high".into(), json!(0.6));
        env.reset(None, &options, &mut obs, &mut Info::default())
            .unwrap();
        assert!(env.state().iter().all(|v| (0.5..0.6).contains(v)));
    }

    #[test]
    fn seed_gives_gymnasium_initial_state() {
        // gym.make("CartPole-v1").reset(seed=42); env.unwrapped.state
        let mut env = env(&[]);
        let mut obs = [0u8; 16];
        env.reset(
            Some(42),
            &ResetOptions::new(),
            &mut obs,
            &mut Info::default(),
        )
        .unwrap();
        assert_eq!(
            env.state(),
            [
                0.027395604855596334,
                -0.006112156024794771,
                0.03585979199113824,
                0.019736802905936393
            ]
        );
    }

    #[test]
    fn terminates_past_angle_or_position() {
        let mut env = env(&[]);
        env.set_state(&[0.0, 0.0, 0.2, 1.0]).unwrap();
        let t = step(&mut env, 1);
        assert!(t.terminated && t.reward == 1.0);
        env.set_state(&[2.39, 1.0, 0.0, 0.0]).unwrap();
        assert!(step(&mut env, 1).terminated);
        env.set_state(&[-2.39, -1.0, 0.0, 0.0]).unwrap();
        assert!(step(&mut env, 0).terminated);
        env.set_state(&[0.0, 0.0, 0.0, 0.0]).unwrap();
        let t = step(&mut env, 0);
        assert!(!t.terminated && t.reward == 1.0);
    }

    #[test]
    fn sutton_barto_reward() {
        let mut env = env(&[("sutton_barto_reward", json!(true))]);
        env.set_state(&[0.0; 4]).unwrap();
        assert_eq!(step(&mut env, 0).reward, 0.0);
        env.set_state(&[0.0, 0.0, 0.2, 1.0]).unwrap();
        assert_eq!(step(&mut env, 0).reward, -1.0);
    }

    #[test]
    fn option_errors() {
        let mut config = EnvConfig::default();
        config.extra.insert("sutton_barto".into(), json!(true));
        let err = CartPole::new(&config).err().unwrap().to_string();
        assert!(err.contains("unknown option `sutton_barto`"), "{err}");
        assert!(
            err.contains("valid options are: sutton_barto_reward"),
            "{err}"
        );

        let mut config = EnvConfig::default();
        config.extra.insert("sutton_barto_reward".into(), json!(1));
        let err = CartPole::new(&config).err().unwrap().to_string();
        assert!(err.contains("expected `true` or `false`, got `1`"), "{err}");

        let mut env = env(&[]);
        let err = env.set_state(&[0.0; 3]).unwrap_err().to_string();
        assert!(err.contains("expects 4 values (x, x_dot, theta, theta_dot), got 3"));
        let mut obs = [0u8; 16];
        let mut fresh = CartPole::new(&EnvConfig::default()).unwrap();
        assert!(
            fresh
                .step(&0i64.to_le_bytes(), &mut obs, &mut Info::default())
                .is_err()
        );
    }
}
