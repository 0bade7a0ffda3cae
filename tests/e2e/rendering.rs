//! Frames rendered in a worker reach the client (`render_mode = "rgb_array"`).

use envhub::EnvConfig;
use envhub_core::ResetOptions;
use envhub_e2e::TestHub;

#[test]
fn frames_come_through_the_hub() {
    let t = TestHub::new("render");
    let adapters = t.hub.adapters().unwrap();
    let mujoco = adapters
        .iter()
        .find(|a| a.name == "mujoco")
        .expect("the mujoco adapter is listed");
    if !mujoco.availability.is_available() {
        // Only a worker built without the `mujoco` feature gets here; `make test` builds it.
        eprintln!("skipped: {:?}", mujoco.availability);
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
