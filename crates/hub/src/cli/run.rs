//! `envhub run`: a random-policy rollout through the hub.

use super::Outcome;
use envhub_core::EnvConfig;
use envhub_hub::Hub;
use rand::SeedableRng;
use std::io::{IsTerminal, Write};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Registry id (`gym-cartpole`).
    pub(crate) id: String,
    /// Envs in the batch.
    #[arg(long, default_value_t = 8)]
    num_envs: usize,
    /// Worker processes (default: one per core, at most one per env).
    #[arg(long)]
    workers: Option<usize>,
    /// Env steps in total (over all envs).
    #[arg(long, default_value_t = 100_000)]
    steps: usize,
    /// Seed of the first reset (env i gets seed + i) and of the random policy.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Print `{"id", "steps", "seconds", "steps_per_sec", "episodes", "mean_return"}`.
    #[arg(long)]
    json: bool,
    /// Where the envs run: `local` (default), a hub's name, `all` live hubs, a list
    /// (`box1,box2,local`: spread by cores) or counts (`box1:48,box2:16`).
    #[arg(long, value_name = "HUBS", default_value = "local")]
    hub: String,
    /// Write the first env's `render()` frames of a random rollout to this MP4 instead (a
    /// quick look at an env; through the Python package's recorder).
    #[arg(long, value_name = "FILE.mp4")]
    pub(crate) video: Option<std::path::PathBuf>,
    /// Steps of the video (`--video`).
    #[arg(long, default_value_t = 300)]
    pub(crate) video_steps: usize,
}

pub(crate) fn run(hub: &Hub, args: &Args) -> anyhow::Result<Outcome> {
    let config = EnvConfig {
        workers: args.workers,
        ..EnvConfig::default()
    };
    let placement: envhub_hub::Placement = args.hub.parse()?;
    let mut env = hub.make_vec_on(&args.id, args.num_envs, &config, &placement)?;
    let n = env.num_envs();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let batches = args.steps.div_ceil(n).max(1);
    let mut returns = vec![0.0f64; n];
    let (mut episodes, mut return_sum) = (0usize, 0.0f64);
    let progress = !args.json && std::io::stderr().is_terminal();
    let start = Instant::now();
    env.reset(Some(args.seed))?;
    for b in 0..batches {
        let actions = env.sample_actions(&mut rng);
        let batch = env.step(&actions)?;
        for (i, ret) in returns.iter_mut().enumerate() {
            *ret += batch.rewards[i];
            if batch.terminated[i] || batch.truncated[i] {
                episodes += 1;
                return_sum += *ret;
                *ret = 0.0;
            }
        }
        if progress && (b % 64 == 0 || b + 1 == batches) {
            let done = (b + 1) as f64 / batches as f64;
            let bar = "#".repeat((done * 30.0) as usize);
            eprint!(
                "\r[{bar:<30}] {:>3.0}%  {} steps",
                done * 100.0,
                (b + 1) * n
            );
            let _ = std::io::stderr().flush();
        }
    }
    let seconds = start.elapsed().as_secs_f64();
    env.close();
    if progress {
        eprintln!();
    }
    let steps = batches * n;
    let mean_return = if episodes > 0 {
        Some(return_sum / episodes as f64)
    } else {
        None
    };
    if args.json {
        println!(
            "{}",
            serde_json::json!({
                "id": args.id,
                "steps": steps,
                "seconds": seconds,
                "steps_per_sec": steps as f64 / seconds,
                "episodes": episodes,
                "mean_return": mean_return,
            })
        );
    } else {
        println!(
            "{}: {steps} steps in {seconds:.2} s ({:.0} steps/s) over {n} envs",
            args.id,
            steps as f64 / seconds
        );
        match mean_return {
            Some(m) => println!("{episodes} episodes, mean return {m:.2}"),
            None => println!("no episode finished"),
        }
    }
    Ok(Outcome::Done)
}
