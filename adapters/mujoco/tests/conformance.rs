//! Conformance of every env of the `mujoco` adapter (and a `custom_mjcf` model) to the `Env`
//! contract: the suite shared with the other adapters (`envhub_conformance::check_env`), then
//! MuJoCo's reset options and env options.

use envhub_conformance::check_env;
use envhub_core::{Env, EnvAdapter, EnvConfig, Info, ResetOptions};
use envhub_mujoco::{CustomMjcf, Mujoco};

#[test]
fn every_env_conforms() {
    let adapter = Mujoco::default();
    // Short episodes so that every env ends some within the rollout.
    let config = EnvConfig {
        max_episode_steps: Some(120),
        ..EnvConfig::default()
    };
    for env_id in adapter.list_envs() {
        check_env(&adapter, &env_id, &config, 300);
    }
}

#[test]
fn custom_model_conforms() {
    let config = EnvConfig {
        asset_path: Some(crate::custom_mjcf::planar_walker()),
        max_episode_steps: Some(100),
        ..EnvConfig::default()
    };
    check_env(&CustomMjcf::default(), "PlanarWalker-v0", &config, 250);
}

#[test]
fn reset_options_start_from_the_given_state() {
    let adapter = Mujoco::default();
    let mut env = adapter
        .make_mujoco("Hopper-v5", &EnvConfig::default())
        .unwrap();
    let mut obs = vec![0u8; env.observation_space().byte_len()];
    let mut info = Info::default();
    let qpos = vec![0.5, 1.3, 0.01, -0.02, 0.03, -0.04];
    let options: ResetOptions = [("qpos".to_string(), serde_json::json!(qpos))].into();
    env.reset(Some(0), &options, &mut obs, &mut info).unwrap();
    assert_eq!(env.qpos(), qpos.as_slice());
    assert_eq!(
        info.get("x_position"),
        Some(&envhub_core::InfoValue::Float(0.5))
    );
    // qvel was still drawn, as in a plain reset with that seed.
    let mut plain = adapter
        .make_mujoco("Hopper-v5", &EnvConfig::default())
        .unwrap();
    plain
        .reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
        .unwrap();
    assert_eq!(env.qvel(), plain.qvel());

    for (options, want) in [
        (serde_json::json!({"qpos": [1.0]}), "`qpos` needs 6 values"),
        (serde_json::json!({"qvel": "fast"}), "`qvel` must be a list"),
        (serde_json::json!({"qpso": []}), "did you mean `qpos`?"),
    ] {
        let options: ResetOptions = serde_json::from_value(options).unwrap();
        let err = env
            .reset(None, &options, &mut obs, &mut info)
            .unwrap_err()
            .to_string();
        assert!(err.contains(want), "{err}");
    }
}

#[test]
fn options_are_validated() {
    let adapter = Mujoco::default();
    let mut config = EnvConfig::default();
    config
        .extra
        .insert("ctrl_cost_weigth".into(), serde_json::json!(0.1));
    let err = adapter.make("Ant-v5", &config).err().unwrap().to_string();
    assert!(err.contains("did you mean `ctrl_cost_weight`"), "{err}");

    let mut config = EnvConfig::default();
    config
        .extra
        .insert("healthy_z_range".into(), serde_json::json!([0.2]));
    let err = adapter.make("Ant-v5", &config).err().unwrap().to_string();
    assert!(err.contains("expected `[low, high]`"), "{err}");

    let spec = adapter.spec("Ant-v5", &EnvConfig::default()).unwrap();
    assert_eq!(spec.observation_space.shape(), Some(vec![105]));
    assert_eq!(spec.action_space.shape(), Some(vec![8]));
    assert_eq!(spec.max_episode_steps, Some(1000));
    let mut config = EnvConfig::default();
    config.extra.insert(
        "include_cfrc_ext_in_observation".into(),
        serde_json::json!(false),
    );
    let spec = adapter.spec("Ant-v5", &config).unwrap();
    assert_eq!(spec.observation_space.shape(), Some(vec![27]));
    let err = adapter
        .make("Ant-v4", &EnvConfig::default())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("did you mean `Ant-v5`"), "{err}");
}
