//! `serve`: create the envs, then run the shared worker loop ([`envhub_shm::serve_batch`]).

use crate::adapters;
use anyhow::Context;
use envhub_core::{EnvError, TimeLimit};
use envhub_shm::{EnvBatch, ReadySpec, WorkerJob, WorkerReply};
use std::io::Write;

/// Creates a job's envs, each wrapped in the episode limit.
pub(crate) fn make_envs(job: &WorkerJob) -> Result<(EnvBatch, ReadySpec), String> {
    let adapter = adapters::by_name(&job.adapter).ok_or_else(|| {
        let names: Vec<&str> = adapters::listed().iter().map(|a| a.name()).collect();
        format!(
            "this worker has no adapter `{}`\nhint: it hosts: {}",
            job.adapter,
            names.join(", ")
        )
    })?;
    if let envhub_core::Availability::Unavailable { reason, hint } = adapter.availability() {
        return Err(EnvError::Unavailable {
            adapter: job.adapter.clone(),
            reason,
            hint,
        }
        .to_string());
    }
    let spec = adapter
        .spec(&job.env_id, &job.config)
        .map_err(|e| e.to_string())?;
    let limit = job.config.episode_limit(spec.max_episode_steps);
    let mut envs = Vec::with_capacity(job.worker_envs);
    for _ in 0..job.worker_envs {
        let env = adapter
            .make(&job.env_id, &job.config)
            .map_err(|e| e.to_string())?;
        envs.push(Box::new(TimeLimit::new(env, limit)) as Box<dyn envhub_core::Env>);
    }
    let ready = ReadySpec {
        observation_space: spec.observation_space,
        action_space: spec.action_space,
        max_episode_steps: limit,
        render_fps: envs.first().and_then(|env| env.render_fps()),
        pid: std::process::id(),
        worker: std::env::current_exe()
            .ok()
            .map(envhub_shm::WorkerIdentity::current),
    };
    Ok((EnvBatch::new(envs, job.config.autoreset_mode), ready))
}

fn reply(line: &WorkerReply) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    serde_json::to_writer(&mut out, line)?;
    out.write_all(b"\n")?;
    out.flush()?;
    Ok(())
}

/// Answers the hub that the job cannot be served, as a job whose envs cannot be made is.
pub(crate) fn refuse(message: String) -> anyhow::Result<()> {
    reply(&WorkerReply::Error(message))
}

pub(crate) fn run(job_json: &str) -> anyhow::Result<()> {
    let job: WorkerJob = serde_json::from_str(job_json).context("invalid job")?;
    let span = tracing::info_span!("worker", adapter = %job.adapter, env_id = %job.env_id, pid = std::process::id());
    let _guard = span.enter();
    let (batch, ready) = match make_envs(&job) {
        Ok(made) => made,
        Err(message) => {
            reply(&WorkerReply::Error(message))?;
            return Ok(());
        }
    };
    envhub_shm::serve_batch(&job, batch, ready, |line| {
        reply(line).map_err(std::io::Error::other)
    })?;
    Ok(())
}
