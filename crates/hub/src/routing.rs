//! Routing: which adapter runs a registry entry, and with which config.

use crate::adapters::AdapterInfo;
use envhub_catalog::EnvEntry;
use envhub_core::{Availability, EnvConfig, FRAMEWORKS, canonical_framework};
use envhub_protocol::HubError;
use envhub_protocol::Route;

/// Merges the entry's settings under the caller's: the caller's `extra` keys override the
/// entry's `kwargs`; the caller's `max_episode_steps` and `asset_path` override the entry's.
pub fn merge_config(entry: &EnvEntry, user: &EnvConfig) -> EnvConfig {
    let mut config = user.clone();
    let mut extra = entry.kwargs.clone();
    extra.extend(user.extra.clone());
    config.extra = extra;
    if matches!(config.max_episode_steps, None | Some(0)) {
        config.max_episode_steps = entry.max_episode_steps.or(config.max_episode_steps);
    }
    if config.asset_path.is_none() {
        config.asset_path = entry.asset_path.clone();
    }
    config
}

fn check_available(a: &AdapterInfo) -> Result<(), HubError> {
    match &a.availability {
        Availability::Available => Ok(()),
        Availability::Unavailable { reason, hint } => Err(HubError::Unavailable {
            adapter: a.name.clone(),
            reason: reason.clone(),
            hint: hint.clone(),
        }),
    }
}

/// Whether `adapter` draws `render_mode` (no mode: yes; an adapter that declares no modes
/// forwards the mode to its framework, which decides).
pub(crate) fn renders(adapter: &AdapterInfo, render_mode: Option<&str>) -> bool {
    match (render_mode, &adapter.render_modes) {
        (Some(mode), Some(modes)) => modes.iter().any(|m| m == mode),
        _ => true,
    }
}

/// Picks the adapter for `entry`: the pinned one if the entry names one; else an available
/// adapter of its framework that implements the env id natively and draws the config's
/// render mode; else a generic adapter of the framework that forwards any id (Gymnasium's
/// own env, the same dynamics as the native one, when only it renders); else the native
/// adapter, which refuses the render mode itself with the modes it has.
pub fn route(
    entry: &EnvEntry,
    adapters: &[AdapterInfo],
    user: &EnvConfig,
) -> Result<Route, HubError> {
    let config = merge_config(entry, user);
    let done = |a: &AdapterInfo| {
        Ok(Route {
            adapter: a.name.clone(),
            env_id: entry.env_id.clone(),
            config: config.clone(),
            python: None,
        })
    };
    if let Some(pinned) = &entry.adapter {
        let a = adapters
            .iter()
            .find(|a| &a.name == pinned)
            .ok_or_else(|| HubError::NoAdapter {
                env_id: entry.env_id.clone(),
                framework: entry.framework.clone(),
                detail: format!(
                    ": entry `{}` pins adapter `{pinned}`, which does not exist",
                    entry.id
                ),
                hint: format!("adapters: {}", names(adapters.iter())),
            })?;
        check_available(a)?;
        return done(a);
    }
    let framework = canonical_framework(&entry.framework)
        .map_or_else(|| entry.framework.to_lowercase(), str::to_string);
    let of_framework: Vec<&AdapterInfo> = adapters
        .iter()
        .filter(|a| a.frameworks.contains(&framework))
        .collect();
    if of_framework.is_empty() {
        let mut known: Vec<String> = FRAMEWORKS.iter().map(|f| f.name.to_string()).collect();
        known.extend(adapters.iter().flat_map(|a| a.frameworks.iter().cloned()));
        known.sort();
        known.dedup();
        return Err(HubError::NoAdapter {
            env_id: entry.env_id.clone(),
            framework: entry.framework.clone(),
            detail: format!(
                ": unknown framework `{}`{}",
                entry.framework,
                unloadable(adapters)
            ),
            hint: format!("known frameworks: {}", known.join(", ")),
        });
    }
    let native: Vec<&&AdapterInfo> = of_framework
        .iter()
        .filter(|a| a.envs.contains(&entry.env_id))
        .collect();
    let mode = config.render_mode.as_deref();
    let usable = |a: &AdapterInfo| a.availability.is_available() && renders(a, mode);
    if let Some(a) = native.iter().find(|a| usable(a)) {
        return done(a);
    }
    let generic: Vec<&&AdapterInfo> = of_framework.iter().filter(|a| a.envs.is_empty()).collect();
    if let Some(a) = generic.iter().find(|a| usable(a)) {
        return done(a);
    }
    if let Some(a) = native.iter().find(|a| a.availability.is_available()) {
        // It cannot draw the mode, and no generic adapter that could is available.
        if let (Some(mode), Some(g)) = (mode, generic.first())
            && let Availability::Unavailable { reason, hint } = &g.availability
        {
            return Err(HubError::Unavailable {
                adapter: g.name.clone(),
                reason: format!(
                    "`{}` runs `{}` but does not draw render mode `{mode}`, which `{}` would: {reason}",
                    a.name, entry.env_id, g.name
                ),
                hint: format!("{hint}; or make it without a render mode"),
            });
        }
        return done(a);
    }
    if let Some(a) = native.first().or(generic.first()) {
        check_available(a)?;
    }
    let provided: Vec<String> = of_framework
        .iter()
        .map(|a| format!("`{}` runs {}", a.name, a.envs.join(", ")))
        .collect();
    Err(HubError::NoAdapter {
        env_id: entry.env_id.clone(),
        framework: framework.clone(),
        detail: format!(": {}", provided.join("; ")),
        hint: "`envhub adapters --all` lists every adapter and what it runs".to_string(),
    })
}

