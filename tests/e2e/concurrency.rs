//! Several client processes at once, each with its own workers: nothing lost, nothing out of
//! order, no crosstalk.

use envhub_e2e::TestHub;
use envhub_hub::EnvConfig;
use std::time::{Duration, Instant};

const CLIENTS: usize = 8;
const STEPS: usize = 10_000;

#[test]
fn eight_clients_ten_thousand_steps_each() {
    let t = TestHub::new("eight");
    let start = Instant::now();
    let children: Vec<_> = (0..CLIENTS)
        .map(|k| {
            std::process::Command::new(std::env::current_exe().unwrap())
                .args(["--exact", "concurrency::client_process", "--nocapture"])
                .env("E2E_CLIENT", k.to_string())
                .env("E2E_CLIENT_NAMESPACE", &t.namespace)
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for (k, child) in children.into_iter().enumerate() {
        let out = child.wait_with_output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && stdout.contains(&format!("client {k} ok")),
            "client {k}: {}\n{stdout}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
    }
    assert!(
        start.elapsed() < Duration::from_secs(90),
        "took {:?}",
        start.elapsed()
    );
}

/// One client of `eight_clients_ten_thousand_steps_each`; does nothing in a normal run.
#[test]
fn client_process() {
    let (Ok(k), Ok(ns)) = (
        std::env::var("E2E_CLIENT"),
        std::env::var("E2E_CLIENT_NAMESPACE"),
    ) else {
        return;
    };
    let k: usize = k.parse().unwrap();
    let hub = envhub_hub::Hub::new(envhub_hub::Registry::builtin()).with_options(
        envhub_hub::SessionOptions {
            namespace: ns,
            ..envhub_hub::SessionOptions::default()
        },
    );
    // Null-v0 writes its step count into the first observation: every step must show the
    // next number, in every env, or a response was lost, repeated or crossed.
    let n = 1 + k % 3;
    let mut env = hub
        .make_vec_direct(
            "null",
            "Null-v0",
            &EnvConfig {
                num_envs: n,
                workers: Some(1),
                ..EnvConfig::default()
            },
        )
        .unwrap();
    env.reset(Some(k as u64)).unwrap();
    let actions = vec![0u8; n * 8];
    for step in 1..=STEPS {
        let b = env.step(&actions).unwrap();
        for i in 0..n {
            let count = b.obs_f32()[i * 4];
            assert_eq!(count, step as f32, "client {k}, env {i}, step {step}");
        }
    }
    env.close();
    println!("client {k} ok");
}
