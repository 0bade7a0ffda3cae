//! Offscreen rendering (`render_mode="rgb_array"`): a frame of Ant is not blank and changes
//! when the robot moves, and frames are Gymnasium's frames of the same state. Needs EGL
//! (Mesa's software EGL without a GPU; `make setup` installs it); set
//! `ENVHUB_SKIP_RENDER_TESTS=1` to skip where it cannot be installed.

use envhub_conformance::{floats, gymnasium_version, python_reference};
use envhub_core::{Env, EnvAdapter, EnvConfig, EnvError, Info, ResetOptions};
use envhub_mujoco::Mujoco;
use serde_json::{Value, json};

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
    // `default_camera_config` takes `MjvCamera` fields, `camera_id` -1 (free) or a camera.
    for (key, value, reason) in [
        (
            "default_camera_config",
            json!({"distanc": 3.0}),
            "unknown camera field `distanc`; did you mean `distance`?",
        ),
        (
            "default_camera_config",
            json!({"lookat": [0.0, 1.0]}),
            "`lookat` must be a list of 3 numbers",
        ),
        (
            "default_camera_config",
            json!({"trackbodyid": 1.5}),
            "`trackbodyid` must be an integer",
        ),
        ("default_camera_config", json!(3), "expected a mapping"),
        ("camera_id", json!(-2), "or -1 for the free camera"),
    ] {
        let config = EnvConfig {
            render_mode: Some("rgb_array".into()),
            extra: [(key.to_string(), value)].into(),
            ..EnvConfig::default()
        };
        match Mujoco::default().make("Hopper-v5", &config) {
            Err(EnvError::InvalidOption {
                key: k, reason: r, ..
            }) => {
                assert_eq!(k, key);
                assert!(r.contains(reason), "{r}");
            }
            Err(other) => panic!("{other}"),
            Ok(_) => panic!("{key} accepted"),
        }
    }
    // Gymnasium's `None`s are accepted.
    let config = EnvConfig {
        extra: [
            ("default_camera_config".to_string(), json!(null)),
            ("camera_id".to_string(), json!(null)),
            ("camera_name".to_string(), json!(null)),
        ]
        .into(),
        ..EnvConfig::default()
    };
    Mujoco::default().make("Hopper-v5", &config).unwrap();

    // Without a render mode there is nothing to draw.
    let mut env = Mujoco::default()
        .make_mujoco("Ant-v5", &EnvConfig::default())
        .unwrap();
    assert!(env.render().unwrap().is_none());
}

fn hex_bytes(hex: &str) -> Vec<u8> {
    hex.as_bytes()
        .chunks_exact(2)
        .map(|pair| u8::from_str_radix(std::str::from_utf8(pair).unwrap(), 16).unwrap())
        .collect()
}

/// `tests/python/support/mujoco_render_reference.py` renders Gymnasium's own envs (default cameras,
/// a `default_camera_config` override, a named fixed camera, `camera_id=-1`, several sizes)
/// after a seeded reset and after random actions; the same seed and actions here must give
/// the same frames, byte for byte.
#[test]
fn frames_match_gymnasium() {
    if skip() {
        return;
    }
    let script = "tests/python/support/mujoco_render_reference.py";
    let needs = "gymnasium 1.4 and mujoco 3.17";
    let Some(reference) = python_reference(script, &["gymnasium", "mujoco"], needs) else {
        return;
    };
    gymnasium_version(&reference, "1.4");
    let adapter = Mujoco::default();
    let mut frames = 0;
    for run in reference["runs"].as_array().unwrap() {
        let env_id = run["env_id"].as_str().unwrap();
        let seed = run["seed"].as_u64().unwrap();
        let config = EnvConfig {
            render_mode: Some("rgb_array".into()),
            extra: serde_json::from_value(run["kwargs"].clone()).unwrap(),
            ..EnvConfig::default()
        };
        let at = format!("{env_id} seed {seed} kwargs {}", run["kwargs"]);
        let mut env = adapter.make_mujoco(env_id, &config).unwrap();
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        env.reset(Some(seed), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        for (i, frame) in run["frames"].as_array().unwrap().iter().enumerate() {
            for action in frame["actions"].as_array().unwrap() {
                let action: Vec<u8> = floats(action)
                    .iter()
                    .flat_map(|a| (*a as f32).to_le_bytes())
                    .collect();
                env.step(&action, &mut obs, &mut info).unwrap();
            }
            let (h, w, rgb) = env.render().unwrap().expect("a frame");
            let want = hex_bytes(frame["rgb"].as_str().unwrap());
            let size = |v: &Value| v.as_u64().unwrap() as usize;
            assert_eq!(
                (h, w),
                (size(&frame["height"]), size(&frame["width"])),
                "{at} frame {i}: size"
            );
            assert_eq!(rgb.len(), want.len(), "{at} frame {i}");
            let (mut differ, mut sum, mut max) = (0usize, 0u64, 0u8);
            for (g, w) in rgb.iter().zip(&want) {
                let d = g.abs_diff(*w);
                differ += usize::from(d > 0);
                sum += u64::from(d);
                max = max.max(d);
            }
            let mad = sum as f64 / want.len() as f64;
            println!(
                "{at} frame {i} ({w}x{h}): {differ} of {} bytes differ, mean abs diff {mad:.5}, \
                 max {max}",
                want.len()
            );
            // Both sides draw with the same libmujoco, camera and EGL driver: exactly the same
            // frame (the figures above say how far off one is).
            assert_eq!(
                differ, 0,
                "{at} frame {i}: {differ} bytes differ from Gymnasium's, mean abs diff {mad}, max {max}"
            );
            frames += 1;
        }
    }
    println!("{frames} frames, every one identical to Gymnasium's");
    assert!(frames >= 10, "the reference has too few frames");
}
