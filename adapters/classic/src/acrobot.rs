//! `Acrobot-v1`: swing the tip of a two-link chain above a line by torquing the middle joint.

use crate::classic_env::{EnvEntry, check_render_mode, classic_env, not_reset};
use crate::layout::{read_discrete, write_f32s};
use crate::numeric::py_square;
use crate::reset_options;
use crate::rng::{NumpyRng, reseed};
use envhub_core::{EnvConfig, EnvError, Info, ResetOptions, Space, Transition};
use std::f64::consts::PI;

const ID: &str = "Acrobot-v1";

/// Gymnasium's `metadata["render_fps"]`.
const RENDER_FPS: f64 = 15.0;

const OPTIONS: &[&str] = &[];
const STATE_NAMES: &[&str] = &["theta1", "theta2", "dtheta1", "dtheta2"];

pub(crate) const ENTRY: EnvEntry = EnvEntry {
    id: ID,
    max_episode_steps: 500,
    options: OPTIONS,
    make: |config| Ok(Box::new(Acrobot::new(config)?)),
};

const DT: f64 = 0.2;
const LINK_LENGTH_1: f64 = 1.0;
const LINK_MASS_1: f64 = 1.0;
const LINK_MASS_2: f64 = 1.0;
const LINK_COM_POS_1: f64 = 0.5;
const LINK_COM_POS_2: f64 = 0.5;
const LINK_MOI: f64 = 1.0;
const MAX_VEL_1: f64 = 4.0 * PI;
const MAX_VEL_2: f64 = 9.0 * PI;
const AVAIL_TORQUE: [f64; 3] = [-1.0, 0.0, 1.0];

/// `Acrobot-v1` as in Gymnasium 1.4 with its defaults: the book's dynamics
/// (`book_or_nips = "book"`), no torque noise, one RK4 step of `dt = 0.2` s in float64, angles
/// wrapped to `[-π, π]` and velocities clipped to ±4π and ±9π. Observation
/// `[cos θ1, sin θ1, cos θ2, sin θ2, θ̇1, θ̇2]` as float32, `Discrete(3)` torques (-1, 0, +1),
/// reward -1 per step and 0 on the terminating one, termination when
/// `-cos θ1 - cos(θ2 + θ1) > 1`.
///
/// No `extra` options (Gymnasium's constructor takes only `render_mode`). Reset options:
/// `low`, `high` (default ∓0.1), the range each state variable is drawn from; as in Gymnasium
/// the drawn state is rounded to float32.
pub struct Acrobot {
    observation_space: Space,
    action_space: Space,
    rng: Option<NumpyRng>,
    state: Option<[f64; 4]>,
}

impl Acrobot {
    /// Creates the env; `config.extra` must be empty.
    pub fn new(config: &EnvConfig) -> Result<Self, EnvError> {
        check_render_mode(ID, config)?;
        config.extra_keys(ID, OPTIONS)?;
        let high = [1.0, 1.0, 1.0, 1.0, MAX_VEL_1, MAX_VEL_2].map(|h| h as f32 as f64);
        Ok(Acrobot {
            observation_space: Space::box_f32_bounds(high.map(|h| -h).to_vec(), high.to_vec()),
            action_space: Space::discrete(3),
            rng: None,
            state: None,
        })
    }

    fn write_obs(&[t1, t2, dt1, dt2]: &[f64; 4], obs: &mut [u8]) {
        let values = [t1.cos(), t1.sin(), t2.cos(), t2.sin(), dt1, dt2];
        write_f32s(obs, &values.map(|v| v as f32));
    }
}

/// `AcrobotEnv._dsdt` with `book_or_nips = "book"`, term for term in Gymnasium's order.
/// Squares of constants are exact either way; squares of state values use `pow` as NumPy does.
fn dsdt(s: &[f64; 5]) -> [f64; 5] {
    let (m1, m2) = (LINK_MASS_1, LINK_MASS_2);
    let l1 = LINK_LENGTH_1;
    let (lc1, lc2) = (LINK_COM_POS_1, LINK_COM_POS_2);
    let (i1, i2) = (LINK_MOI, LINK_MOI);
    let g = 9.8;
    let [theta1, theta2, dtheta1, dtheta2, a] = *s;
    let d1 = m1 * lc1 * lc1 + m2 * (l1 * l1 + lc2 * lc2 + 2.0 * l1 * lc2 * theta2.cos()) + i1 + i2;
    let d2 = m2 * (lc2 * lc2 + l1 * lc2 * theta2.cos()) + i2;
    let phi2 = m2 * lc2 * g * (theta1 + theta2 - PI / 2.0).cos();
    let phi1 = -m2 * l1 * lc2 * py_square(dtheta2) * theta2.sin()
        - 2.0 * m2 * l1 * lc2 * dtheta2 * dtheta1 * theta2.sin()
        + (m1 * lc1 + m2 * l1) * g * (theta1 - PI / 2.0).cos()
        + phi2;
    let ddtheta2 = (a + d2 / d1 * phi1 - m2 * l1 * lc2 * py_square(dtheta1) * theta2.sin() - phi2)
        / (m2 * lc2 * lc2 + i2 - py_square(d2) / d1);
    let ddtheta1 = -(d2 * ddtheta2 + phi1) / d1;
    [dtheta1, dtheta2, ddtheta1, ddtheta2, 0.0]
}

