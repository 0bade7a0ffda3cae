//! The worker loop: open the channel, report ready, answer reset/step/render/close until
//! closed or the owner exits. Shared by the Rust worker binary and the Python worker
//! (`python -m envhub.worker`, through the `envhub._envhub` bindings), so both speak the
//! same protocol and only differ in what their envs are.

use crate::{
    DataPlaneError, EnvBatch, Layout, ProcessWatch, ReadySpec, Reply, WaitPolicy, WorkerChannel,
    WorkerJob, WorkerReply, command,
};
use envhub_core::{AutoresetMode, ResetOptions};
use std::time::Duration;

/// Serves `batch` for `job` until the client closes it or its owner exits. `reply` prints the
/// one ready (or error) line the owner waits for. A channel that cannot be opened is reported
/// through `reply`, not returned.
pub fn serve_batch(
    job: &WorkerJob,
    mut batch: EnvBatch,
    ready: ReadySpec,
    mut reply: impl FnMut(&WorkerReply) -> std::io::Result<()>,
) -> Result<(), DataPlaneError> {
    let io =
        |e: std::io::Error| DataPlaneError::PeerGone(format!("cannot reply to the owner: {e}"));
    let layout = Layout::new(
        job.num_envs,
        ready.observation_space.byte_len(),
        ready.action_space.byte_len(),
        job.config.autoreset_mode == AutoresetMode::SameStep,
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
            return reply(&WorkerReply::Error(format!(
                "cannot open the data plane: {e}"
            )))
            .map_err(io);
        }
    };
    let owner = ProcessWatch::new(job.owner_pid).map_err(|e| {
        DataPlaneError::PeerGone(format!("the owner process {} is gone: {e}", job.owner_pid))
    })?;
    reply(&WorkerReply::Ready(ready)).map_err(io)?;
    tracing::debug!(envs = job.num_envs, "worker ready");

    let alive = || {
        if owner.exited() {
            Err(DataPlaneError::PeerGone(format!(
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
            Err(DataPlaneError::PeerGone(why)) => {
                tracing::debug!(%why, "owner gone, exiting");
                batch.close();
                return Ok(());
            }
            Err(e) => return Err(e),
        }
    }
}
