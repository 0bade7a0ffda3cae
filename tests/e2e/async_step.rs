//! EnvPool-style asynchronous stepping: `send` to some envs, `recv` what finished first.

use envhub::EnvConfig;
use envhub_e2e::TestHub;

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
