//! `serve`: create the envs, open the channel, report ready, answer requests until closed.

use crate::adapters;
use anyhow::Context;
use envhub_core::{EnvError, ResetOptions, TimeLimit};
use envhub_shm::{
    EnvBatch, Layout, ProcessWatch, ReadySpec, Reply, WaitPolicy, WorkerChannel, WorkerJob,
    WorkerReply, command,
};
use std::io::Write;
use std::time::Duration;

/// Creates a job's envs, each wrapped in the episode limit.
pub(crate) fn make_envs(job: &WorkerJob) -> Result<(EnvBatch, ReadySpec), String> {
    let adapter = adapters::by_name(&job.adapter).ok_or_else(|| {
        let names: Vec<&str> = adapters::all().iter().map(|a| a.name()).collect();
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
    let mut envs = Vec::with_capacity(job.num_envs);
    for _ in 0..job.num_envs {
        let env = adapter
            .make(&job.env_id, &job.config)
            .map_err(|e| e.to_string())?;
        envs.push(Box::new(TimeLimit::new(env, limit)) as Box<dyn envhub_core::Env>);
    }
    let ready = ReadySpec {
        observation_space: spec.observation_space,
        action_space: spec.action_space,
        max_episode_steps: limit,
        pid: std::process::id(),
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

pub(crate) fn run(job_json: &str) -> anyhow::Result<()> {
    let job: WorkerJob = serde_json::from_str(job_json).context("invalid job")?;
    let span = tracing::info_span!("worker", adapter = %job.adapter, env_id = %job.env_id, pid = std::process::id());
    let _guard = span.enter();
    let (mut batch, ready) = match make_envs(&job) {
        Ok(made) => made,
        Err(message) => {
            reply(&WorkerReply::Error(message))?;
            return Ok(());
        }
    };
    let layout = Layout::new(
        job.num_envs,
        ready.observation_space.byte_len(),
        ready.action_space.byte_len(),
        job.config.autoreset_mode == envhub_core::AutoresetMode::SameStep,
    );
    let policy = WaitPolicy {
        spin: Duration::from_micros(job.spin_us),
        max_spin: Duration::from_micros(job.max_spin_us),
        tick: Duration::from_millis(50),
    };
    let node_name = format!("worker-{}", std::process::id());
    let mut channel = match WorkerChannel::open(&job.channel, &node_name, layout, policy) {
        Ok(c) => c,
        Err(e) => {
            reply(&WorkerReply::Error(format!(
                "cannot open the data plane: {e}"
            )))?;
            return Ok(());
        }
    };
    let owner = ProcessWatch::new(job.owner_pid).context("the owner process is gone")?;
    reply(&WorkerReply::Ready(ready))?;
    tracing::debug!(envs = job.num_envs, "worker ready");

    let alive = || {
        if owner.exited() {
            Err(envhub_shm::DataPlaneError::PeerGone(format!(
                "owner process {} exited",
                owner.pid()
            )))
        } else {
            Ok(())
        }
    };
    loop {
        let outcome = channel.serve_one(alive, |req, out| match req.header.command {
            command::RESET => {
                let options: ResetOptions = if req.options.is_empty() {
                    ResetOptions::new()
                } else {
                    match serde_json::from_str(req.options) {
                        Ok(o) => o,
                        Err(e) => return Reply::Error(format!("invalid reset options: {e}")),
                    }
                };
                match batch.reset(req.flags, req.seeds, &options, out) {
                    Ok(info) => Reply::Ok { info },
                    Err(e) => Reply::Error(e.to_string()),
                }
            }
            command::STEP => match batch.step(req.flags, req.actions, out) {
                Ok(info) => Reply::Ok { info },
                Err(e) => Reply::Error(e.to_string()),
            },
            command::RENDER => match batch.render(req.flags) {
                Ok(info) => Reply::Ok { info },
                Err(e) => Reply::Error(e.to_string()),
            },
            command::CLOSE => {
                batch.close();
                Reply::Closed
            }
            other => Reply::Error(format!("unknown command {other}")),
        });
        match outcome {
            Ok(command::CLOSE) => return Ok(()),
            Ok(_) => {}
            Err(envhub_shm::DataPlaneError::PeerGone(why)) => {
                tracing::debug!(%why, "owner gone, exiting");
                batch.close();
                return Ok(());
            }
            Err(e) => return Err(e.into()),
        }
    }
}
