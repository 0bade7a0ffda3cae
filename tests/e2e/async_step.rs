//! EnvPool-style asynchronous stepping: `send` to some envs, `recv` what finished first.

use envhub_e2e::TestHub;
use envhub_hub::EnvConfig;

fn config(workers: usize) -> EnvConfig {
    EnvConfig {
        workers: Some(workers),
        ..EnvConfig::default()
    }
}

#[test]
fn send_to_some_envs_and_receive_them() {
    let t = TestHub::new("async");
    // Null-v0 counts steps in obs[0]: it shows which envs really stepped.
    let mut env = t
        .hub
        .make_vec_direct(
            "null",
            "Null-v0",
            &EnvConfig {
                num_envs: 4,
                ..config(2)
            },
        )
        .unwrap();
    env.reset(Some(0)).unwrap();
    // Envs 0 and 1 live on worker 0; 2 and 3 on worker 1.
    env.send(&[0u8; 16], &[1, 0]).unwrap();
    let b = env.recv().unwrap();
    assert_eq!(b.env_ids, &[0, 1]);
    assert_eq!(b.obs_f32()[0], 1.0);
    assert_eq!(b.obs_f32()[4], 1.0);

    // All four, then collect until every worker has answered.
    env.send(&[0u8; 32], &[0, 1, 2, 3]).unwrap();
    let mut seen = Vec::new();
    while seen.len() < 4 {
        let b = env.recv().unwrap();
        for (k, &id) in b.env_ids.iter().enumerate() {
            let expected = if id < 2 { 2.0 } else { 1.0 };
            assert_eq!(b.obs_f32()[k * 4], expected, "env {id}");
            seen.push(id);
        }
    }
    seen.sort();
    assert_eq!(seen, [0, 1, 2, 3]);
}

#[test]
fn async_misuse_is_an_error() {
    let t = TestHub::new("async_misuse");
    let mut env = t
        .hub
        .make_vec_direct(
            "null",
            "Null-v0",
            &EnvConfig {
                num_envs: 2,
                ..config(1)
            },
        )
        .unwrap();
    env.reset(None).unwrap();
    let err = env.recv().unwrap_err().to_string();
    assert!(err.contains("nothing was sent"), "{err}");
    env.send(&[0u8; 8], &[1]).unwrap();
    let err = env.send(&[0u8; 8], &[0]).unwrap_err().to_string();
    assert!(err.contains("call `recv` first"), "{err}");
    env.recv().unwrap();
    let err = env.send(&[0u8; 8], &[5]).unwrap_err().to_string();
    assert!(err.contains("env id 5 is out of range"), "{err}");
    let err = env.send(&[0u8; 8], &[0, 1]).unwrap_err().to_string();
    assert!(err.contains("for 2 envs"), "{err}");
}

fn null(t: &TestHub, num_envs: usize, workers: usize, sleep_ms: u64) -> envhub_hub::VecEnv {
    let mut config = EnvConfig {
        num_envs,
        ..config(workers)
    };
    config
        .extra
        .insert("sleep_ms".into(), serde_json::json!(sleep_ms));
    t.hub.make_vec_direct("null", "Null-v0", &config).unwrap()
}

#[test]
fn recv_holds_exactly_the_envs_that_were_stepped() {
    let t = TestHub::new("async_exact");
    // One worker hosting envs 0 and 1: a send to env 0 alone must not bring env 1 back.
    let mut env = null(&t, 2, 1, 0);
    env.reset(Some(0)).unwrap();
    env.step(&[0u8; 16]).unwrap();
    env.send(&[0u8; 8], &[0]).unwrap();
    let b = env.recv().unwrap();
    assert_eq!(b.env_ids, &[0]);
    assert_eq!(b.obs.len(), 16, "one observation");
    assert_eq!(b.rewards.len(), 1);
    assert_eq!(b.obs_f32()[0], 2.0, "env 0 stepped twice");
    // Env 1 did not step: the next full step shows it one step behind.
    let b = env.step(&[0u8; 16]).unwrap();
    assert_eq!((b.obs_f32()[0], b.obs_f32()[4]), (3.0, 2.0));
}

