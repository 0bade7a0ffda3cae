//! Conformance of every env of the adapter to the `Env` contract: observations inside the
//! observation space, same seed → same trajectory, reset after the episode ends, and `TimeLimit`
//! truncation at `max_episode_steps`.
//!
//! `check_env` takes any adapter and env id, so it can move to a suite shared by all adapters.

use envhub_classic::{ClassicControl, ClassicEnv};
use envhub_core::{Env, EnvAdapter, EnvConfig, Info, ResetOptions, TimeLimit, Transition};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// Steps `env` with random actions, resetting when an episode ends; returns every observation,
/// reward and end flag. Panics if an observation or action leaves its space.
fn rollout(env: &mut dyn Env, seed: u64, steps: usize) -> Vec<(Vec<u8>, f64, bool, bool)> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut obs = vec![0u8; env.observation_space().byte_len()];
    let mut info = Info::default();
    let options = ResetOptions::new();
    env.reset(Some(seed), &options, &mut obs, &mut info)
        .unwrap();
    let mut out = vec![(obs.clone(), 0.0, false, false)];
    for _ in 0..steps {
        let action = env.action_space().sample(&mut rng);
        assert!(env.action_space().contains(&action));
        let t = env.step(&action, &mut obs, &mut info).unwrap();
        assert!(
            env.observation_space().contains(&obs),
            "{:?}",
            env.observation_space().validate(&obs)
        );
        assert!(t.reward.is_finite());
        out.push((obs.clone(), t.reward, t.terminated, t.truncated));
        if t.terminated || t.truncated {
            env.reset(None, &options, &mut obs, &mut info).unwrap();
            assert!(env.observation_space().contains(&obs));
            out.push((obs.clone(), 0.0, false, false));
        }
    }
    out
}

/// The contract checks for one env of `adapter`.
fn check_env(adapter: &dyn EnvAdapter, env_id: &str) {
    let config = EnvConfig::default();
    let spec = adapter.spec(env_id, &config).unwrap();
    let limit = config.episode_limit(spec.max_episode_steps);
    let make = || TimeLimit::new(adapter.make(env_id, &config).unwrap(), limit);

    let mut env = make();
    assert_eq!(env.observation_space(), &spec.observation_space, "{env_id}");
    assert_eq!(env.action_space(), &spec.action_space, "{env_id}");

    // Observations stay in the space over several episodes, with resets after each end.
    let a = rollout(&mut env, 7, 1500);
    let episodes = a.iter().filter(|s| s.2 || s.3).count();
    assert!(episodes >= 1, "{env_id}: no episode ended in 1500 steps");

    // Same seed, same trajectory (a fresh env, and the same env reseeded).
    assert_eq!(a, rollout(&mut make(), 7, 1500), "{env_id}: fresh env");
    assert_eq!(a, rollout(&mut env, 7, 1500), "{env_id}: reseeded env");
    assert_ne!(a, rollout(&mut env, 8, 1500), "{env_id}: other seed");

    // Truncation at exactly the limit, whether the env's default or the caller's.
    for limit in [spec.max_episode_steps.unwrap(), 5] {
        let mut env = TimeLimit::new(adapter.make(env_id, &config).unwrap(), Some(limit));
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        env.reset(Some(3), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        for step in 1..=limit {
            let action = env.action_space().sample(&mut rng);
            let t = env.step(&action, &mut obs, &mut info).unwrap();
            assert_eq!(t.truncated, step == limit, "{env_id}: step {step}/{limit}");
            if t.terminated {
                break;
            }
        }
    }
}

#[test]
fn every_env_conforms() {
    let adapter = ClassicControl;
    for env_id in adapter.list_envs() {
        check_env(&adapter, &env_id);
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
