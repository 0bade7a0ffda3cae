//! Conformance of every env of the adapter to the `Env` contract: the shared suite
//! (`envhub_conformance::check_env`: spaces, same seed → same trajectory, reset after the
//! episode ends, `TimeLimit` truncation at the env's default limit and a short one), then
//! classic-control checks: no early termination under a short limit, reset after termination.

use envhub_classic::{ClassicControl, ClassicEnv};
use envhub_conformance::check_env;
use envhub_core::{Env, EnvAdapter, EnvConfig, Info, ResetOptions, TimeLimit, Transition};

#[test]
fn every_env_conforms() {
    let adapter = ClassicControl;
    for env_id in adapter.list_envs() {
        check_env(&adapter, &env_id, &EnvConfig::default(), 1500);
    }
}

#[test]
fn short_limit_truncates_before_any_termination() {
    // No env can terminate within 5 steps of a default reset, so every one truncates at 5.
    let adapter = ClassicControl;
    for env_id in adapter.list_envs() {
        let mut env = TimeLimit::new(
            adapter.make(&env_id, &EnvConfig::default()).unwrap(),
            Some(5),
        );
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        let action = vec![0u8; env.action_space().byte_len()];
        env.reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        let ends: Vec<Transition> = (0..5)
            .map(|_| env.step(&action, &mut obs, &mut info).unwrap())
            .collect();
        assert!(ends.iter().all(|t| !t.terminated), "{env_id}");
        assert!(ends[4].truncated && ends[..4].iter().all(|t| !t.truncated));
        assert_eq!(env.elapsed(), 5);
    }
}

/// A state from which one step (with the given action) terminates, per terminating env.
const TERMINAL_STARTS: &[(&str, &[f64], &[u8])] = &[
    ("CartPole-v1", &[0.0, 0.0, 0.2, 1.0], &1i64.to_le_bytes()),
    ("MountainCar-v0", &[0.499, 0.01], &2i64.to_le_bytes()),
    (
        "MountainCarContinuous-v0",
        &[0.449, 0.01],
        &1.0f32.to_le_bytes(),
    ),
    (
        "Acrobot-v1",
        &[std::f64::consts::PI - 0.01, 0.0, 0.0, 0.0],
        &1i64.to_le_bytes(),
    ),
];

#[test]
fn reset_after_termination() {
    let adapter = ClassicControl;
    for &(env_id, state, action) in TERMINAL_STARTS {
        let mut env: Box<dyn ClassicEnv> =
            adapter.make_classic(env_id, &EnvConfig::default()).unwrap();
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        env.reset(Some(1), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        env.set_state(state).unwrap();
        assert!(env.step(action, &mut obs, &mut info).unwrap().terminated);

        env.reset(None, &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        assert!(env.observation_space().contains(&obs), "{env_id}");
        assert_ne!(env.state(), state);
        let t = env.step(action, &mut obs, &mut info).unwrap();
        assert!(!t.terminated, "{env_id}: a fresh episode ended at once");
        assert!(env.observation_space().contains(&obs), "{env_id}");
    }
}
