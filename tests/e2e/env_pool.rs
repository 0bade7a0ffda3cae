//! EnvPool's asynchronous contract: `batch_size` M of N, `async_reset`, `send` of any envs
//! handed out, `recv` of exactly the first M to finish — and every env's trajectory the same
//! as in a lock-step run, whatever order the envs come back in.

use envhub_e2e::{TestHub, mujoco_available};
use envhub_hub::EnvConfig;
use rand::SeedableRng;

/// Env `e`'s action at its step `t`: the same in every run, whatever the order.
pub(crate) fn action(env: &envhub_hub::VecEnv, e: usize, t: usize, out: &mut [u8]) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(((e as u64) << 32) | t as u64);
    env.action_space().sample_into(&mut rng, out);
}

/// One env's results of a reset or step as bytes: observation, reward, done flags.
pub(crate) fn record(b: &envhub_hub::Batch<'_>, k: usize, ob: usize) -> Vec<u8> {
    let mut row = b.obs[k * ob..(k + 1) * ob].to_vec();
    row.extend(b.rewards[k].to_le_bytes());
    row.extend([b.terminated[k] as u8, b.truncated[k] as u8]);
    row
}

/// Per env, the reset and `steps` steps in lock step.
pub(crate) fn lock_step(
    env: &mut envhub_hub::VecEnv,
    seed: u64,
    steps: usize,
) -> Vec<Vec<Vec<u8>>> {
    let (n, ob, ab) = (
        env.num_envs(),
        env.observation_space().byte_len(),
        env.action_space().byte_len(),
    );
    let mut out: Vec<Vec<Vec<u8>>> = vec![Vec::new(); n];
    let b = env.reset(Some(seed)).unwrap();
    for (e, rows) in out.iter_mut().enumerate() {
        rows.push(record(&b, e, ob));
    }
    let mut actions = vec![0u8; n * ab];
    for t in 0..steps {
        for e in 0..n {
            action(env, e, t, &mut actions[e * ab..(e + 1) * ab]);
        }
        let b = env.step(&actions).unwrap();
        for (e, rows) in out.iter_mut().enumerate() {
            rows.push(record(&b, e, ob));
        }
    }
    out
}

/// Per env, the reset and at least `steps` steps through `async_reset`/`send`/`recv` with
/// `batch_size` M: each `recv` must hold exactly M distinct envs.
pub(crate) fn env_pool(
    env: &mut envhub_hub::VecEnv,
    m: usize,
    seed: u64,
    steps: usize,
) -> Vec<Vec<Vec<u8>>> {
    let (n, ob, ab) = (
        env.num_envs(),
        env.observation_space().byte_len(),
        env.action_space().byte_len(),
    );
    env.set_batch_size(m).unwrap();
    assert_eq!(env.batch_size(), Some(m));
    env.async_reset(Some(seed)).unwrap();
    let mut out: Vec<Vec<Vec<u8>>> = vec![Vec::new(); n];
    let mut orders = std::collections::HashSet::new();
    while out.iter().any(|rows| rows.len() <= steps) {
        let ids = {
            let b = env.recv().unwrap();
            assert_eq!(b.env_ids.len(), m, "recv returns exactly batch_size envs");
            for (k, &e) in b.env_ids.iter().enumerate() {
                out[e].push(record(&b, k, ob));
            }
            b.env_ids.to_vec()
        };
        let mut sorted = ids.clone();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), m, "distinct envs: {ids:?}");
        orders.insert(ids.clone());
        let mut actions = vec![0u8; m * ab];
        for (k, &e) in ids.iter().enumerate() {
            action(env, e, out[e].len() - 1, &mut actions[k * ab..(k + 1) * ab]);
        }
        env.send(&actions, &ids).unwrap();
    }
    assert!(orders.len() > 1, "the envs came back in one grouping only");
    out
}

pub(crate) fn assert_same_per_env(
    id: &str,
    sync: &[Vec<Vec<u8>>],
    pool: &[Vec<Vec<u8>>],
    steps: usize,
) {
    for (e, (a, b)) in sync.iter().zip(pool).enumerate() {
        for t in 0..=steps {
            assert_eq!(a[t], b[t], "{id}: env {e} differs at its step {t}");
        }
    }
}

