//! In one thread, with no IPC: how long creating and resetting `N` envs takes, and how many
//! env steps per second they run with random actions (the raw ceiling `envhub bench` compares
//! with). Run with
//! `cargo run --release -p envhub-mujoco --features libmujoco --example mujoco_speed -- Ant-v5 8`.

use envhub_core::{Env, EnvConfig, Info, ResetOptions};
use envhub_mujoco::Mujoco;
use rand::SeedableRng;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let env_id = args.next().unwrap_or_else(|| "Ant-v5".into());
    let n: usize = args
        .next()
        .map_or(8, |s| s.parse().expect("a number of envs"));
    let steps: usize = args
        .next()
        .map_or(2000, |s| s.parse().expect("a number of steps"));

    let start = Instant::now();
    let adapter = Mujoco::default();
    let mut envs: Vec<_> = (0..n)
        .map(|_| adapter.make_mujoco(&env_id, &EnvConfig::default()).unwrap())
        .collect();
    let obs_len = envs[0].observation_space().byte_len();
    let mut obs = vec![0u8; obs_len];
    let mut info = Info::default();
    for (i, env) in envs.iter_mut().enumerate() {
        env.reset(Some(i as u64), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
    }
    let made = start.elapsed();

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(0);
    let actions: Vec<Vec<u8>> = (0..64)
        .map(|_| envs[0].action_space().sample(&mut rng))
        .collect();
    let start = Instant::now();
    for s in 0..steps {
        for env in &mut envs {
            info.clear();
            let t = env.step(&actions[s % 64], &mut obs, &mut info).unwrap();
            if t.terminated {
                env.reset(None, &ResetOptions::new(), &mut obs, &mut info)
                    .unwrap();
            }
        }
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{env_id}: make + reset of {n} envs {:.1} ms (assets lookup included); \
         {:.0} env steps/s on one thread",
        made.as_secs_f64() * 1e3,
        (n * steps) as f64 / secs
    );
}
