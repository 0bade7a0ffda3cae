//! One worker process as its owner sees it: started, watched, waited for, killed, restarted.

use crate::error::HubError;
use crate::launcher::{Launcher, WorkerProcess};
use envhub_shm::{
    Bell, ClientChannel, DataPlaneError, Layout, ProcessWatch, ReadySpec, Response, WaitPolicy,
    WorkerJob,
};

/// Asked while waiting on workers: `true` stops the wait with [`HubError::Interrupted`] (the
/// Python client checks for Ctrl-C this way).
pub type InterruptCheck = dyn Fn() -> bool + Send + Sync;
use std::time::{Duration, Instant};

/// A running worker and the client's end of its channel.
pub(crate) struct WorkerLink {
    pub index: usize,
    pub job: WorkerJob,
    pub spec: ReadySpec,
    pub channel: ClientChannel,
    process: WorkerProcess,
    launcher: Launcher,
    watch: ProcessWatch,
    generation: u32,
    bell: Bell,
    /// A request is in flight.
    pub pending: bool,
    /// A response received but not yet handed to the caller (`recv` returns it later).
    pub response: Option<Response>,
    /// The batch slot of the last request with results.
    pub slot: u32,
    /// The envs (session ids, ascending) the last step or reset request selected.
    pub sent: Vec<usize>,
    /// When the request in flight was sent.
    pub sent_at: Instant,
    /// The worker was restarted since the last results were read.
    pub restarted: bool,
    /// Restarts so far.
    pub restarts: u32,
}

impl WorkerLink {
    /// Creates the channel, starts the worker and waits for it to report ready.
    #[allow(clippy::too_many_arguments)] // one worker's whole identity, used in one place
    pub fn start(
        index: usize,
        mut job: WorkerJob,
        session: &str,
        generation: u32,
        policy: WaitPolicy,
        start_timeout: Duration,
        launcher: &Launcher,
        bell: Bell,
    ) -> Result<WorkerLink, HubError> {
        job.channel.service = format!("envhub/{session}/{index}/{generation}");
        let node_name = format!("client-{}-{index}", std::process::id());
        let mut channel = ClientChannel::create(&job.channel, &node_name, policy)?;
        channel.set_bell(bell.clone());
        let (process, spec) = launcher.launch(&job, start_timeout).map_err(|e| match e {
            HubError::WorkerDied { pid, why, envs, .. } => HubError::WorkerDied {
                worker: index,
                envs,
                pid,
                why,
            },
            other => other,
        })?;
        let pid = process.pid();
        let watch = ProcessWatch::new(pid).map_err(|e| HubError::WorkerDied {
            worker: index,
            envs: env_range(&job),
            pid,
            why: format!("vanished right after starting: {e}"),
        })?;
        channel.set_layout(Layout::new(job.num_envs, spec.action_space.byte_len()))?;
        tracing::debug!(worker = index, pid, envs = %env_range(&job), "worker ready");
        Ok(WorkerLink {
            index,
            job,
            spec,
            channel,
            process,
            launcher: launcher.clone(),
            watch,
            generation,
            bell,
            pending: false,
            response: None,
            slot: 0,
            sent: Vec::new(),
            sent_at: Instant::now(),
            restarted: false,
            restarts: 0,
        })
    }

    /// The worker's pid.
    pub fn pid(&self) -> u32 {
        self.spec.pid
    }

    /// Notes a request just sent: its slot and the envs it selected.
    pub fn sent(&mut self, slot: u32, envs: impl IntoIterator<Item = usize>) {
        self.pending = true;
        self.response = None;
        self.slot = slot;
        self.sent.clear();
        self.sent.extend(envs);
        self.sent_at = Instant::now();
    }

    /// Waits for the response to the request in flight. A worker that exits, or does not
    /// answer within `timeout` of the request (then it is killed), is reported as
    /// [`HubError::WorkerDied`]; `interrupt` is asked every tick.
    pub fn wait(
        &mut self,
        timeout: Duration,
        interrupt: &InterruptCheck,
    ) -> Result<Response, HubError> {
        const INTERRUPTED: &str = "interrupted";
        const TIMED_OUT: &str = "timed out";
        let deadline = self.sent_at + timeout;
        let watch = &self.watch;
        let result = self.channel.receive(|| {
            if watch.exited() {
                Err(DataPlaneError::PeerGone("exited".into()))
            } else if interrupt() {
                Err(DataPlaneError::PeerGone(INTERRUPTED.into()))
            } else if Instant::now() >= deadline {
                Err(DataPlaneError::PeerGone(TIMED_OUT.into()))
            } else {
                Ok(())
            }
        });
        match result {
            Ok(response) => {
                self.pending = false;
                Ok(response)
            }
            Err(DataPlaneError::PeerGone(why)) if why == INTERRUPTED => Err(HubError::Interrupted),
            Err(DataPlaneError::PeerGone(why)) if why == TIMED_OUT => Err(self.hung(timeout)),
            Err(DataPlaneError::PeerGone(_)) => Err(self.exited()),
            Err(e) => {
                self.pending = false;
                Err(e.into())
            }
        }
    }

