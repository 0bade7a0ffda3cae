//! `render_mode="rgb_array"`: `(height, width, 3)` frames that change as the robot moves.

use envhub_core::{EnvAdapter, EnvConfig, Info, ResetOptions};
use envhub_rapier::Rapier;
use serde_json::json;

#[test]
fn frames_have_the_asked_size_and_follow_the_robot() {
    let mut config = EnvConfig {
        render_mode: Some("rgb_array".into()),
        ..EnvConfig::default()
    };
    config.extra.insert("width".into(), json!(96));
    config.extra.insert("height".into(), json!(64));
    for env_id in Rapier.list_envs() {
        let mut env = Rapier.make(&env_id, &config).unwrap();
        assert_eq!(
            env.render_fps(),
            Some(if env_id == "ArmReach-v0" { 50.0 } else { 20.0 })
        );
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        env.reset(Some(1), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        let (h, w, first) = env.render().unwrap().expect("a frame");
        assert_eq!((h, w, first.len()), (64, 96, 64 * 96 * 3), "{env_id}");
        // Not a blank frame: several distinct colours.
        let mut colours: Vec<&[u8]> = first.chunks_exact(3).collect();
        colours.sort();
        colours.dedup();
        assert!(colours.len() > 20, "{env_id}: {} colours", colours.len());
        let action: Vec<u8> = (0..env.action_space().num_elements())
            .flat_map(|i| (if i % 2 == 0 { 1.0f32 } else { -0.7 }).to_le_bytes())
            .collect();
        for _ in 0..15 {
            env.step(&action, &mut obs, &mut info).unwrap();
        }
        let (_, _, later) = env.render().unwrap().unwrap();
        let changed = first
            .chunks_exact(3)
            .zip(later.chunks_exact(3))
            .filter(|(a, b)| a != b)
            .count();
        assert!(changed > 50, "{env_id}: only {changed} pixels changed");
    }
}

#[test]
fn no_render_mode_renders_nothing_and_other_modes_are_refused() {
    let mut env = Rapier.make("ArmReach-v0", &EnvConfig::default()).unwrap();
    assert_eq!(env.render().unwrap(), None);
    let config = EnvConfig {
        render_mode: Some("human".into()),
        ..EnvConfig::default()
    };
    let err = Rapier
        .make("RoverTerrain-v0", &config)
        .err()
        .unwrap()
        .to_string();
    assert!(
        err.contains("render mode `human` is not supported"),
        "{err}"
    );
    assert!(err.contains("rgb_array"), "{err}");
}

/// Writes one frame per task to `$ENVHUB_RAPIER_FRAMES` (a folder) as binary PPM, to look at.
#[test]
fn write_frames_when_asked() {
    let Ok(dir) = std::env::var("ENVHUB_RAPIER_FRAMES") else {
        return;
    };
    let config = EnvConfig {
        render_mode: Some("rgb_array".into()),
        ..EnvConfig::default()
    };
    for env_id in Rapier.list_envs() {
        let mut env = Rapier.make(&env_id, &config).unwrap();
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        env.reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        let action = vec![0u8; env.action_space().byte_len()];
        for _ in 0..10 {
            env.step(&action, &mut obs, &mut info).unwrap();
        }
        let (h, w, rgb) = env.render().unwrap().unwrap();
        let mut ppm = format!("P6\n{w} {h}\n255\n").into_bytes();
        ppm.extend_from_slice(&rgb);
        std::fs::write(format!("{dir}/{env_id}.ppm"), ppm).unwrap();
    }
}
