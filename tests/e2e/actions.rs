//! Continuous actions beyond the action space's bounds: passed to the env as Gymnasium passes
//! them (the env clips them), refused with `strict_actions`; NaN and infinities refused either
//! way.

use envhub_e2e::TestHub;
use envhub_hub::{EnvConfig, HubError, VecEnv};

fn strict() -> EnvConfig {
    EnvConfig {
        strict_actions: true,
        ..EnvConfig::default()
    }
}

fn non_finite_refused(env: &mut VecEnv, actions: &[f32], env_index: usize) {
    let err = env.step_f32(actions).unwrap_err();
    assert!(matches!(err, HubError::InvalidAction { .. }), "{err}");
    let err = err.to_string();
    assert!(
        err.contains(&format!("`{}` env {env_index}: element 0 is", env.id()))
            && err.contains("hint: actions must be finite numbers"),
        "{err}"
    );
}

#[test]
fn pendulum_clips_beyond_the_bounds_by_default() {
    let t = TestHub::new("actions_default");
    let mut beyond = t
        .hub
        .make_vec("gym-pendulum", 2, &EnvConfig::default())
        .unwrap();
    let mut at_bound = t
        .hub
        .make_vec("gym-pendulum", 2, &EnvConfig::default())
        .unwrap();
    beyond.reset(Some(3)).unwrap();
    at_bound.reset(Some(3)).unwrap();
    for _ in 0..20 {
        // Gymnasium's Pendulum clips the torque: 6 and -1e30 act as 2 and -2 exactly.
        let b = beyond.step_f32(&[6.0, -1e30]).unwrap();
        let (obs, rewards) = (b.obs.to_vec(), b.rewards.to_vec());
        let a = at_bound.step_f32(&[2.0, -2.0]).unwrap();
        assert_eq!(obs, a.obs);
        assert_eq!(rewards, a.rewards);
    }
    // Also through `send`, which checks the envs it is given.
    beyond.send(bytemuck::cast_slice(&[-7.5f32]), &[1]).unwrap();
    beyond.recv().unwrap();

    non_finite_refused(&mut beyond, &[0.0, f32::NAN], 1);
    non_finite_refused(&mut beyond, &[f32::INFINITY, 0.0], 0);
    non_finite_refused(&mut beyond, &[0.0, f32::NEG_INFINITY], 1);
    beyond.step_f32(&[0.5, 0.5]).unwrap();
}

#[test]
fn strict_actions_refuse_beyond_the_bounds() {
    let t = TestHub::new("actions_strict");
    let mut pend = t.hub.make_vec("gym-pendulum", 2, &strict()).unwrap();
    pend.reset(Some(0)).unwrap();
    let err = pend.step_f32(&[0.0, 3.0]).unwrap_err();
    assert!(matches!(err, HubError::InvalidAction { .. }), "{err}");
    let err = err.to_string();
    assert!(
        err.contains("`gym-pendulum` env 1: element 0 = 3 is outside Box(-2, 2, [1], float32)")
            && err.contains("valid range [-2, 2]")
            && err.contains("hint: actions must lie in Box(-2, 2, [1], float32)"),
        "{err}"
    );
    let err = pend
        .send(bytemuck::cast_slice(&[-2.5f32]), &[0])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("`gym-pendulum` env 0: element 0 = -2.5 is outside"),
        "{err}"
    );
    non_finite_refused(&mut pend, &[f32::NAN, 0.0], 0);
    pend.step_f32(&[2.0, -2.0]).unwrap();
}

#[test]
fn mujoco_takes_actions_beyond_ctrlrange_unless_strict() {
    let t = TestHub::new("actions_mujoco");
    let adapters = t.hub.adapters().unwrap();
    let mujoco = adapters.iter().find(|a| a.name == "mujoco").unwrap();
    assert!(
        mujoco.availability.is_available(),
        "the worker lacks MuJoCo: {:?}\nhint: build with `--features envhub-worker/mujoco` (`make test` does)",
        mujoco.availability
    );
    let mut ant = t
        .hub
        .make_vec("mujoco-ant", 1, &EnvConfig::default())
        .unwrap();
    let n = ant.action_space().num_elements();
    ant.reset(Some(0)).unwrap();
    // MuJoCo clamps `ctrl` to `ctrlrange`; the control cost sees the action as given:
    // 0.5 · Σ 3², as in Gymnasium.
    let b = ant.step_f32(&vec![3.0; n]).unwrap();
    assert_eq!(
        b.info(0)["reward_ctrl"],
        -0.5 * 9.0 * n as f64,
        "{:?}",
        b.info(0)
    );
    non_finite_refused(&mut ant, &vec![f32::NAN; n], 0);

    let mut strict_ant = t.hub.make_vec("mujoco-ant", 1, &strict()).unwrap();
    strict_ant.reset(Some(0)).unwrap();
    let err = strict_ant.step_f32(&vec![3.0; n]).unwrap_err().to_string();
    assert!(
        err.contains("`mujoco-ant` env 0: element 0 = 3 is outside")
            && err.contains("valid range [-1, 1]"),
        "{err}"
    );
    strict_ant.step_f32(&vec![1.0; n]).unwrap();
}
