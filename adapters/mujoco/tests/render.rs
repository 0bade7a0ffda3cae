//! Offscreen rendering (`render_mode="rgb_array"`): a frame of Ant is not blank and changes
//! when the robot moves. Needs EGL (Mesa's software EGL without a GPU; `make setup` installs
//! it); set `ENVHUB_SKIP_RENDER_TESTS=1` to skip where it cannot be installed.

use envhub_core::{Env, EnvAdapter, EnvConfig, EnvError, Info, ResetOptions};
use envhub_mujoco::Mujoco;
use serde_json::json;

fn skip() -> bool {
    let skip = std::env::var("ENVHUB_SKIP_RENDER_TESTS").as_deref() == Ok("1");
    if skip {
        println!("skipped (ENVHUB_SKIP_RENDER_TESTS=1)");
    }
    skip
}

#[test]
fn ant_frames_are_drawn_and_change() {
    if skip() {
        return;
    }
    let config = EnvConfig {
        render_mode: Some("rgb_array".into()),
        extra: [
            ("width".to_string(), json!(160)),
            ("height".to_string(), json!(120)),
        ]
        .into(),
        ..EnvConfig::default()
    };
    let mut env = Mujoco::default().make_mujoco("Ant-v5", &config).unwrap();
    let mut obs = vec![0u8; env.observation_space().byte_len()];
    let mut info = Info::default();
    env.reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
        .unwrap();
    let (h, w, first) = env.render().unwrap().expect("a frame");
    assert_eq!((h, w, first.len()), (120, 160, 120 * 160 * 3));
    let distinct: std::collections::BTreeSet<&[u8]> = first.chunks_exact(3).collect();
    assert!(
        distinct.len() > 20,
        "blank frame: {} colours",
        distinct.len()
    );

    // Move the robot: lift and turn the torso.
    let mut qpos = env.qpos().to_vec();
    qpos[2] += 0.3;
    qpos[3..7].copy_from_slice(&[0.924, 0.0, 0.383, 0.0]);
    let qvel = env.qvel().to_vec();
    env.set_state(&qpos, &qvel).unwrap();
    let (_, _, moved) = env.render().unwrap().unwrap();
    let changed = first
        .iter()
        .zip(&moved)
        .filter(|(a, b)| a.abs_diff(**b) > 8)
        .count();
    assert!(changed > 200, "only {changed} bytes changed");
}

#[test]
fn render_options_are_checked() {
    let mut config = EnvConfig {
        render_mode: Some("human".into()),
        ..EnvConfig::default()
    };
    let err = Mujoco::default()
        .make("Ant-v5", &config)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("render mode `human` is not supported"),
        "{err}"
    );

    config.render_mode = Some("rgb_array".into());
    config.extra.insert("camera_name".into(), json!("nope"));
    let mut env = Mujoco::default().make_mujoco("Ant-v5", &config).unwrap();
    let mut obs = vec![0u8; env.observation_space().byte_len()];
    env.reset(
        Some(0),
        &ResetOptions::new(),
        &mut obs,
        &mut Info::default(),
    )
    .unwrap();
    match env.render() {
        Err(EnvError::InvalidOption { key, reason, .. }) => {
            assert_eq!(key, "camera_name");
            assert!(reason.contains("no camera `nope`"), "{reason}");
        }
        other => panic!("{other:?}"),
    }
    // Without a render mode there is nothing to draw.
    let mut env = Mujoco::default()
        .make_mujoco("Ant-v5", &EnvConfig::default())
        .unwrap();
    assert!(env.render().unwrap().is_none());
}