#[test]
fn cartpole_trajectories_per_env_equal_the_lock_step_run() {
    let t = TestHub::new("pool_cartpole");
    let config = EnvConfig {
        workers: Some(3),
        ..EnvConfig::default()
    };
    let steps = 150;
    let mut env = t.hub.make_vec("gym-cartpole", 8, &config).unwrap();
    let sync = lock_step(&mut env, 7, steps);
    // M = 3 is no multiple of the envs per worker (3, 3, 2): envs of one answer are handed
    // out over two `recv`s, and sends to a busy worker wait on the client.
    let mut env = t.hub.make_vec("gym-cartpole", 8, &config).unwrap();
    let pool = env_pool(&mut env, 3, 7, steps);
    assert_same_per_env("gym-cartpole", &sync, &pool, steps);
}

#[test]
fn mujoco_trajectories_per_env_equal_the_lock_step_run() {
    let t = TestHub::new("pool_mujoco");
    if !mujoco_available(
        &t.hub,
        "mujoco_trajectories_per_env_equal_the_lock_step_run",
    ) {
        return;
    }
    // Short episodes: autoresets (truncation) happen inside the run.
    let config = EnvConfig {
        workers: Some(2),
        max_episode_steps: Some(25),
        ..EnvConfig::default()
    };
    let steps = 80;
    let mut env = t.hub.make_vec("mujoco-hopper", 6, &config).unwrap();
    let sync = lock_step(&mut env, 3, steps);
    let mut env = t.hub.make_vec("mujoco-hopper", 6, &config).unwrap();
    let pool = env_pool(&mut env, 3, 3, steps);
    assert_same_per_env("mujoco-hopper", &sync, &pool, steps);
}

fn null(t: &TestHub, num_envs: usize, workers: usize) -> envhub_hub::VecEnv {
    let config = EnvConfig {
        num_envs,
        workers: Some(workers),
        ..EnvConfig::default()
    };
    t.hub.make_vec_direct("null", "Null-v0", &config).unwrap()
}

#[test]
fn recv_returns_exactly_batch_size_envs_and_misuse_is_an_error() {
    let t = TestHub::new("pool_exact");
    // Null-v0 counts its steps in obs[0].
    let mut env = null(&t, 6, 3);
    for bad in [0, 7] {
        let err = env.set_batch_size(bad).unwrap_err().to_string();
        assert!(err.contains("use between 1 and 6"), "{err}");
    }
    env.set_batch_size(4).unwrap();
    env.async_reset(Some(0)).unwrap();
    let mut steps = [0u32; 6];
    let mut handed = Vec::new();
    for _ in 0..30 {
        let ids = {
            let b = env.recv().unwrap();
            assert_eq!(b.env_ids.len(), 4);
            for (k, &e) in b.env_ids.iter().enumerate() {
                assert_eq!(b.obs_f32()[k * 4], steps[e] as f32, "env {e}");
            }
            b.env_ids.to_vec()
        };
        for &e in &ids {
            steps[e] += 1;
        }
        handed = ids.clone();
        env.send(&vec![0u8; 8 * ids.len()], &ids).unwrap();
    }
    // Six envs in flight or waiting: a send to one of them is refused.
    let err = env.send(&[0u8; 8], &handed[..1]).unwrap_err().to_string();
    assert!(err.contains("was sent and not received"), "{err}");
    // Lock-step stepping is refused while envs are out; a reset drops what is out.
    let err = env.step(&[0u8; 48]).unwrap_err().to_string();
    assert!(err.contains("EnvPool mode"), "{err}");
    let b = env.reset(Some(0)).unwrap();
    assert!(b.obs_f32().chunks(4).all(|o| o[0] == 0.0));
    // After a lock-step reset every env is handed out: send two, and `recv` (4) cannot
    // be satisfied.
    env.send(&[0u8; 16], &[2, 5]).unwrap();
    let err = env.recv().unwrap_err().to_string();
    assert!(err.contains("only 2 are sent"), "{err}");
    env.send(&[0u8; 16], &[0, 1]).unwrap();
    let b = env.recv().unwrap();
    let mut ids = b.env_ids.to_vec();
    ids.sort();
    assert_eq!(ids, [0, 1, 2, 5]);
    assert!(b.obs_f32().chunks(4).all(|o| o[0] == 1.0));
}

#[test]
fn a_batch_of_whole_workers_is_viewed_in_place() {
    let t = TestHub::new("pool_in_place");
    // Two envs per worker and M = 2: every `recv` is one worker's answer, one block.
    let mut env = null(&t, 6, 3);
    env.set_batch_size(2).unwrap();
    env.async_reset(None).unwrap();
    for _ in 0..30 {
        let ids = {
            let b = env.recv().unwrap();
            assert!(b.in_place(), "{:?}", b.env_ids);
            b.env_ids.to_vec()
        };
        env.send(&[0u8; 16], &ids).unwrap();
    }
    assert_eq!(env.obs_bytes_copied(), 0);
}
