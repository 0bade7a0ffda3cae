//! A benchmark, not a test (ignored; it asserts nothing about time): CartPole × 1024 on a
//! remote hub over loopback against the same envs here, in one run, lock step and EnvPool's
//! `send`/`recv`, with one lane and with more lanes per hub. Here `send`/`recv` takes N/2 envs
//! a batch; on the hub it takes one lane's share (N/K with K lanes; N/2 with one), so the
//! other lanes step and travel while one batch is handled.
//!
//! `cargo test --release --features envhub-worker/mujoco -p envhub-e2e -- --ignored
//! remote_pool_bench --nocapture` (ENVHUB_BENCH_ENVS, ENVHUB_BENCH_WORKERS,
//! ENVHUB_BENCH_SECONDS and ENVHUB_BENCH_LANES, a comma-separated list, change the workload;
//! ENVHUB_BENCH_ZENOH_CONFIG gives the hub and the clients a Zenoh config file, to compare
//! transports).

use envhub_e2e::TestHub;
use envhub_e2e::remote::{RemoteHub, client};
use envhub_hub::{EnvConfig, Placement, SessionOptions, VecEnv};
use rand::SeedableRng;
use std::time::Instant;

fn knob(name: &str, default: f64) -> f64 {
    std::env::var(name)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default)
}

/// Random action rows, one per env, cycled through so sampling is not what is measured.
fn action_pool(env: &VecEnv) -> Vec<Vec<u8>> {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    (0..16).map(|_| env.sample_actions(&mut rng)).collect()
}

/// Env steps per second in lock step.
fn lock_step_rate(env: &mut VecEnv, seconds: f64) -> f64 {
    let pool = action_pool(env);
    env.reset(Some(0)).unwrap();
    for a in pool.iter().cycle().take(100) {
        env.step(a).unwrap();
    }
    let (start, mut steps) = (Instant::now(), 0usize);
    while start.elapsed().as_secs_f64() < seconds {
        for a in &pool {
            env.step(a).unwrap();
        }
        steps += pool.len() * env.num_envs();
    }
    steps as f64 / start.elapsed().as_secs_f64()
}

/// Env steps per second through `send`/`recv` with `batch_size` `m`.
fn env_pool_rate(env: &mut VecEnv, m: usize, seconds: f64) -> f64 {
    let ab = env.action_space().byte_len();
    let pool = action_pool(env);
    env.set_batch_size(m).unwrap();
    env.async_reset(Some(0)).unwrap();
    let mut round = |k: usize| {
        let ids = env.recv().unwrap().env_ids.to_vec();
        let a = &pool[k % pool.len()][..ids.len() * ab];
        env.send(a, &ids).unwrap();
    };
    for k in 0..200 {
        round(k);
    }
    let (start, mut k) = (Instant::now(), 0usize);
    while start.elapsed().as_secs_f64() < seconds {
        for _ in 0..16 {
            round(k);
            k += 1;
        }
    }
    (k * m) as f64 / start.elapsed().as_secs_f64()
}

#[test]
#[ignore = "a benchmark: run it with --ignored remote_pool_bench --nocapture"]
fn remote_pool_bench() {
    let n = knob("ENVHUB_BENCH_ENVS", 1024.0) as usize;
    let workers = knob("ENVHUB_BENCH_WORKERS", 2.0) as usize;
    let seconds = knob("ENVHUB_BENCH_SECONDS", 1.0);
    // Every lane count's session is open at once: no limit on what one client holds.
    let unlimited = [
        "--max-envs",
        "0",
        "--max-workers",
        "0",
        "--max-envs-per-client",
        "0",
        "--max-workers-per-client",
        "0",
        "--max-sessions-per-client",
        "0",
    ];
    // A Zenoh config file for both ends (e.g. another transport), to compare links.
    let zenoh_config = std::env::var("ENVHUB_BENCH_ZENOH_CONFIG").ok();
    let mut hub_args: Vec<&str> = unlimited.to_vec();
    if let Some(path) = &zenoh_config {
        hub_args.extend(["--zenoh-config", path.as_str()]);
    }
    let hub = RemoteHub::start("poolbench", &hub_args, &[]);
    let on_hub = Placement::Hubs(vec![hub.name.clone()]);
    let config = EnvConfig {
        workers: Some(workers),
        ..EnvConfig::default()
    };
    let local = TestHub::new("pool_bench_local");
    let mut here = local.hub.make_vec("gym-cartpole", n, &config).unwrap();
    let lanes: Vec<usize> = std::env::var("ENVHUB_BENCH_LANES")
        .unwrap_or_else(|_| "1,2".into())
        .split(',')
        .map(|k| {
            k.trim()
                .parse()
                .expect("ENVHUB_BENCH_LANES: lane counts, as `1,2,4`")
        })
        .collect();
    let mut remote: Vec<(usize, VecEnv)> = lanes
        .into_iter()
        .map(|lanes| {
            let mut c = client(&format!("bench{lanes}"), &[&hub]);
            if let Some(path) = &zenoh_config {
                let mut net = envhub_e2e::remote::net_to(&[&hub]);
                net.config = Some(path.into());
                c = c.with_network(net);
            }
            let options = SessionOptions {
                remote_lanes: lanes,
                ..c.options().clone()
            };
            let env = c
                .with_options(options)
                .make_vec_on("gym-cartpole", n, &config, &on_hub)
                .unwrap();
            (lanes, env)
        })
        .collect();
    // Alternated, best of three each: the machine is shared and its load drifts.
    let mut best = std::collections::BTreeMap::<String, f64>::new();
    let mut note = |name: String, rate: f64| {
        let e = best.entry(name).or_default();
        *e = e.max(rate);
    };
    for _ in 0..3 {
        note("here, lock step".into(), lock_step_rate(&mut here, seconds));
        here.reset(None).unwrap();
        note(
            format!("here, send/recv M={}", n / 2),
            env_pool_rate(&mut here, n / 2, seconds),
        );
        here.reset(None).unwrap();
        for (lanes, env) in &mut remote {
            note(
                format!("hub, {lanes} lane(s), lock step"),
                lock_step_rate(env, seconds),
            );
            env.reset(None).unwrap();
            let m = n / (*lanes).max(2);
            note(
                format!("hub, {lanes} lane(s), send/recv M={m}"),
                env_pool_rate(env, m, seconds),
            );
            env.reset(None).unwrap();
        }
    }
    let base = best["here, lock step"];
    println!("gym-cartpole x {n}, {workers} workers per machine, best of 3 x {seconds} s:");
    for (name, rate) in &best {
        println!(
            "  {name:<34} {rate:>12.0} steps/s  {:.2}x here's lock step",
            rate / base
        );
    }
}