#[test]
fn recv_returns_the_first_worker_to_finish() {
    let t = TestHub::new("async_first");
    // One env per worker, each step takes 150 ms.
    let mut env = null(&t, 2, 2, 150);
    env.reset(Some(0)).unwrap();
    let start = std::time::Instant::now();
    // Worker 1 starts first and finishes first (at 150 ms), although worker 0 comes first in
    // env order (it finishes at 230 ms).
    env.send(&[0u8; 8], &[1]).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(80));
    env.send(&[0u8; 8], &[0]).unwrap();
    let b = env.recv().unwrap();
    let first = start.elapsed();
    assert_eq!(b.env_ids, &[1]);
    assert!(b.in_place());
    let b = env.recv().unwrap();
    assert_eq!(b.env_ids, &[0]);
    assert!(
        first < std::time::Duration::from_millis(215),
        "the first worker's results came after {first:?}"
    );
}

#[test]
fn envs_of_idle_workers_can_be_sent_while_others_step() {
    let t = TestHub::new("async_pipeline");
    let mut env = null(&t, 4, 2, 20);
    env.reset(Some(0)).unwrap();
    env.send(&[0u8; 16], &[0, 1]).unwrap();
    env.send(&[0u8; 16], &[2, 3]).unwrap();
    let err = env.send(&[0u8; 8], &[1]).unwrap_err().to_string();
    assert!(err.contains("env 1 is still stepping"), "{err}");
    // EnvPool's loop: whatever comes back is sent again at once.
    let mut steps = [0u32; 4];
    for _ in 0..20 {
        let ids: Vec<usize> = {
            let b = env.recv().unwrap();
            assert!(b.in_place(), "one worker's rows are one block");
            b.env_ids.to_vec()
        };
        for &i in &ids {
            steps[i] += 1;
        }
        env.send(&vec![0u8; 8 * ids.len()], &ids).unwrap();
    }
    assert!(steps.iter().all(|&s| s >= 5), "{steps:?}");
    assert_eq!(env.obs_bytes_copied(), 0);
}

#[test]
fn several_workers_fill_one_block_viewed_in_place() {
    let t = TestHub::new("async_block");
    let mut env = null(&t, 6, 3, 0);
    let b = env.reset(Some(0)).unwrap();
    assert!(b.in_place() && b.lease().is_some());
    for k in 1..=20 {
        let b = env.step(&[0u8; 48]).unwrap();
        assert!(b.in_place());
        assert!(b.obs_f32().chunks(4).all(|o| o[0] == k as f32));
    }
    // All three workers sent together and done together: one block, in place.
    env.send(&[0u8; 48], &[0, 1, 2, 3, 4, 5]).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(50));
    let b = env.recv().unwrap();
    assert_eq!(b.env_ids, &[0, 1, 2, 3, 4, 5]);
    assert!(b.in_place());
    // Envs picked out of a worker's are gathered: the one case that copies.
    env.send(&[0u8; 16], &[0, 5]).unwrap();
    let mut seen = Vec::new();
    while seen.len() < 2 {
        seen.extend_from_slice(env.recv().unwrap().env_ids);
    }
    seen.sort();
    assert_eq!(seen, [0, 5]);
    assert_eq!(
        env.obs_bytes_copied(),
        0,
        "each worker's one env is a block of one"
    );
}