/// Gymnasium's `rk4(derivs, y0, [0, dt])`: one classic Runge-Kutta step.
fn rk4(y0: &[f64; 5], dt: f64) -> [f64; 5] {
    let dt2 = dt / 2.0;
    let add = |k: &[f64; 5], h: f64| std::array::from_fn(|i| y0[i] + h * k[i]);
    let k1 = dsdt(y0);
    let k2 = dsdt(&add(&k1, dt2));
    let k3 = dsdt(&add(&k2, dt2));
    let k4 = dsdt(&add(&k3, dt));
    std::array::from_fn(|i| y0[i] + dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// Gymnasium's `wrap(x, -pi, pi)`: shifts by whole turns, not a modulo.
fn wrap(mut x: f64, m: f64, big_m: f64) -> f64 {
    let diff = big_m - m;
    while x > big_m {
        x -= diff;
    }
    while x < m {
        x += diff;
    }
    x
}

classic_env!(Acrobot {
    fn reset(
        &mut self,
        seed: Option<u64>,
        options: &ResetOptions,
        obs: &mut [u8],
        _info: &mut Info,
    ) -> Result<(), EnvError> {
        let (low, high) = reset_options::bounds(ID, options, -0.1, 0.1)?;
        let rng = reseed(&mut self.rng, seed);
        let state = [(); 4].map(|_| rng.uniform(low, high) as f32 as f64);
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
        let [t1, t2, dt1, dt2] = self.state.ok_or_else(|| not_reset(ID))?;
        let torque = AVAIL_TORQUE[read_discrete(action) as usize];
        let ns = rk4(&[t1, t2, dt1, dt2, torque], DT);
        let state = [
            wrap(ns[0], -PI, PI),
            wrap(ns[1], -PI, PI),
            ns[2].clamp(-MAX_VEL_1, MAX_VEL_1),
            ns[3].clamp(-MAX_VEL_2, MAX_VEL_2),
        ];
        let terminated = -state[0].cos() - (state[1] + state[0]).cos() > 1.0;
        Self::write_obs(&state, obs);
        self.state = Some(state);
        Ok(Transition {
            reward: if terminated { 0.0 } else { -1.0 },
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

    fn make() -> Acrobot {
        Acrobot::new(&EnvConfig::default()).unwrap()
    }

    fn step(env: &mut Acrobot, action: i64) -> Transition {
        env.step(&action.to_le_bytes(), &mut [0u8; 24], &mut Info::default())
            .unwrap()
    }

    #[test]
    fn spaces_match_gymnasium() {
        let env = make();
        assert_eq!(env.action_space(), &Space::discrete(3));
        let Space::Box { high, .. } = env.observation_space() else {
            panic!("not a box")
        };
        assert_eq!(high[4], 12.566371f32 as f64);
        assert_eq!(high[5], 28.274334f32 as f64);
    }

    #[test]
    fn reset_draws_float32_within_bounds() {
        let mut env = make();
        for seed in 0..50 {
            env.reset(
                Some(seed),
                &ResetOptions::new(),
                &mut [0u8; 24],
                &mut Info::default(),
            )
            .unwrap();
            for &v in env.state() {
                assert!((-0.1..=0.1).contains(&v));
                assert_eq!(v, v as f32 as f64);
            }
        }
    }

    #[test]
    fn terminates_with_the_tip_above_the_line() {
        let mut env = make();
        // Both links pointing up: the tip is at height 2.
        env.set_state(&[PI - 0.01, 0.0, 0.0, 0.0]).unwrap();
        let t = step(&mut env, 1);
        assert!(t.terminated && t.reward == 0.0);
        env.set_state(&[0.0; 4]).unwrap();
        let t = step(&mut env, 1);
        assert!(!t.terminated && t.reward == -1.0);
        // Hanging still stays still, up to cos(-π/2) not being exactly 0 (as in Gymnasium).
        assert!(
            env.state().iter().all(|v| v.abs() < 1e-15),
            "{:?}",
            env.state()
        );
    }

    #[test]
    fn wraps_angles_and_clips_velocities() {
        let mut env = make();
        env.set_state(&[3.1, -3.1, 100.0, -100.0]).unwrap();
        step(&mut env, 2);
        let s = env.state();
        assert!(s[0].abs() <= PI && s[1].abs() <= PI);
        assert!(s[2].abs() <= MAX_VEL_1 && s[3].abs() <= MAX_VEL_2);
    }

    #[test]
    fn takes_no_options() {
        let mut config = EnvConfig::default();
        config.extra.insert("book_or_nips".into(), json!("nips"));
        let err = Acrobot::new(&config).err().unwrap().to_string();
        assert!(err.contains("unknown option `book_or_nips`"), "{err}");
        assert!(err.contains("valid options are: (none)"), "{err}");
    }
}
