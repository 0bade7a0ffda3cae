//! `ClassicEnv`: an `Env` whose whole simulator state is a few numbers that can be read and set.

use envhub_core::{Env, EnvConfig, EnvError};

/// A classic-control env. Its full internal state is a short vector of `f64`, the same numbers
/// as Gymnasium's `env.unwrapped.state`, so a state can be saved, restored, or copied from
/// Gymnasium to compare the two implementations step by step.
pub trait ClassicEnv: Env {
    /// The Gymnasium id (`CartPole-v1`).
    fn env_id(&self) -> &'static str;

    /// Names of the state variables, in the order `state` lists them.
    fn state_names(&self) -> &'static [&'static str];

    /// The current state, in the order of `state_names`; empty before the first `reset` or
    /// `set_state`.
    fn state(&self) -> &[f64];

    /// Replaces the state, as assigning a float64 array to `env.unwrapped.state` does in
    /// Gymnasium; the next `step` starts from it. The values are not range-checked (Gymnasium
    /// does not check them either). Fails only on a wrong number of values.
    fn set_state(&mut self, state: &[f64]) -> Result<(), EnvError>;
}

/// `state` as an array of `N`, or an error naming the expected variables.
pub(crate) fn state_array<const N: usize>(
    env_id: &str,
    names: &[&str],
    state: &[f64],
) -> Result<[f64; N], EnvError> {
    state.try_into().map_err(|_| EnvError::InvalidReset {
        env_id: env_id.to_string(),
        reason: format!(
            "`set_state` expects {N} values ({}), got {}",
            names.join(", "),
            state.len()
        ),
    })
}

/// The error of `step` before any `reset`.
pub(crate) fn not_reset(env_id: &str) -> EnvError {
    EnvError::Simulator {
        env_id: env_id.to_string(),
        reason: "`step` called before `reset`\nhint: call `reset` (or `set_state`) first".into(),
    }
}

/// Classic-control envs do not render: any `render_mode` is refused rather than ignored.
pub(crate) fn check_render_mode(env_id: &str, config: &EnvConfig) -> Result<(), EnvError> {
    match &config.render_mode {
        None => Ok(()),
        Some(mode) => Err(EnvError::RenderMode {
            env_id: env_id.to_string(),
            mode: mode.clone(),
            supported: vec!["(none: native classic-control envs do not render)".into()],
        }),
    }
}

/// One env of the adapter: its id, Gymnasium's registered time limit, its `extra` options and
/// its constructor. Each env file defines one as `ENTRY`.
pub(crate) struct EnvEntry {
    /// The Gymnasium id.
    pub(crate) id: &'static str,
    /// `max_episode_steps` as Gymnasium registers the id.
    pub(crate) max_episode_steps: u32,
    /// The keys the env takes in `extra`.
    pub(crate) options: &'static [&'static str],
    /// Creates the env, validating `config`.
    pub(crate) make: fn(&EnvConfig) -> Result<Box<dyn ClassicEnv>, EnvError>,
}

/// Declares a classic env's trait impls once, from the env file's `ID`, `STATE_NAMES` and
/// `RENDER_FPS` and its struct's `observation_space`, `action_space` and `state` fields:
/// `classic_env!(CartPole { fn reset(..) {..} fn step(..) {..} })` emits `impl Env` (the
/// spaces, the fps and the given `reset`/`step`) and `impl ClassicEnv`. An env whose
/// `set_state` must also reset something of its own adds `on_set_state(env) { .. }`.
macro_rules! classic_env {
    ($ty:ident { $($body:tt)* }) => {
        classic_env!($ty { $($body)* } on_set_state(_env) {});
    };
    ($ty:ident { $($body:tt)* } on_set_state($env:ident) $hook:block) => {
        impl envhub_core::Env for $ty {
            fn observation_space(&self) -> &envhub_core::Space {
                &self.observation_space
            }

            fn action_space(&self) -> &envhub_core::Space {
                &self.action_space
            }

            fn render_fps(&self) -> Option<f64> {
                Some(RENDER_FPS)
            }

            $($body)*
        }

        impl $crate::classic_env::ClassicEnv for $ty {
            fn env_id(&self) -> &'static str {
                ID
            }

            fn state_names(&self) -> &'static [&'static str] {
                STATE_NAMES
            }

            fn state(&self) -> &[f64] {
                self.state.as_ref().map_or(&[], |s| s.as_slice())
            }

            fn set_state(&mut self, state: &[f64]) -> Result<(), envhub_core::EnvError> {
                self.state = Some($crate::classic_env::state_array(ID, STATE_NAMES, state)?);
                let $env = self;
                $hook
                Ok(())
            }
        }
    };
}
pub(crate) use classic_env;
