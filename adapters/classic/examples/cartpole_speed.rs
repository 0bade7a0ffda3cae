//! Steps per second of one `CartPole-v1` in a tight single-thread loop, resetting when an
//! episode terminates. Run with `cargo run --release -p envhub-classic --example cartpole_speed`.

use envhub_classic::CartPole;
use envhub_core::{Env, EnvConfig, Info, ResetOptions};
use std::time::Instant;

fn main() {
    let steps: u64 = std::env::args()
        .nth(1)
        .map_or(50_000_000, |s| s.parse().expect("steps must be a number"));
    let mut env = CartPole::new(&EnvConfig::default()).expect("default config is valid");
    let mut obs = [0u8; 16];
    let mut info = Info::default();
    let options = ResetOptions::new();
    env.reset(Some(0), &options, &mut obs, &mut info).unwrap();

    let start = Instant::now();
    let (mut episodes, mut total) = (0u64, 0.0);
    for i in 0..steps {
        // A cheap pseudo-random action that does not dominate the step's cost.
        let action = ((i.wrapping_mul(0x9E37_79B9_7F4A_7C15) >> 63) as i64).to_le_bytes();
        let t = env.step(&action, &mut obs, &mut info).unwrap();
        total += t.reward;
        if t.terminated {
            env.reset(None, &options, &mut obs, &mut info).unwrap();
            episodes += 1;
        }
    }
    let secs = start.elapsed().as_secs_f64();
    println!(
        "{steps} steps, {episodes} episodes, reward {total} in {secs:.3} s: {:.1} M steps/s ({:.1} ns/step)",
        steps as f64 / secs / 1e6,
        secs * 1e9 / steps as f64
    );
}
