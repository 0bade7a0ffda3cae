//! Gymnasium's reset `options` for classic control: `low`/`high` bounds or `x_init`/`y_init`.
//!
//! Gymnasium silently ignores keys it does not read; here an unknown key is an error that names
//! the valid ones, so a typo (`{"hi": 0.1}`) cannot go unnoticed.

use envhub_core::{EnvError, ResetOptions};

fn invalid(env_id: &str, reason: String) -> EnvError {
    EnvError::InvalidReset {
        env_id: env_id.to_string(),
        reason,
    }
}

/// Rejects keys outside `known`, naming the valid ones.
pub(crate) fn check_keys(
    env_id: &str,
    options: &ResetOptions,
    known: &[&str],
) -> Result<(), EnvError> {
    for key in options.keys() {
        if !known.contains(&key.as_str()) {
            let closest = envhub_core::closest(key, known.iter().copied(), 1);
            let hint = closest
                .first()
                .map(|c| format!("; did you mean `{c}`?"))
                .unwrap_or_default();
            let valid: Vec<String> = known.iter().map(|k| format!("`{k}`")).collect();
            return Err(invalid(
                env_id,
                format!(
                    "unknown option `{key}`{hint}\nhint: valid reset options are {}",
                    valid.join(", ")
                ),
            ));
        }
    }
    Ok(())
}

/// The number under `key`, or `default` when absent (Gymnasium's `verify_number_and_cast`,
/// restricted to JSON numbers).
pub(crate) fn number(
    env_id: &str,
    options: &ResetOptions,
    key: &str,
    default: f64,
) -> Result<f64, EnvError> {
    match options.get(key) {
        None => Ok(default),
        Some(v) => v
            .as_f64()
            .ok_or_else(|| invalid(env_id, format!("`{key}` must be a number, got `{v}`"))),
    }
}

/// Gymnasium's `maybe_parse_reset_bounds`: `low` and `high`, each defaulted, with
/// `low <= high`. Any other key is an error.
pub(crate) fn bounds(
    env_id: &str,
    options: &ResetOptions,
    default_low: f64,
    default_high: f64,
) -> Result<(f64, f64), EnvError> {
    if options.is_empty() {
        return Ok((default_low, default_high));
    }
    check_keys(env_id, options, &["low", "high"])?;
    let low = number(env_id, options, "low", default_low)?;
    let high = number(env_id, options, "high", default_high)?;
    if low > high {
        return Err(invalid(
            env_id,
            format!("`low` ({low}) must not be greater than `high` ({high})"),
        ));
    }
    Ok((low, high))
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn opts(pairs: &[(&str, serde_json::Value)]) -> ResetOptions {
        pairs
            .iter()
            .map(|(k, v)| (k.to_string(), v.clone()))
            .collect()
    }

    #[test]
    fn defaults_and_overrides() {
        assert_eq!(bounds("e", &opts(&[]), -0.1, 0.1).unwrap(), (-0.1, 0.1));
        assert_eq!(
            bounds("e", &opts(&[("high", json!(0.3))]), -0.1, 0.1).unwrap(),
            (-0.1, 0.3)
        );
        assert_eq!(
            bounds(
                "e",
                &opts(&[("low", json!(-1)), ("high", json!(2))]),
                0.0,
                0.0
            )
            .unwrap(),
            (-1.0, 2.0)
        );
    }

    #[test]
    fn unknown_key_names_the_valid_ones() {
        let err = bounds("CartPole-v1", &opts(&[("hig", json!(0.1))]), -0.05, 0.05)
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown option `hig`"), "{err}");
        assert!(err.contains("did you mean `high`?"), "{err}");
        assert!(
            err.contains("valid reset options are `low`, `high`"),
            "{err}"
        );
    }

    #[test]
    fn wrong_type_and_inverted_bounds() {
        let err = bounds("e", &opts(&[("low", json!("a"))]), -0.05, 0.05)
            .unwrap_err()
            .to_string();
        assert!(err.contains("`low` must be a number, got `\"a\"`"), "{err}");
        let err = bounds("e", &opts(&[("low", json!(0.2))]), -0.05, 0.05)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("`low` (0.2) must not be greater than `high` (0.05)"),
            "{err}"
        );
    }
}