/// Why each adapter that failed to load did (a user adapter that cannot be imported), as
/// `; reason` clauses: such an adapter cannot say which frameworks it serves, so it is the
/// likely cause of an unknown framework.
fn unloadable(adapters: &[AdapterInfo]) -> String {
    adapters
        .iter()
        .filter(|a| a.frameworks.is_empty())
        .filter_map(|a| match &a.availability {
            Availability::Unavailable { reason, .. } => Some(format!("; {reason}")),
            Availability::Available => None,
        })
        .collect()
}

fn names<'a>(adapters: impl Iterator<Item = &'a AdapterInfo>) -> String {
    adapters
        .map(|a| a.name.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn adapter(name: &str, frameworks: &[&str], envs: &[&str], available: bool) -> AdapterInfo {
        AdapterInfo {
            name: name.into(),
            frameworks: frameworks.iter().map(|s| s.to_string()).collect(),
            requires: vec![],
            description: String::new(),
            availability: if available {
                Availability::Available
            } else {
                Availability::Unavailable {
                    reason: "missing".into(),
                    hint: "install it".into(),
                }
            },
            envs: envs.iter().map(|s| s.to_string()).collect(),
            host: Default::default(),
            render_modes: None,
        }
    }

    fn drawing(mut a: AdapterInfo, modes: &[&str]) -> AdapterInfo {
        a.render_modes = Some(modes.iter().map(|s| s.to_string()).collect());
        a
    }

    #[test]
    fn a_render_mode_the_native_adapter_lacks_goes_to_the_generic_one() {
        let classic = drawing(
            adapter("classic_control", &["gymnasium"], &["CartPole-v1"], true),
            &[],
        );
        let mujoco = drawing(
            adapter("mujoco", &["gymnasium"], &["Ant-v5"], true),
            &["rgb_array"],
        );
        let gymnasium = adapter("gymnasium", &["gymnasium"], &[], true);
        let adapters = [classic.clone(), mujoco, gymnasium.clone()];
        let drawn = EnvConfig {
            render_mode: Some("rgb_array".into()),
            ..EnvConfig::default()
        };
        let via = |e: &EnvEntry, adapters: &[AdapterInfo], c: &EnvConfig| {
            route(e, adapters, c).map(|r| r.adapter)
        };
        let cartpole = entry("gym", "CartPole-v1");
        assert_eq!(via(&cartpole, &adapters, &drawn).unwrap(), "gymnasium");
        assert_eq!(
            via(&cartpole, &adapters, &EnvConfig::default()).unwrap(),
            "classic_control"
        );
        // A native adapter that draws the mode keeps the entry.
        assert_eq!(
            via(&entry("gym", "Ant-v5"), &adapters, &drawn).unwrap(),
            "mujoco"
        );
        // A pin is kept: the adapter refuses the mode itself.
        let mut pinned = cartpole.clone();
        pinned.adapter = Some("classic_control".into());
        assert_eq!(via(&pinned, &adapters, &drawn).unwrap(), "classic_control");
        // Without a generic adapter, the native one refuses the mode itself; with an
        // unavailable one, the error says what would draw it and why it cannot.
        assert_eq!(
            via(&cartpole, std::slice::from_ref(&classic), &drawn).unwrap(),
            "classic_control"
        );
        let missing = adapter("gymnasium", &["gymnasium"], &[], false);
        let err = route(&cartpole, &[classic, missing], &drawn)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("`classic_control` runs `CartPole-v1` but does not draw render mode `rgb_array`, which `gymnasium` would: missing")
                && err.contains("hint: install it; or make it without a render mode"),
            "{err}"
        );
    }

    fn entry(framework: &str, env_id: &str) -> EnvEntry {
        serde_norway::from_str(&format!(
            "{{id: x, name: X, framework: {framework}, env_id: {env_id}, robot_type: custom, env_type: floor, kwargs: {{a: 1}}, max_episode_steps: 50}}"
        ))
        .unwrap()
    }

    #[test]
    fn native_before_generic_and_pins_win() {
        let adapters = [
            adapter("gymnasium", &["gymnasium"], &[], true),
            adapter("classic_control", &["gymnasium"], &["CartPole-v1"], true),
        ];
        let r = route(
            &entry("gym", "CartPole-v1"),
            &adapters,
            &EnvConfig::default(),
        )
        .unwrap();
        assert_eq!(r.adapter, "classic_control");
        let r = route(
            &entry("gymnasium", "Hopper-v5"),
            &adapters,
            &EnvConfig::default(),
        )
        .unwrap();
        assert_eq!(r.adapter, "gymnasium");
        let mut pinned = entry("gymnasium", "CartPole-v1");
        pinned.adapter = Some("gymnasium".into());
        assert_eq!(
            route(&pinned, &adapters, &EnvConfig::default())
                .unwrap()
                .adapter,
            "gymnasium"
        );
    }

    #[test]
    fn explains_unknown_framework_and_unavailable() {
        let adapters = [adapter("mujoco", &["gymnasium"], &["Ant-v5"], false)];
        let err = route(&entry("bullet", "X"), &adapters, &EnvConfig::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("unknown framework `bullet`") && err.contains("known frameworks"),
            "{err}"
        );
        let err = route(
            &entry("gymnasium", "Ant-v5"),
            &adapters,
            &EnvConfig::default(),
        )
        .unwrap_err()
        .to_string();
        assert!(
            err.contains("unavailable") && err.contains("install it"),
            "{err}"
        );
    }

    #[test]
    fn unknown_framework_names_adapters_that_failed_to_load() {
        let mut broken = adapter("my_sim:Adapter", &[], &[], false);
        broken.availability = Availability::Unavailable {
            reason: "cannot import `my_sim:Adapter`: ModuleNotFoundError".into(),
            hint: "check the import path".into(),
        };
        let adapters = [adapter("gymnasium", &["gymnasium"], &[], true), broken];
        let err = route(&entry("mysim", "X"), &adapters, &EnvConfig::default())
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("unknown framework `mysim`; cannot import `my_sim:Adapter`"),
            "{err}"
        );
    }

    #[test]
    fn caller_overrides_entry_settings() {
        let mut user = EnvConfig::default();
        user.extra.insert("a".into(), serde_json::json!(2));
        let c = merge_config(&entry("gymnasium", "X"), &user);
        assert_eq!(c.extra["a"], serde_json::json!(2));
        assert_eq!(c.max_episode_steps, Some(50));
        user.max_episode_steps = Some(7);
        assert_eq!(
            merge_config(&entry("gymnasium", "X"), &user).max_episode_steps,
            Some(7)
        );
    }
}
