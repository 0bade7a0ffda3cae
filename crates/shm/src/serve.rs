//! The worker loop: open the channel, report ready, answer reset/step/render/close until
//! closed or the owner exits. Shared by the Rust worker binary and the Python worker
//! (`python -m envhub.worker`, through the `envhub._envhub` bindings), so both speak the
//! same protocol and only differ in what their envs are.

use crate::{
    BatchLayout, DataPlaneError, Doorbells, Layout, ProcessWatch, ReadySpec, Reply,
    ResponseBlocksMut, SlotMap, WaitPolicy, WorkerChannel, WorkerJob, WorkerReply, command,
};
use envhub_core::{AutoresetMode, EnvError, ResetOptions};
use std::time::Duration;

/// What the worker loop serves: all of one worker's envs, answering each request for the
/// whole batch at once.
///
/// `EnvBatch` (in `batch`) implements it over one [`Env`](envhub_core::Env) per env and
/// applies the autoreset mode itself; a simulator that holds its envs in one object, steps
/// them together and autoresets them itself (a Gymnasium `VectorEnv`, Isaac Lab) implements
/// it directly. Every method that answers with blocks writes every block the client reads for
/// that command, for every env (samples are reused, so nothing is zero on arrival).
pub trait ServedBatch {
    /// Number of envs; must equal the job's `num_envs`.
    fn len(&self) -> usize;

