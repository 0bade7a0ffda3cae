//! Bad input: unknown ids and options name the valid ones; bad values say what is valid.

use envhub_core::{EnvAdapter, EnvConfig};
use envhub_rapier::Rapier;
use serde_json::json;

fn make_err(env_id: &str, key: &str, value: serde_json::Value) -> String {
    let mut config = EnvConfig::default();
    config.extra.insert(key.into(), value);
    Rapier.make(env_id, &config).err().unwrap().to_string()
}

#[test]
fn unknown_option_lists_the_valid_ones() {
    let err = make_err("RoverTerrain-v0", "terrain_roughnes", json!(2.0));
    assert!(err.contains("unknown option `terrain_roughnes`"), "{err}");
    assert!(err.contains("did you mean `terrain_roughness`"), "{err}");
    assert!(
        err.contains("valid options are: terrain_roughness, goal_distance_range"),
        "{err}"
    );
    assert!(err.contains("width, height"), "{err}");
    let spec = Rapier.spec("ArmPush-v0", &EnvConfig::default()).unwrap();
    assert_eq!(
        spec.options,
        [
            "reward_near_weight",
            "reward_dist_weight",
            "reward_control_weight",
            "width",
            "height"
        ]
    );
}

#[test]
fn invalid_values_say_what_is_valid() {
    let err = make_err("RoverTerrain-v0", "terrain_roughness", json!(7));
    assert!(err.contains("expected 0 (flat) to 3, got 7"), "{err}");
    let err = make_err("AntRun-v0", "healthy_z_range", json!([0.2]));
    assert!(err.contains("invalid option `healthy_z_range`"), "{err}");
    let err = make_err("ArmReach-v0", "width", json!(0));
    assert!(err.contains("expected 1 to 4096 pixels, got 0"), "{err}");
}

#[test]
fn unknown_env_suggests_the_closest() {
    let err = Rapier
        .make("AntRun-v1", &EnvConfig::default())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("has no env `AntRun-v1`"), "{err}");
    assert!(err.contains("did you mean `AntRun-v0`"), "{err}");
}
