//! Random rollouts of the five classic-control envs through the hub, checked against the same
//! envs stepped in this process.

use envhub_classic::ClassicControl;
use envhub_core::{Env, EnvAdapter, Info, ResetOptions, TimeLimit};
use envhub_e2e::TestHub;
use envhub_hub::{AutoresetMode, EnvConfig};
use rand::SeedableRng;

const IDS: [(&str, &str); 5] = [
    ("gym-cartpole", "CartPole-v1"),
    ("gym-pendulum", "Pendulum-v1"),
    ("gym-mountain-car", "MountainCar-v0"),
    ("gym-mountain-car-continuous", "MountainCarContinuous-v0"),
    ("gym-acrobot", "Acrobot-v1"),
];

#[test]
fn all_five_roll_out_and_match_in_process_stepping() {
    let t = TestHub::new("rollouts");
    for (id, env_id) in IDS {
        let n = 5;
        let config = EnvConfig {
            workers: Some(2),
            ..EnvConfig::default()
        };
        let mut env = t.hub.make_vec(id, n, &config).unwrap();
        assert_eq!(env.num_workers(), 2);
        let obs_space = env.observation_space().clone();
        let ob = obs_space.byte_len();

        // The reference: the same envs, same seeds, stepped here with Gymnasium's next_step
        // autoreset applied by hand.
        let adapter = ClassicControl;
        let spec = adapter.spec(env_id, &EnvConfig::default()).unwrap();
        let mut local: Vec<_> = (0..n)
            .map(|_| {
                TimeLimit::new(
                    adapter.make(env_id, &EnvConfig::default()).unwrap(),
                    spec.max_episode_steps,
                )
            })
            .collect();
        let mut local_obs = vec![vec![0u8; ob]; n];
        let mut info = Info::default();
        let first = env.reset(Some(100)).unwrap().obs.to_vec();
        for (i, e) in local.iter_mut().enumerate() {
            e.reset(
                Some(100 + i as u64),
                &ResetOptions::new(),
                &mut local_obs[i],
                &mut info,
            )
            .unwrap();
            assert_eq!(
                &first[i * ob..(i + 1) * ob],
                &local_obs[i][..],
                "{id}: reset obs of env {i}"
            );
        }
        let mut pending = vec![false; n];
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let (mut episodes, mut truncations) = (0, 0);
        for step in 0..600 {
            let actions = env.sample_actions(&mut rng);
            let b = env.step(&actions).unwrap();
            let ab = actions.len() / n;
            for i in 0..n {
                let (reward, terminated, truncated) = if pending[i] {
                    local[i]
                        .reset(None, &ResetOptions::new(), &mut local_obs[i], &mut info)
                        .unwrap();
                    pending[i] = false;
                    (0.0, false, false)
                } else {
                    let t = local[i]
                        .step(&actions[i * ab..(i + 1) * ab], &mut local_obs[i], &mut info)
                        .unwrap();
                    pending[i] = t.terminated || t.truncated;
                    (t.reward, t.terminated, t.truncated)
                };
                let got = &b.obs[i * ob..(i + 1) * ob];
                assert!(
                    obs_space.contains(got),
                    "{id}: obs of env {i} at step {step} outside {obs_space}"
                );
                assert_eq!(
                    got,
                    &local_obs[i][..],
                    "{id}: obs of env {i} at step {step}"
                );
                assert_eq!(
                    b.rewards[i], reward,
                    "{id}: reward of env {i} at step {step}"
                );
                assert_eq!(
                    (b.terminated[i], b.truncated[i]),
                    (terminated, truncated),
                    "{id}: env {i} step {step}"
                );
                episodes += usize::from(terminated || truncated);
                truncations += usize::from(truncated);
            }
        }
        let limit = env.max_episode_steps().expect("classic envs have a limit");
        if limit <= 500 {
            assert!(episodes > 0, "{id}: some episode ended in 600 steps");
        }
        if limit <= 200 {
            assert!(truncations > 0, "{id}: episodes are truncated at {limit}");
        }
        env.close();
    }
}

#[test]
fn same_step_autoreset_reports_final_observation() {
    let t = TestHub::new("same_step");
    let config = EnvConfig {
        autoreset_mode: AutoresetMode::SameStep,
        max_episode_steps: Some(5),
        workers: Some(1),
        ..EnvConfig::default()
    };
    let mut env = t.hub.make_vec("gym-pendulum", 2, &config).unwrap();
    env.reset(Some(1)).unwrap();
    let action = vec![0u8; 2 * env.action_space().byte_len()];
    for step in 1..=12 {
        let b = env.step(&action).unwrap();
        let done = step % 5 == 0;
        assert_eq!(b.truncated, &[done, done], "step {step}");
        assert_eq!(b.final_obs(0).is_some(), done, "step {step}");
    }
}

#[test]
fn disabled_autoreset_resets_with_a_mask() {
    let t = TestHub::new("disabled");
    let config = EnvConfig {
        autoreset_mode: AutoresetMode::Disabled,
        max_episode_steps: Some(3),
        workers: Some(1),
        ..EnvConfig::default()
    };
    let mut env = t.hub.make_vec("gym-pendulum", 2, &config).unwrap();
    env.reset(Some(1)).unwrap();
    let action = vec![0u8; 2 * env.action_space().byte_len()];
    for _ in 0..3 {
        env.step(&action).unwrap();
    }
    let before = env.step(&action).unwrap().obs.to_vec();
    let b = env
        .reset_with(&[Some(5), None], Some(&[true, false]), &ResetOptions::new())
        .unwrap();
    let ob = b.obs.len() / 2;
    assert_ne!(&b.obs[..ob], &before[..ob], "env 0 was reset");
    let b = env.step(&action).unwrap();
    assert!(!b.truncated[0], "env 0 starts a new episode");
}

#[test]
fn single_env_keeps_gymnasium_contract() {
    let t = TestHub::new("single");
    let mut env = t.hub.make("gym-cartpole", &EnvConfig::default()).unwrap();
    let first = env
        .reset(Some(3), &ResetOptions::new())
        .unwrap()
        .obs
        .to_vec();
    let again = env
        .reset(Some(3), &ResetOptions::new())
        .unwrap()
        .obs
        .to_vec();
    assert_eq!(first, again, "same seed, same start");
    let mut steps = 0;
    loop {
        let s = env.step(&1i64.to_le_bytes()).unwrap();
        steps += 1;
        if s.terminated || s.truncated {
            break;
        }
        assert!(steps < 500);
    }
    assert!(steps < 100, "always pushing right ends the episode early");
}
