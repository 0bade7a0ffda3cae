//! Frames rendered in a worker reach the client (`render_mode = "rgb_array"`).

use envhub_core::ResetOptions;
use envhub_e2e::{TestHub, mujoco_available};
use envhub_hub::EnvConfig;

#[test]
fn frames_come_through_the_hub() {
    let t = TestHub::new("render");
    if !mujoco_available(&t.hub, "rendering::frames_come_through_the_hub") {
        return;
    }
    let mut config = EnvConfig {
        render_mode: Some("rgb_array".into()),
        workers: Some(1),
        ..EnvConfig::default()
    };
    config.extra.insert("width".into(), 64.into());
    config.extra.insert("height".into(), 48.into());
    let mut env = t.hub.make("mujoco-ant", &config).unwrap();
    env.reset(Some(0), &ResetOptions::new()).unwrap();
    let first = env.render().unwrap().expect("a frame");
    assert_eq!(
        (first.height, first.width, first.rgb.len()),
        (48, 64, 48 * 64 * 3)
    );
    assert!(
        first.rgb.iter().any(|&p| p != first.rgb[0]),
        "the frame is not blank"
    );
    let action = vec![0u8; env.action_space().byte_len()];
    for _ in 0..30 {
        env.step(&action).unwrap();
    }
    let later = env.render().unwrap().expect("a frame");
    assert_ne!(first.rgb, later.rgb, "the frame changes as the robot moves");
    let mut cart = t.hub.make("gym-cartpole", &EnvConfig::default()).unwrap();
    cart.reset(Some(0), &ResetOptions::new()).unwrap();
    assert!(cart.render().unwrap().is_none());
}

/// Each env's frame rate (Gymnasium's `metadata["render_fps"]`) comes through the worker's
/// ready line to the client: the classic envs' constants, MuJoCo's `round(1 / dt)`.
#[test]
fn render_fps_reaches_the_client() {
    let t = TestHub::new("render_fps");
    for (id, fps) in [("gym-cartpole", 50.0), ("gym-acrobot", 15.0)] {
        let env = t.hub.make(id, &EnvConfig::default()).unwrap();
        assert_eq!(env.render_fps(), Some(fps), "{id}");
    }
    let config = EnvConfig {
        workers: Some(2),
        ..EnvConfig::default()
    };
    let envs = t.hub.make_vec("gym-pendulum", 4, &config).unwrap();
    assert_eq!(envs.render_fps(), Some(30.0));

    if !mujoco_available(
        &t.hub,
        "rendering::render_fps_reaches_the_client (MuJoCo part)",
    ) {
        return;
    }
    let hopper = t.hub.make("mujoco-hopper", &EnvConfig::default()).unwrap();
    assert_eq!(hopper.render_fps(), Some(125.0)); // dt = 0.002 s × 4
    let mut config = EnvConfig::default();
    config.extra.insert("frame_skip".into(), 2.into());
    let hopper = t.hub.make("mujoco-hopper", &config).unwrap();
    assert_eq!(hopper.render_fps(), Some(250.0));
}