    /// Whether the request in flight has been waited on for longer than `timeout`.
    pub fn overdue(&self, timeout: Duration) -> bool {
        self.pending && self.sent_at.elapsed() >= timeout
    }

    /// The response if it has arrived, without asking whether the worker lives (cheap: for
    /// spinning).
    pub fn try_take(&mut self) -> Result<Option<Response>, HubError> {
        if !self.pending {
            return Ok(None);
        }
        let r = self.channel.try_receive()?;
        if r.is_some() {
            self.pending = false;
        }
        Ok(r)
    }

    /// The response if it has arrived; a dead worker is an error.
    pub fn poll(&mut self) -> Result<Option<Response>, HubError> {
        if !self.pending {
            return Ok(None);
        }
        if let Some(r) = self.channel.try_receive()? {
            self.pending = false;
            return Ok(Some(r));
        }
        if self.watch.exited() {
            return Err(self.exited());
        }
        Ok(None)
    }

    /// Kills a worker that did not answer within `timeout` and describes it.
    pub fn hung(&mut self, timeout: Duration) -> HubError {
        self.pending = false;
        self.process.kill();
        HubError::WorkerDied {
            worker: self.index,
            envs: env_range(&self.job),
            pid: self.pid(),
            why: format!("did not answer within {timeout:?} (step timeout) and was killed"),
        }
    }

    fn exited(&mut self) -> HubError {
        self.pending = false;
        let why = match self.process.exit_status(Duration::from_millis(500)) {
            Some(status) => format!("died ({status})"),
            None => "died (exit status unknown)".to_string(),
        };
        HubError::WorkerDied {
            worker: self.index,
            envs: env_range(&self.job),
            pid: self.pid(),
            why,
        }
    }

    /// Starts a replacement worker for the same envs.
    pub fn restart(
        &mut self,
        session: &str,
        policy: WaitPolicy,
        start_timeout: Duration,
    ) -> Result<(), HubError> {
        let fresh = WorkerLink::start(
            self.index,
            self.job.clone(),
            session,
            self.generation + 1,
            policy,
            start_timeout,
            &self.launcher,
            self.bell.clone(),
        )?;
        let restarts = self.restarts + 1;
        *self = fresh;
        self.restarts = restarts;
        self.restarted = true;
        Ok(())
    }

    /// Asks the worker to close and waits briefly for it to exit; kills it if it does not.
    /// The reply to the close is not read: the worker unmaps its response segment as it
    /// exits, and reading a sample from a segment this client never mapped (a session that
    /// never stepped) makes iceoryx2 warn about a lost chunk.
    pub fn close(&mut self) {
        self.response = None;
        let asked = self.channel.send_close().is_ok();
        if !asked || self.process.exit_status(Duration::from_secs(2)).is_none() {
            self.process.kill();
        }
    }

    /// Kills the worker at once (the caller gave up on the session, e.g. on Ctrl-C).
    pub fn abort(&mut self) {
        self.response = None;
        self.pending = false;
        self.process.kill_now();
    }
}

impl Drop for WorkerLink {
    fn drop(&mut self) {
        if !self.watch.exited() {
            self.process.kill();
        }
    }
}

fn env_range(job: &WorkerJob) -> String {
    format!("{}..{}", job.env_offset, job.env_offset + job.num_envs)
}

/// Splits `num_envs` over `workers` as evenly as possible: (offset, count) per worker.
pub(crate) fn split_envs(num_envs: usize, workers: usize) -> Vec<(usize, usize)> {
    let mut out = Vec::with_capacity(workers);
    let mut offset = 0;
    for w in 0..workers {
        let count = num_envs / workers + usize::from(w < num_envs % workers);
        out.push((offset, count));
        offset += count;
    }
    out
}
