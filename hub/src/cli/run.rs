//! `envhub run`: a random-policy rollout through the hub.

use super::Outcome;
use envhub::Hub;
use envhub_core::EnvConfig;
use rand::SeedableRng;
use std::io::{IsTerminal, Write};
use std::time::Instant;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Registry id (`gym-cartpole`).
    id: String,
    /// Envs in the batch.
    #[arg(long, default_value_t = 8)]
    num_envs: usize,
    /// Worker processes (default: one per core, at most one per env).
    #[arg(long)]
    workers: Option<usize>,
    /// Env steps in total (over all envs; default 100000), or with `--video` the video's
    /// frames (default 300).
    #[arg(long)]
    steps: Option<usize>,
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
    /// Instead, write one env's `render()` frames to this MP4 (recorded by the Python package,
    /// as `envhub record` is).
    #[arg(long, value_name = "FILE")]
    video: Option<std::path::PathBuf>,
}

impl Args {
    /// `--video`: the file, the env id, the frames and the seed.
    pub(crate) fn video(&self) -> Option<(&std::path::Path, &str, usize, u64)> {
        let path = self.video.as_deref()?;
        Some((path, &self.id, self.steps.unwrap_or(300), self.seed))
    }
}

pub(crate) fn run(hub: &Hub, args: &Args) -> anyhow::Result<Outcome> {
    let config = EnvConfig {
        workers: args.workers,
        ..EnvConfig::default()
    };
    let placement: envhub::Placement = args.hub.parse()?;
    let mut env = hub.make_vec_on(&args.id, args.num_envs, &config, &placement)?;
    let n = env.num_envs();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let batches = args.steps.unwrap_or(100_000).div_ceil(n).max(1);
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
