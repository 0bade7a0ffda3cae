//! Bad input gets a clear error naming what is wrong and what is valid; never a panic or hang.

use envhub_core::ResetOptions;
use envhub_e2e::TestHub;
use envhub_hub::{EnvConfig, HubError};

fn msg(e: HubError) -> String {
    e.to_string()
}

#[test]
fn unknown_id_suggests_the_closest() {
    let t = TestHub::new("unknown");
    let err = t
        .hub
        .make_vec("gym-cartpol", 1, &EnvConfig::default())
        .err()
        .map(msg)
        .unwrap();
    assert!(err.contains("did you mean `gym-cartpole`"), "{err}");
}

#[test]
fn wrong_shape_dtype_range_and_nan() {
    let t = TestHub::new("actions");
    let mut cart = t
        .hub
        .make_vec("gym-cartpole", 2, &EnvConfig::default())
        .unwrap();
    cart.reset(Some(0)).unwrap();
    let err = msg(cart.step(&[0u8; 8]).unwrap_err());
    assert!(
        err.contains("for 2 envs") && err.contains("[2] of int64"),
        "{err}"
    );
    let err = msg(cart.step_f32(&[0.0, 1.0]).unwrap_err());
    assert!(
        err.contains("actions are float32 but Discrete(2) takes int64"),
        "{err}"
    );
    let err = msg(cart.step_i64(&[0, 2]).unwrap_err());
    assert!(
        err.contains("env 1") && err.contains("outside Discrete(2)"),
        "{err}"
    );
    cart.step_i64(&[0, 1]).unwrap();

    let mut pend = t
        .hub
        .make_vec("gym-pendulum", 1, &EnvConfig::default())
        .unwrap();
    pend.reset(Some(0)).unwrap();
    let err = msg(pend.step_f32(&[f32::NAN]).unwrap_err());
    assert!(err.contains("NaN"), "NaN actions are rejected: {err}");
    // Beyond the bounds, as Gymnasium: the env clips (`actions.rs` covers both modes).
    pend.step_f32(&[3.0]).unwrap();
    let err = msg(pend.step_f32(&[0.0, 1.0]).unwrap_err());
    assert!(err.contains("for 1 envs"), "{err}");
}

#[test]
fn step_before_reset_and_after_close() {
    let t = TestHub::new("state");
    let mut env = t
        .hub
        .make_vec("gym-cartpole", 1, &EnvConfig::default())
        .unwrap();
    let err = msg(env.step_i64(&[0]).unwrap_err());
    assert!(err.contains("must be reset before it is stepped"), "{err}");
    env.reset(None).unwrap();
    env.close();
    let err = msg(env.step_i64(&[0]).unwrap_err());
    assert!(err.contains("is closed"), "{err}");
    assert!(env.reset(None).is_err());
    env.close();
}

#[test]
fn bad_counts_and_options() {
    let t = TestHub::new("counts");
    let err = t
        .hub
        .make_vec("gym-cartpole", 0, &EnvConfig::default())
        .err()
        .map(msg)
        .unwrap();
    assert!(
        err.contains("num_envs") && err.contains("at least 1"),
        "{err}"
    );
    let err = t
        .hub
        .make_vec(
            "gym-cartpole",
            2,
            &EnvConfig {
                workers: Some(3),
                ..EnvConfig::default()
            },
        )
        .err()
        .map(msg)
        .unwrap();
    assert!(err.contains("3 workers for 2 envs"), "{err}");
    let mut config = EnvConfig::default();
    config.extra.insert("gravity".into(), 9.8.into());
    let err = t
        .hub
        .make_vec("gym-pendulum", 1, &config)
        .err()
        .map(msg)
        .unwrap();
    assert!(
        err.contains("unknown option `gravity`") && err.contains("valid options are: g"),
        "{err}"
    );

    let mut env = t.hub.make("gym-pendulum", &EnvConfig::default()).unwrap();
    let mut options = ResetOptions::new();
    options.insert("x_init".into(), "far".into());
    let err = msg(env.reset(Some(0), &options).unwrap_err());
    assert!(err.contains("x_init"), "{err}");
    env.reset(Some(0), &ResetOptions::new()).unwrap();
}

#[test]
fn unknown_framework_and_adapter() {
    let t = TestHub::new("framework");
    let dir = std::env::temp_dir().join(format!("e2e-fw-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("r.yaml");
    std::fs::write(
        &file,
        "environments:\n  - {id: odd, name: Odd, framework: bullet, env_id: X-v0, robot_type: arm, env_type: tabletop}\n  - {id: pinned, name: P, framework: gym, env_id: CartPole-v1, robot_type: custom, env_type: floor, adapter: nope}\n  - {id: nonnative, name: N, framework: gym, env_id: NoSuchEnv-v0, robot_type: custom, env_type: floor}\n",
    )
    .unwrap();
    let hub = envhub_hub::Hub::new(envhub_hub::Registry::load(&[&file]).unwrap())
        .with_options(t.hub.options().clone());
    let err = hub
        .make("odd", &EnvConfig::default())
        .err()
        .map(msg)
        .unwrap();
    assert!(
        err.contains("unknown framework `bullet`") && err.contains("gymnasium"),
        "{err}"
    );
    let err = hub
        .make("pinned", &EnvConfig::default())
        .err()
        .map(msg)
        .unwrap();
    assert!(
        err.contains("pins adapter `nope`") && err.contains("classic_control"),
        "{err}"
    );
    let err = hub
        .make("nonnative", &EnvConfig::default())
        .err()
        .map(msg)
        .unwrap();
    // No native adapter runs it, so it goes to the Python-hosted `gymnasium` adapter, which
    // says Gymnasium has no such id (or, without a usable Python, that it is unavailable).
    assert!(
        err.contains("Gymnasium has no env `NoSuchEnv-v0`")
            || err.contains("adapter `gymnasium` is unavailable"),
        "{err}"
    );
}