/// `send_reset` resets some envs alone while the others step: every env's trajectory (its
/// reset, its steps with its own actions, its second reset with a new seed and its steps)
/// equals a lock-step run that resets the same envs with `reset_with` and a mask. Reset rows
/// come back with reward 0 and no done flag.
#[test]
fn envs_reset_alone_while_others_step_follow_the_lock_step_trajectories() {
    use crate::env_pool::{action, record};
    let t = TestHub::new("send_reset");
    let (n, first, second) = (4, 10, 10);
    let reseed = [Some(100), Some(101), None, None];
    let mask = [true, true, false, false];
    let make = || t.hub.make_vec("gym-cartpole", n, &config(2)).unwrap();
    let (ob, ab) = {
        let env = make();
        (
            env.observation_space().byte_len(),
            env.action_space().byte_len(),
        )
    };
    // Lock step: `first` steps, envs 0 and 1 reset with new seeds, `second` steps.
    let mut sync = make();
    let mut want: Vec<Vec<Vec<u8>>> = vec![Vec::new(); n];
    let mut steps = [0usize; 4];
    let b = sync.reset(Some(3)).unwrap();
    (0..n).for_each(|e| want[e].push(record(&b, e, ob)));
    let mut actions = vec![0u8; n * ab];
    for round in 0..first + second {
        if round == first {
            let b = sync
                .reset_with(&reseed, Some(&mask), &Default::default())
                .unwrap();
            (0..2).for_each(|e| want[e].push(record(&b, e, ob)));
            steps[..2].fill(0);
        }
        for e in 0..n {
            action(&sync, e, steps[e], &mut actions[e * ab..(e + 1) * ab]);
            steps[e] += 1;
        }
        let b = sync.step(&actions).unwrap();
        (0..n).for_each(|e| want[e].push(record(&b, e, ob)));
    }
    sync.close();
    // send/recv: envs 0 and 1 (worker 0) reset alone while envs 2 and 3 (worker 1) step.
    let mut env = make();
    let mut got: Vec<Vec<Vec<u8>>> = vec![Vec::new(); n];
    let mut steps = [0usize; 4];
    let b = env.reset(Some(3)).unwrap();
    (0..n).for_each(|e| got[e].push(record(&b, e, ob)));
    let receive = |env: &mut envhub_hub::VecEnv, got: &mut Vec<Vec<Vec<u8>>>, count: usize| {
        let mut seen = 0;
        while seen < count {
            let b = env.recv().unwrap();
            for (k, &e) in b.env_ids.iter().enumerate() {
                got[e].push(record(&b, k, ob));
            }
            seen += b.env_ids.len();
        }
    };
    let send = |env: &mut envhub_hub::VecEnv, ids: &[usize], steps: &mut [usize; 4]| {
        let mut block = vec![0u8; ids.len() * ab];
        for (k, &e) in ids.iter().enumerate() {
            action(env, e, steps[e], &mut block[k * ab..(k + 1) * ab]);
            steps[e] += 1;
        }
        env.send(&block, ids).unwrap();
    };
    for _ in 0..first {
        send(&mut env, &[0, 1, 2, 3], &mut steps);
        receive(&mut env, &mut got, n);
    }
    env.send_reset(&[0, 1], &reseed[..2], &Default::default())
        .unwrap();
    steps[..2].fill(0);
    send(&mut env, &[2, 3], &mut steps);
    receive(&mut env, &mut got, n);
    for (e, rows) in got.iter().enumerate().take(2) {
        let reset_row = rows.last().unwrap();
        assert_eq!(
            &reset_row[ob..],
            &[0u8; 10][..],
            "env {e}'s reset row: reward 0, not done"
        );
    }
    for _ in 0..second - 1 {
        send(&mut env, &[0, 1, 2, 3], &mut steps);
        receive(&mut env, &mut got, n);
    }
    send(&mut env, &[0, 1], &mut steps);
    receive(&mut env, &mut got, 2);
    for e in 0..n {
        assert_eq!(got[e].len(), want[e].len(), "env {e}'s results");
        for (k, (a, b)) in want[e].iter().zip(&got[e]).enumerate() {
            assert_eq!(a, b, "env {e} differs at its result {k}");
        }
    }
    // Misuse is refused with the reason: an env whose worker is out, seeds that do not match.
    send(&mut env, &[0, 1], &mut steps);
    let busy = env
        .send_reset(&[1], &[None], &Default::default())
        .unwrap_err();
    assert!(busy.to_string().contains("still stepping"), "{busy}");
    let seeds = env.send_reset(&[2], &[], &Default::default()).unwrap_err();
    assert!(seeds.to_string().contains("0 seeds for 1 envs"), "{seeds}");
}
