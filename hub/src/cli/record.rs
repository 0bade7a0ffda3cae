//! `envhub record` and `envhub run --video`: recording lives in the Python package
//! (`python -m envhub.record`: LeRobot datasets, MP4 through PyAV, a writer off the hot path),
//! which this runs with the hub's interpreter — one implementation for the CLI and Python
//! users, and no video encoder linked into the hub.

use super::Outcome;
use anyhow::Context;
use std::path::{Path, PathBuf};
use std::process::Command;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Registry id (`mujoco-ant`).
    id: String,
    /// Episodes to keep.
    #[arg(long, default_value_t = 1)]
    episodes: usize,
    /// The dataset's folder (created, or appended to when it holds a dataset of this layout).
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Envs stepped at once.
    #[arg(long, default_value_t = 1)]
    num_envs: usize,
    /// The policy, as `module:function` (a callable taking the batched observation and
    /// returning actions); default: random actions.
    #[arg(long, value_name = "MODULE:FUNCTION")]
    policy: Option<String>,
    /// Keep only episodes whose info says `success` / `is_success`.
    #[arg(long)]
    success_only: bool,
    /// No video of `render()` frames (camera observations are still encoded).
    #[arg(long)]
    no_video: bool,
    /// Episode limit (default: the entry's).
    #[arg(long)]
    max_episode_steps: Option<u32>,
    /// Seed of the first reset and of the random policy.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// The hub's interpreter running `python -m envhub.record ARGS`, with the CLI's registries.
fn recorder(registries: &[PathBuf], args: &[String]) -> anyhow::Result<Outcome> {
    let python = envhub::python_interpreter();
    let mut command = Command::new(&python);
    command.args(["-m", "envhub.record"]).args(args);
    if !registries.is_empty() {
        let joined = std::env::join_paths(registries).context("registry paths")?;
        command.env(envhub::env_vars::ENVHUB_REGISTRY, joined);
    }
    let status = command.status().with_context(|| {
        format!(
            "cannot run `{} -m envhub.record`\nhint: recording runs in the Python package: set ENVHUB_PYTHON to an interpreter with `envhub[record]` installed",
            python.display()
        )
    })?;
    if !status.success() {
        anyhow::bail!("recording failed ({status})");
    }
    Ok(Outcome::Done)
}

pub(crate) fn run(registries: &[PathBuf], args: &Args) -> anyhow::Result<Outcome> {
    let mut argv = vec![
        args.id.clone(),
        "--episodes".into(),
        args.episodes.to_string(),
        "--out".into(),
        args.out.display().to_string(),
        "--num-envs".into(),
        args.num_envs.to_string(),
    ];
    if let Some(policy) = &args.policy {
        argv.extend(["--policy".into(), policy.clone()]);
    }
    if args.success_only {
        argv.push("--success-only".into());
    }
    if args.no_video {
        argv.push("--no-video".into());
    }
    if let Some(limit) = args.max_episode_steps {
        argv.extend(["--max-episode-steps".into(), limit.to_string()]);
    }
    argv.extend(["--seed".into(), args.seed.to_string()]);
    recorder(registries, &argv)
}

/// `envhub run ID --video PATH`: the first env's `render()` frames of a random rollout.
pub(crate) fn video(
    registries: &[PathBuf],
    id: &str,
    path: &Path,
    steps: usize,
) -> anyhow::Result<Outcome> {
    recorder(
        registries,
        &[
            id.to_string(),
            "--video".into(),
            path.display().to_string(),
            "--steps".into(),
            steps.to_string(),
        ],
    )
}
