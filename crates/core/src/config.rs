//! `EnvConfig`: how to create an env, and the hub options that shape a session.

use crate::{BoundsCheck, EnvError};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// When a vector env resets a finished sub-env, as in Gymnasium 1.x.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AutoresetMode {
    /// The step after a done returns the reset observation (Gymnasium's default).
    #[default]
    NextStep,
    /// The done step itself returns the reset observation; the final one goes in info.
    SameStep,
    /// Never reset automatically; the caller resets selected envs with a mask.
    Disabled,
}

impl std::str::FromStr for AutoresetMode {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_lowercase().replace('-', "_").as_str() {
            "next_step" => Ok(AutoresetMode::NextStep),
            "same_step" => Ok(AutoresetMode::SameStep),
            "disabled" => Ok(AutoresetMode::Disabled),
            _ => Err(format!(
                "unknown autoreset mode `{s}`; valid modes are `next_step`, `same_step`, `disabled`"
            )),
        }
    }
}

/// How to create an env. Everything has a default; unknown fields are an error.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EnvConfig {
    /// `None`, `"rgb_array"`, ...
    pub render_mode: Option<String>,
    /// Seed of the first reset (env `i` of a vector env gets `seed + i`).
    pub seed: Option<u64>,
    /// Truncate after this many steps. `None` or 0 keep the env's own default limit.
    pub max_episode_steps: Option<u32>,
    /// Number of env instances in the session. The config each worker is started with is
    /// the exception: there it is that worker's envs (`WorkerJob::worker_envs`), what its
    /// adapter builds (`make_vec(num_envs=config.num_envs)`).
    pub num_envs: usize,
    /// A model file that overrides the env's default asset.
    pub asset_path: Option<PathBuf>,
    /// Framework-specific options (the registry entry's `kwargs` merged with the caller's).
    pub extra: BTreeMap<String, serde_json::Value>,
    /// Worker processes to spread the envs over (`None`: one per core, at most one per env).
    pub workers: Option<usize>,
    /// Autoreset behaviour of vector envs.
    pub autoreset_mode: AutoresetMode,
    /// Refuse continuous actions outside the action space's `Box` bounds. Off by default:
    /// they reach the env unchanged, as Gymnasium passes them, and the env clips them as it
    /// was written to (Pendulum clips the torque, MuJoCo clamps `ctrl` to `ctrlrange` while
    /// the control cost sees the action as given). NaN and infinite actions, discrete actions
    /// out of range, and actions of the wrong shape or dtype are an error either way.
    pub strict_actions: bool,
}

impl Default for EnvConfig {
    fn default() -> Self {
        EnvConfig {
            render_mode: None,
            seed: None,
            max_episode_steps: None,
            num_envs: 1,
            asset_path: None,
            extra: BTreeMap::new(),
            workers: None,
            autoreset_mode: AutoresetMode::NextStep,
            strict_actions: false,
        }
    }
}

impl EnvConfig {
    /// How actions are held to the action space's bounds (see [`EnvConfig::strict_actions`]).
    pub fn action_bounds(&self) -> BoundsCheck {
        if self.strict_actions {
            BoundsCheck::Strict
        } else {
            BoundsCheck::FiniteFloats
        }
    }

    /// The episode limit to apply: the caller's if set and non-zero, else the env's default.
    pub fn episode_limit(&self, env_default: Option<u32>) -> Option<u32> {
        match self.max_episode_steps {
            Some(0) | None => env_default,
            Some(n) => Some(n),
        }
    }

    /// Reads the `extra` options an env takes, rejecting unknown keys with the valid ones.
    pub fn extra_keys<'a>(
        &'a self,
        env_id: &str,
        known: &[&str],
    ) -> Result<ExtraKeys<'a>, EnvError> {
        for key in self.extra.keys() {
            if !known.contains(&key.as_str()) {
                return Err(EnvError::UnknownOption {
                    env_id: env_id.to_string(),
                    key: key.clone(),
                    closest: crate::closest(key, known.iter().copied(), 2),
                    known: known.iter().map(|k| k.to_string()).collect(),
                });
            }
        }
        Ok(ExtraKeys {
            env_id: env_id.to_string(),
            extra: &self.extra,
        })
    }
}

/// Typed access to validated `extra` options.
pub struct ExtraKeys<'a> {
    env_id: String,
    extra: &'a BTreeMap<String, serde_json::Value>,
}

