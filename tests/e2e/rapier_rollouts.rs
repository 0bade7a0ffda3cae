//! The rapier tasks through the real hub: the same seeds and actions give bit-identical
//! batches with one worker and with two, in each autoreset mode; the first observations equal
//! the same envs reset in this process.

use envhub_core::{Env, EnvAdapter, Info, ResetOptions};
use envhub_e2e::TestHub;
use envhub_hub::{AutoresetMode, EnvConfig};
use envhub_rapier::Rapier;
use rand::SeedableRng;

const IDS: [(&str, &str); 4] = [
    ("rapier-arm-reach", "ArmReach-v0"),
    ("rapier-arm-push", "ArmPush-v0"),
    ("rapier-ant-run", "AntRun-v0"),
    ("rapier-rover-terrain", "RoverTerrain-v0"),
];

/// Everything a rollout returned, step by step: observations, rewards, flags and the final
/// observations of same-step autoresets.
type Trace = Vec<(
    Vec<u8>,
    Vec<f64>,
    Vec<bool>,
    Vec<bool>,
    Vec<Option<Vec<u8>>>,
)>;

fn rollout(t: &TestHub, id: &str, n: usize, workers: usize, mode: AutoresetMode) -> Trace {
    let config = EnvConfig {
        workers: Some(workers),
        autoreset_mode: mode,
        // Short episodes, so every mode resets several times.
        max_episode_steps: Some(12),
        ..EnvConfig::default()
    };
    let mut env = t.hub.make_vec(id, n, &config).unwrap();
    assert_eq!(env.num_workers(), workers, "{id}");
    let first = env.reset(Some(100)).unwrap().obs.to_vec();
    let mut trace: Trace = vec![(first, vec![], vec![], vec![], vec![])];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    for _ in 0..40 {
        let actions = env.sample_actions(&mut rng);
        let b = env.step(&actions).unwrap();
        let finals = (0..n).map(|i| b.final_obs(i).map(<[u8]>::to_vec)).collect();
        let done: Vec<bool> = (0..n).map(|i| b.terminated[i] || b.truncated[i]).collect();
        trace.push((
            b.obs.to_vec(),
            b.rewards.to_vec(),
            b.terminated.to_vec(),
            b.truncated.to_vec(),
            finals,
        ));
        if mode == AutoresetMode::Disabled && done.iter().any(|&d| d) {
            let b = env
                .reset_with(&vec![None; n], Some(&done), &ResetOptions::new())
                .unwrap();
            trace.push((b.obs.to_vec(), vec![], vec![], vec![], vec![]));
        }
    }
    env.close();
    trace
}

#[test]
fn one_and_two_workers_give_bit_identical_rollouts_in_every_autoreset_mode() {
    let t = TestHub::new("rapier_workers");
    for (id, env_id) in IDS {
        let n = 4;
        let modes: &[AutoresetMode] = if id == "rapier-rover-terrain" {
            &[
                AutoresetMode::NextStep,
                AutoresetMode::SameStep,
                AutoresetMode::Disabled,
            ]
        } else {
            &[AutoresetMode::NextStep]
        };
        for &mode in modes {
            let one = rollout(&t, id, n, 1, mode);
            let two = rollout(&t, id, n, 2, mode);
            assert_eq!(one.len(), two.len(), "{id} {mode:?}");
            for (step, (a, b)) in one.iter().zip(&two).enumerate() {
                assert!(
                    a == b,
                    "{id} {mode:?}: 1 and 2 workers differ at entry {step}"
                );
            }
            let resets = one
                .iter()
                .skip(1)
                .filter(|s| s.2.iter().chain(&s.3).any(|&d| d))
                .count();
            assert!(resets > 0, "{id} {mode:?}: no episode ended");
            if mode == AutoresetMode::SameStep {
                assert!(one.iter().any(|s| s.4.iter().any(Option::is_some)), "{id}");
            }
        }

        // The hub's first observations are the adapter's, reset here with the same seeds.
        let first = &rollout(&t, id, n, 2, AutoresetMode::NextStep)[0].0;
        let ob = first.len() / n;
        for i in 0..n {
            let mut local = Rapier.make(env_id, &EnvConfig::default()).unwrap();
            let mut obs = vec![0u8; ob];
            local
                .reset(
                    Some(100 + i as u64),
                    &ResetOptions::new(),
                    &mut obs,
                    &mut Info::default(),
                )
                .unwrap();
            assert_eq!(&first[i * ob..(i + 1) * ob], &obs[..], "{id}: env {i}");
        }
    }
}
