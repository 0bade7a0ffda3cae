//! `envhub record` and `envhub run --video`: recording lives in the Python package
//! (`python -m envhub.recording`: LeRobot datasets, MP4s through PyAV, a writer thread off the
//! stepping path), which this runs with the hub's interpreter — one implementation for the
//! command line and Python users, and no video encoder linked into the hub.

use super::Outcome;
use anyhow::Context;
use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `python -m envhub.recording`'s exit status when it kept fewer episodes than asked.
const FEWER_EPISODES: i32 = 3;

#[derive(clap::Args, Debug)]
pub(crate) struct Args {
    /// Registry id (`mujoco-ant`).
    id: String,
    /// Episodes to keep.
    #[arg(long, default_value_t = 1)]
    episodes: usize,
    /// The dataset's folder (LeRobot v3.0): created, or appended to when it holds a dataset of
    /// the same layout.
    #[arg(long, value_name = "DIR")]
    out: PathBuf,
    /// Envs stepped at once.
    #[arg(long, default_value_t = 1)]
    num_envs: usize,
    /// The policy, a Python callable `module:function` taking the batch of observations (and,
    /// if it has two parameters, the action space) and returning a batch of actions; default:
    /// random actions.
    #[arg(long, value_name = "MODULE:FUNCTION")]
    policy: Option<String>,
    /// Keep only episodes whose last info says `success` / `is_success`.
    #[arg(long)]
    success_only: bool,
    /// No video of `render()` frames (camera observations are still recorded).
    #[arg(long)]
    no_video: bool,
    /// Seed of the first reset and of the random policy.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Stop after this many batched steps, however many episodes were kept.
    #[arg(long)]
    max_steps: Option<u64>,
    /// Frames per second of the dataset (default: the env's `render_fps`).
    #[arg(long)]
    fps: Option<u32>,
    /// Video encoder: `libx264` (default), `libsvtav1`, `libaom-av1`, `libopenh264`.
    #[arg(long)]
    codec: Option<String>,
    /// When the writer falls behind: steps `wait` for it, or `drop` (the episodes in flight).
    #[arg(long, value_name = "wait|drop", default_value = "wait")]
    when_full: String,
}

/// The hub's interpreter set to run `python -m MODULE` (arguments to add), with the command
/// line's registries and config file: how `envhub record` and `envhub eval` reach the Python
/// package. Returns the interpreter too, for messages.
pub(crate) fn python_module(
    module: &str,
    registries: &[PathBuf],
    config: Option<&Path>,
) -> anyhow::Result<(PathBuf, Command)> {
    let python = envhub_hub::python_interpreter();
    let mut command = Command::new(&python);
    command.args(["-m", module]);
    if !registries.is_empty() {
        let joined = std::env::join_paths(registries).context("registry paths")?;
        command.env(envhub_hub::env_vars::ENVHUB_REGISTRY, joined);
    }
    if let Some(config) = config {
        command.env(envhub_hub::env_vars::ENVHUB_CONFIG, config);
    }
    Ok((python, command))
}

/// The hub's interpreter running `python -m envhub.recording ARGS`, with the command line's
/// registries and config file.
fn recorder(
    registries: &[PathBuf],
    config: Option<&Path>,
    args: &[OsString],
) -> anyhow::Result<Outcome> {
    let (python, mut command) = python_module("envhub.recording", registries, config)?;
    let status = command.args(args).status().with_context(|| {
        format!(
            "cannot run `{} -m envhub.recording`\nhint: recording runs in the Python package: set ENVHUB_PYTHON to an interpreter with `envhub[record]` installed",
            python.display()
        )
    })?;
    match status.code() {
        Some(0) => Ok(Outcome::Done),
        // Fewer episodes than asked (`--max-steps`); the recorder said how many.
        Some(FEWER_EPISODES) => Ok(Outcome::NotFound),
        // The recorder printed its own `error: ...` (or that it was interrupted).
        Some(2) => anyhow::bail!("recording failed"),
        Some(130) => anyhow::bail!("recording interrupted"),
        _ => anyhow::bail!(
            "recording failed ({status})\nhint: the recorder runs as `{} -m envhub.recording`: set ENVHUB_PYTHON to an interpreter with the envhub package and `envhub[record]`",
            python.display()
        ),
    }
}

pub(crate) fn run(
    registries: &[PathBuf],
    config: Option<&Path>,
    args: &Args,
) -> anyhow::Result<Outcome> {
    let mut argv: Vec<OsString> = vec![
        args.id.clone().into(),
        "--episodes".into(),
        args.episodes.to_string().into(),
        "--out".into(),
        args.out.clone().into(),
        "--num-envs".into(),
        args.num_envs.to_string().into(),
        "--seed".into(),
        args.seed.to_string().into(),
        "--when-full".into(),
        args.when_full.clone().into(),
    ];
    if let Some(policy) = &args.policy {
        argv.extend(["--policy".into(), policy.into()]);
    }
    if let Some(steps) = args.max_steps {
        argv.extend(["--max-steps".into(), steps.to_string().into()]);
    }
    if let Some(fps) = args.fps {
        argv.extend(["--fps".into(), fps.to_string().into()]);
    }
    if let Some(codec) = &args.codec {
        argv.extend(["--codec".into(), codec.into()]);
    }
    if args.success_only {
        argv.push("--success-only".into());
    }
    if args.no_video {
        argv.push("--no-video".into());
    }
    recorder(registries, config, &argv)
}

/// `envhub run ID --video FILE`: one env's `render()` frames over `steps` random steps.
pub(crate) fn video(
    registries: &[PathBuf],
    config: Option<&Path>,
    id: &str,
    path: &Path,
    steps: usize,
) -> anyhow::Result<Outcome> {
    let argv: Vec<OsString> = vec![
        id.into(),
        "--video".into(),
        path.into(),
        "--steps".into(),
        steps.to_string().into(),
    ];
    recorder(registries, config, &argv)
}