impl ExtraKeys<'_> {
    fn invalid(&self, key: &str, reason: String) -> EnvError {
        EnvError::InvalidOption {
            env_id: self.env_id.clone(),
            key: key.to_string(),
            reason,
        }
    }

    /// A number option, or `default` when absent.
    pub fn f64(&self, key: &str, default: f64) -> Result<f64, EnvError> {
        match self.extra.get(key) {
            None => Ok(default),
            Some(v) => v
                .as_f64()
                .filter(|x| x.is_finite())
                .ok_or_else(|| self.invalid(key, format!("expected a finite number, got `{v}`"))),
        }
    }

    /// A boolean option, or `default` when absent.
    pub fn bool(&self, key: &str, default: bool) -> Result<bool, EnvError> {
        match self.extra.get(key) {
            None => Ok(default),
            Some(v) => v
                .as_bool()
                .ok_or_else(|| self.invalid(key, format!("expected `true` or `false`, got `{v}`"))),
        }
    }

    /// A non-negative integer option, or `default` when absent.
    pub fn u64(&self, key: &str, default: u64) -> Result<u64, EnvError> {
        match self.extra.get(key) {
            None => Ok(default),
            Some(v) => v.as_u64().ok_or_else(|| {
                self.invalid(key, format!("expected a non-negative integer, got `{v}`"))
            }),
        }
    }

    /// A string option, or `None` when absent.
    pub fn str(&self, key: &str) -> Result<Option<&str>, EnvError> {
        match self.extra.get(key) {
            None => Ok(None),
            Some(v) => v
                .as_str()
                .map(Some)
                .ok_or_else(|| self.invalid(key, format!("expected a string, got `{v}`"))),
        }
    }

    /// A `[low, high]` option (a list of two numbers; `"inf"` and `"-inf"` stand for the
    /// infinities JSON lacks), or `default` when absent.
    pub fn range(&self, key: &str, default: (f64, f64)) -> Result<(f64, f64), EnvError> {
        let Some(v) = self.extra.get(key) else {
            return Ok(default);
        };
        let bound = |b: &serde_json::Value| match b {
            serde_json::Value::String(s) => match s.as_str() {
                "inf" | "+inf" => Some(f64::INFINITY),
                "-inf" => Some(f64::NEG_INFINITY),
                _ => None,
            },
            b => b.as_f64(),
        };
        match v.as_array().map(Vec::as_slice) {
            Some([lo, hi]) => match (bound(lo), bound(hi)) {
                (Some(lo), Some(hi)) => Ok((lo, hi)),
                _ => Err(self.invalid(key, format!("expected `[low, high]` numbers, got `{v}`"))),
            },
            _ => Err(self.invalid(key, format!("expected `[low, high]`, got `{v}`"))),
        }
    }

    /// The raw value of `key`, for options of a shape the typed accessors do not cover.
    pub fn value(&self, key: &str) -> Option<&serde_json::Value> {
        self.extra.get(key)
    }

    /// An error for `key` with the given reason, for checks the env does itself.
    pub fn error(&self, key: &str, reason: impl Into<String>) -> EnvError {
        self.invalid(key, reason.into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn unknown_extra_names_the_valid_ones() {
        let mut cfg = EnvConfig::default();
        cfg.extra.insert("gravty".into(), json!(9.8));
        let err = cfg
            .extra_keys("Pendulum-v1", &["g"])
            .err()
            .unwrap()
            .to_string();
        assert!(err.contains("unknown option `gravty`"), "{err}");
        assert!(err.contains("valid options are: g"), "{err}");
    }

    #[test]
    fn typed_options() {
        let mut cfg = EnvConfig::default();
        cfg.extra.insert("g".into(), json!(9.81));
        cfg.extra.insert("sutton_barto_reward".into(), json!("yes"));
        let keys = cfg.extra_keys("x", &["g", "sutton_barto_reward"]).unwrap();
        assert_eq!(keys.f64("g", 10.0).unwrap(), 9.81);
        assert!(keys.bool("sutton_barto_reward", false).is_err());
    }

    #[test]
    fn zero_limit_means_default() {
        let mut cfg = EnvConfig::default();
        assert_eq!(cfg.episode_limit(Some(500)), Some(500));
        cfg.max_episode_steps = Some(0);
        assert_eq!(cfg.episode_limit(Some(500)), Some(500));
        cfg.max_episode_steps = Some(20);
        assert_eq!(cfg.episode_limit(Some(500)), Some(20));
    }

    #[test]
    fn rejects_unknown_config_fields() {
        let err = serde_json::from_str::<EnvConfig>(r#"{"num_env": 3}"#).unwrap_err();
        assert!(err.to_string().contains("unknown field `num_env`"), "{err}");
    }

    #[test]
    fn strict_actions_is_off_unless_asked_for() {
        let cfg: EnvConfig = serde_json::from_str("{}").unwrap();
        assert!(!cfg.strict_actions);
        assert_eq!(cfg.action_bounds(), BoundsCheck::FiniteFloats);
        let cfg: EnvConfig = serde_json::from_str(r#"{"strict_actions": true}"#).unwrap();
        assert_eq!(cfg.action_bounds(), BoundsCheck::Strict);
        let err = serde_json::from_str::<EnvConfig>(r#"{"strict_action": true}"#).unwrap_err();
        assert!(err.to_string().contains("strict_actions"), "{err}");
    }
}