    /// Whether there are no envs.
    fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Resets the envs whose flag has [`env_flag::SELECTED`](crate::env_flag::SELECTED),
    /// seeding those with [`env_flag::SEEDED`](crate::env_flag::SEEDED). Returns the info
    /// section (`[{...}, ...]`, one JSON object per env; empty when no env reported info).
    fn reset(
        &mut self,
        flags: &[u8],
        seeds: &[u64],
        options: &ResetOptions,
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError>;

    /// Steps the selected envs with their actions (`act_bytes` per env, back to back) under
    /// the job's autoreset mode. Returns the info section.
    fn step(
        &mut self,
        flags: &[u8],
        actions: &[u8],
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError>;

    /// Renders the selected envs: for each, in order, a `u32` height, a `u32` width (both 0:
    /// nothing rendered) and `height × width × 3` RGB bytes, all little-endian.
    fn render(&mut self, flags: &[u8]) -> Result<Vec<u8>, EnvError>;

    /// Closes every env.
    fn close(&mut self);

    /// The envs whose last reset or step failed while the others went on, with the errors
    /// (`(index, message)`), taken out of the batch. A batch that fails as a whole returns
    /// `Err` instead; this is for one env's failure that must not cost the others their step.
    fn take_failures(&mut self) -> Vec<(usize, String)> {
        Vec::new()
    }
}

/// The reply to a reset or step: the results, or which envs failed.
fn answer(batch: &mut impl ServedBatch, result: Result<Vec<u8>, EnvError>) -> Reply {
    match result {
        Ok(info) => {
            let failed = batch.take_failures();
            if failed.is_empty() {
                Reply::Ok { info }
            } else {
                Reply::EnvFailed { failed, info }
            }
        }
        Err(e) => Reply::Error(e.to_string()),
    }
}

/// Serves `batch` for `job` until the client closes it or its owner exits. `reply` prints the
/// one ready (or error) line the owner waits for. A channel that cannot be opened, or a batch
/// whose size is not the job's, is reported through `reply`, not returned.
pub fn serve_batch(
    job: &WorkerJob,
    mut batch: impl ServedBatch,
    ready: ReadySpec,
    mut reply: impl FnMut(&WorkerReply) -> std::io::Result<()>,
) -> Result<(), DataPlaneError> {
    let io =
        |e: std::io::Error| DataPlaneError::PeerGone(format!("cannot reply to the owner: {e}"));
    if batch.len() != job.worker_envs {
        batch.close();
        return reply(&WorkerReply::Error(format!(
            "the worker made {} envs for a job of {}\nhint: a batch must hold exactly the job's `num_envs`",
            batch.len(),
            job.worker_envs
        )))
        .map_err(io);
    }
    if job.env_offset + job.worker_envs > job.session_envs {
        batch.close();
        return reply(&WorkerReply::Error(format!(
            "envs {}..{} of a session of {}",
            job.env_offset,
            job.env_offset + job.worker_envs,
            job.session_envs
        )))
        .map_err(io);
    }
    let layout = Layout::new(job.worker_envs, ready.action_space.byte_len());
    let plain = BatchLayout::new(
        job.session_envs,
        ready.observation_space.byte_len(),
        job.config.autoreset_mode == AutoresetMode::SameStep,
    );
    let Some(batch_layout) = plain.with_info_columns(job.info_row_bytes) else {
        batch.close();
        return reply(&WorkerReply::Error(format!(
            "info columns of {} bytes per env do not fit a slot\nhint: a multiple of 8, well under the memory size",
            job.info_row_bytes
        )))
        .map_err(io);
    };
    let slots = SlotMap::new(job.slots.clone(), batch_layout);
    let policy = WaitPolicy {
        spin: Duration::from_micros(job.spin_us),
        max_spin: Duration::from_micros(job.max_spin_us),
        tick: Duration::from_millis(50),
        block_beyond: Duration::ZERO,
    };
    let node_name = format!("worker-{}", std::process::id());
    let mut channel = match WorkerChannel::open(
        &job.channel,
        &node_name,
        layout,
        slots,
        job.env_offset,
        policy,
    ) {
        Ok(c) => c,
        Err(e) => {
            return reply(&WorkerReply::Error(format!(
                "cannot open the data plane: {e}"
            )))
            .map_err(io);
        }
    };
    if job.session_workers > 0 {
        // The client rings only workers whose flag says they are blocked, so a worker without
        // its doorbell would wait out every tick: that is a start-up error, not a fallback.
        match Doorbells::open(&job.slots, job.session_workers)
            .and_then(|b| b.bell(job.worker_index))
        {
            Ok(bell) => channel.set_bell(bell),
            Err(e) => {
                batch.close();
                return reply(&WorkerReply::Error(format!(
                    "cannot open the session's doorbells: {e}"
                )))
                .map_err(io);
            }
        }
    }
    let owner = ProcessWatch::new(job.owner_pid).map_err(|e| {
        DataPlaneError::PeerGone(format!("the owner process {} is gone: {e}", job.owner_pid))
    })?;
    reply(&WorkerReply::Ready(ready)).map_err(io)?;
    tracing::debug!(envs = job.worker_envs, "worker ready");

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
        let outcome = channel.serve_one(alive, |req, out| match (req.header.command, out) {
            (command::RESET, Some(out)) => {
                let options: ResetOptions = if req.options.is_empty() {
                    ResetOptions::new()
                } else {
                    match serde_json::from_str(req.options) {
                        Ok(o) => o,
                        Err(e) => return Reply::Error(format!("invalid reset options: {e}")),
                    }
                };
                let result = batch.reset(req.flags, req.seeds, &options, out);
                answer(&mut batch, result)
            }
            (command::STEP, Some(out)) => {
                let result = batch.step(req.flags, req.actions, out);
                answer(&mut batch, result)
            }
            (command::RENDER, _) => match batch.render(req.flags) {
                Ok(info) => Reply::Ok { info },
                Err(e) => Reply::Error(e.to_string()),
            },
            (command::CLOSE, _) => {
                batch.close();
                Reply::Closed
            }
            (command::RESET | command::STEP, None) => {
                Reply::Error("a reset or step request must name a batch slot".into())
            }
            (other, _) => Reply::Error(format!("unknown command {other}")),
        });
        match outcome {
            Ok(command::CLOSE) => return Ok(()),
            Ok(_) => {}
            Err(DataPlaneError::PeerGone(why)) => {
                tracing::debug!(%why, "owner gone, exiting");
                batch.close();
                // The owner could not close the session: remove what it left in shared memory.
                channel.slots().name().unlink_all();
                let _ = crate::cleanup_dead_nodes(&job.channel.prefix);
                return Ok(());
            }
            Err(e) => return Err(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{
        ChannelName, ClientChannel, SlotPool, SlotsName, env_flag, remove_namespace, status,
    };
    use envhub_core::{EnvConfig, Space};
    use std::sync::mpsc;

    /// A batch that, like a vectorised simulator, only steps all its envs together: every
    /// observation is the step count, every reward the env's action.
    struct Lockstep {
        num_envs: usize,
        t: f32,
    }

    impl ServedBatch for Lockstep {
        fn len(&self) -> usize {
            self.num_envs
        }

        fn reset(
            &mut self,
            _flags: &[u8],
            _seeds: &[u64],
            _options: &ResetOptions,
            out: &mut ResponseBlocksMut<'_>,
        ) -> Result<Vec<u8>, EnvError> {
            self.t = 0.0;
            out.obs.fill(0);
            out.rewards.fill(0.0);
            out.terminated.fill(0);
            out.truncated.fill(0);
            out.final_mask.fill(0);
            Ok(Vec::new())
        }

        fn step(
            &mut self,
            flags: &[u8],
            actions: &[u8],
            out: &mut ResponseBlocksMut<'_>,
        ) -> Result<Vec<u8>, EnvError> {
            if flags.iter().any(|f| f & env_flag::SELECTED == 0) {
                return Err(EnvError::Simulator {
                    env_id: "Lockstep-v0".into(),
                    reason: "it steps its envs together".into(),
                });
            }
            self.t += 1.0;
            let actions: &[i64] = bytemuck::cast_slice(actions);
            for obs in out.obs.chunks_exact_mut(4) {
                obs.copy_from_slice(&self.t.to_le_bytes());
            }
            for (reward, &a) in out.rewards.iter_mut().zip(actions) {
                *reward = a as f64;
            }
            out.terminated.fill(0);
            out.truncated.fill(0);
            out.final_mask.fill(0);
            Ok(Vec::new())
        }

        fn render(&mut self, _flags: &[u8]) -> Result<Vec<u8>, EnvError> {
            Ok(Vec::new())
        }

        fn close(&mut self) {}
    }

    fn job(prefix: &str, num_envs: usize) -> WorkerJob {
        WorkerJob {
            adapter: "test".into(),
            env_id: "Lockstep-v0".into(),
            config: EnvConfig::default(),
            env_offset: 0,
            worker_envs: num_envs,
            session_envs: num_envs,
            channel: ChannelName {
                prefix: prefix.into(),
                service: "envhub/serve-test/0/0".into(),
            },
            slots: SlotsName::new(prefix, format!("{}-serve-test", std::process::id())),
            worker_index: 0,
            session_workers: 0,
            owner_pid: std::process::id(),
            spin_us: 0,
            max_spin_us: 0,
            info_row_bytes: 0,
            python: None,
        }
    }

    fn ready() -> ReadySpec {
        ReadySpec {
            observation_space: Space::box_f32(&[1], -1e9, 1e9),
            action_space: Space::discrete(10),
            max_episode_steps: None,
            render_fps: None,
            pid: std::process::id(),
            worker: None,
        }
    }

    #[test]
    fn serves_any_served_batch_over_a_real_channel() {
        let prefix = format!("shmserve{}_", std::process::id());
        let n = 3;
        let policy = WaitPolicy {
            spin: Duration::ZERO,
            max_spin: Duration::ZERO,
            tick: Duration::from_millis(10),
            block_beyond: Duration::ZERO,
        };
        let job = job(&prefix, n);
        let mut client = ClientChannel::create(&job.channel, "client", policy).unwrap();
        client.set_layout(Layout::new(n, 8)).unwrap();
        let mut pool = SlotPool::new(job.slots.clone(), BatchLayout::new(n, 4, false), 1 << 20);
        let (tx, rx) = mpsc::channel();
        let worker = std::thread::spawn(move || {
            let batch = Lockstep {
                num_envs: n,
                t: 0.0,
            };
            serve_batch(&job, batch, ready(), |line| {
                tx.send(line.clone()).map_err(std::io::Error::other)
            })
        });
        let line = rx.recv_timeout(Duration::from_secs(20)).unwrap();
        assert!(matches!(line, WorkerReply::Ready(_)), "{line:?}");
        let alive = || Ok(());

        let slot = pool.writable().unwrap();
        client
            .send_reset(slot.index(), &[Some(1), Some(2), Some(3)], None, "")
            .unwrap();
        assert_eq!(client.receive(alive).unwrap().header().status, status::OK);

        let actions: Vec<i64> = vec![4, 5, 6];
        client
            .send_step(slot.index(), bytemuck::cast_slice(&actions), None)
            .unwrap();
        let r = client.receive(alive).unwrap();
        assert_eq!(r.header().status, status::OK);
        let rows = slot.rows(0, n);
        let obs: Vec<f32> = rows
            .obs
            .chunks_exact(4)
            .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
            .collect();
        assert_eq!(obs, [1.0; 3]);
        assert_eq!(rows.rewards, [4.0, 5.0, 6.0]);
        drop(r);

        // The batch's own error reaches the client; the loop keeps serving.
        client
            .send_step(
                slot.index(),
                bytemuck::cast_slice(&actions),
                Some(&[true, false, true]),
            )
            .unwrap();
        let err = client.receive(alive).unwrap().error().unwrap();
        assert!(err.contains("steps its envs together"), "{err}");

        client.send_close().unwrap();
        assert_eq!(
            client.receive(alive).unwrap().header().status,
            status::CLOSED
        );
        worker.join().unwrap().unwrap();
        drop(slot);
        pool.close();
        assert!(
            !std::fs::read_dir("/dev/shm").unwrap().any(|e| e
                .unwrap()
                .file_name()
                .to_string_lossy()
                .contains("serve-test")),
            "closing the pool removes its slots"
        );
        drop(client);
        let _ = remove_namespace(&prefix);
    }

    #[test]
    fn a_batch_of_the_wrong_size_is_refused_before_serving() {
        let mut lines = Vec::new();
        let batch = Lockstep {
            num_envs: 2,
            t: 0.0,
        };
        serve_batch(&job("unused_", 3), batch, ready(), |line| {
            lines.push(line.clone());
            Ok(())
        })
        .unwrap();
        match &lines[..] {
            [WorkerReply::Error(e)] => assert!(e.contains("made 2 envs for a job of 3"), "{e}"),
            other => panic!("expected one error line, got {other:?}"),
        }
    }
}
