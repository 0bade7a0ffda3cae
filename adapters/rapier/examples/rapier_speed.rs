//! In one thread, with no IPC: env steps per second of each rapier task with random actions
//! (episodes reset when they end), and the time to render one 240 × 240 frame. Run with
//! `cargo run --release -p envhub-rapier --example rapier_speed -- [env_id] [steps]`.

use envhub_core::{Env, EnvAdapter, EnvConfig, Info, ResetOptions, TimeLimit};
use envhub_rapier::Rapier;
use std::time::Instant;

fn main() {
    let mut args = std::env::args().skip(1);
    let ids = match args.next() {
        Some(id) => vec![id],
        None => Rapier.list_envs(),
    };
    let steps: usize = args
        .next()
        .map_or(4000, |s| s.parse().expect("a number of steps"));
    for env_id in ids {
        let spec = Rapier.spec(&env_id, &EnvConfig::default()).unwrap();
        let mut env = TimeLimit::new(
            Rapier.make(&env_id, &EnvConfig::default()).unwrap(),
            spec.max_episode_steps,
        );
        let mut obs = vec![0u8; env.observation_space().byte_len()];
        let mut info = Info::default();
        let n_act = env.action_space().num_elements();
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut action = vec![0u8; n_act * 4];
        env.reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        let start = Instant::now();
        for _ in 0..steps {
            for a in action.chunks_exact_mut(4) {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                let x = (state >> 40) as f32 / (1u64 << 24) as f32 * 2.0 - 1.0;
                a.copy_from_slice(&x.to_le_bytes());
            }
            let t = env.step(&action, &mut obs, &mut info).unwrap();
            if t.terminated || t.truncated {
                env.reset(None, &ResetOptions::new(), &mut obs, &mut info)
                    .unwrap();
            }
        }
        let rate = steps as f64 / start.elapsed().as_secs_f64();
        // One 240 x 240 frame of the state reached.
        let config = EnvConfig {
            render_mode: Some("rgb_array".into()),
            ..EnvConfig::default()
        };
        let mut renderer = Rapier.make(&env_id, &config).unwrap();
        renderer
            .reset(Some(0), &ResetOptions::new(), &mut obs, &mut info)
            .unwrap();
        let start = Instant::now();
        let frames = 5;
        for _ in 0..frames {
            renderer.render().unwrap().unwrap();
        }
        let frame_ms = start.elapsed().as_secs_f64() * 1e3 / f64::from(frames);
        println!(
            "{env_id:16} {rate:8.0} steps/s (one thread, random actions), {frame_ms:5.1} ms a 240x240 frame"
        );
    }
}
