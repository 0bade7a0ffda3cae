//! One worker as its owner sees it: a local process (started, watched, waited for, killed,
//! restarted) reached over iceoryx2, or a remote hub's slice of the session reached over
//! Zenoh. Both answer the same requests with the same statuses and result rows.

use crate::launch::{Launch, Process};
use crate::remote::RemoteSlice;
use envhub_protocol::HubError;
use envhub_protocol::batch_codec::{RemoteAnswer, RequestBody};
use envhub_shm::{
    Bell, ClientChannel, DataPlaneError, ProcessWatch, ReadySpec, Response, ResponseHeader,
    WaitPolicy, WorkerJob, command, status,
};
use std::sync::Arc;

/// Asked while waiting on workers: `true` stops the wait with [`HubError::Interrupted`] (the
/// Python client checks for Ctrl-C this way).
pub type InterruptCheck = dyn Fn() -> bool + Send + Sync;
use std::time::{Duration, Instant};

/// How long a wait for a remote answer spins (yielding the core) before it sleeps.
const REMOTE_SPIN: Duration = Duration::from_micros(300);

/// Extra wait for a remote slice beyond the step timeout (see [`WorkerLink::wait`]).
const REMOTE_GRACE: Duration = Duration::from_secs(2);

/// A local worker process and the client's end of its channel.
pub(crate) struct LocalConn {
    pub channel: ClientChannel,
    process: Box<dyn Process>,
    launcher: Arc<dyn Launch>,
    watch: ProcessWatch,
    generation: u32,
    bell: Bell,
}

/// How a link reaches its envs.
pub(crate) enum Conn {
    /// Both boxed: each is large (iceoryx2 ports; Zenoh handles), and links move around in
    /// a `Vec`.
    Local(Box<LocalConn>),
    Remote(Box<dyn RemoteSlice>),
}

/// A worker's answer: in place in iceoryx2 shared memory, or a remote hub's message (whose
/// result rows are copied into the batch slot when the results are taken).
pub(crate) enum Answer {
    Local(Response),
    Remote(RemoteAnswer),
}

impl Answer {
    pub fn header(&self) -> &ResponseHeader {
        match self {
            Answer::Local(r) => r.header(),
            Answer::Remote(r) => r.header(),
        }
    }

    pub fn info_bytes(&self) -> &[u8] {
        match self {
            Answer::Local(r) => r.info_bytes(),
            Answer::Remote(r) => r.info_bytes(),
        }
    }

    pub fn info_json(&self) -> Option<&str> {
        let bytes = self.info_bytes();
        (!bytes.is_empty()).then(|| std::str::from_utf8(bytes).unwrap_or(""))
    }

    /// The message of an [`status::ERROR`] answer.
    pub fn error(&self) -> Option<String> {
        (self.header().status == status::ERROR)
            .then(|| String::from_utf8_lossy(self.info_bytes()).into_owned())
    }
}

/// A worker (local process or remote slice) and the client's end of its channel.
pub(crate) struct WorkerLink {
    pub index: usize,
    pub job: WorkerJob,
    pub spec: ReadySpec,
    pub conn: Conn,
    /// A request is in flight.
    pub pending: bool,
    /// A response received but not yet handed to the caller (`recv` returns it later).
    pub response: Option<Answer>,
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
    /// The hub this remote slice was lost on, since the last results were read (its envs
    /// were placed again elsewhere).
    pub lost_hub: Option<String>,
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
        launcher: &Arc<dyn Launch>,
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
        // The spaces are the word of user code: checked before a size is computed from them.
        let mut process = process;
        let layout = match envhub_protocol::untrusted::check_worker_spaces(&spec, job.worker_envs) {
            Ok(layout) => layout,
            Err(e) => {
                process.kill_now();
                return Err(HubError::SpacesDiffer(format!(
                    "worker {index} (pid {pid}, envs {}) announced {e}",
                    env_range(&job)
                )));
            }
        };
        let watch = ProcessWatch::new(pid).map_err(|e| HubError::WorkerDied {
            worker: index,
            envs: env_range(&job),
            pid,
            why: format!("vanished right after starting: {e}"),
        })?;
        channel.set_layout(layout)?;
        tracing::debug!(worker = index, pid, envs = %env_range(&job), "worker ready");
        Ok(WorkerLink::new(
            index,
            job,
            spec,
            Conn::Local(Box::new(LocalConn {
                channel,
                process,
                launcher: launcher.clone(),
                watch,
                generation,
                bell,
            })),
        ))
    }

    /// A remote hub's slice of the session, connected.
    pub fn remote(
        index: usize,
        job: WorkerJob,
        spec: ReadySpec,
        conn: Box<dyn RemoteSlice>,
    ) -> WorkerLink {
        WorkerLink::new(index, job, spec, Conn::Remote(conn))
    }

    /// A link with nothing sent yet.
    fn new(index: usize, job: WorkerJob, spec: ReadySpec, conn: Conn) -> WorkerLink {
        WorkerLink {
            index,
            job,
            spec,
            conn,
            pending: false,
            response: None,
            slot: 0,
            sent: Vec::new(),
            sent_at: Instant::now(),
            restarted: false,
            restarts: 0,
            lost_hub: None,
        }
    }

    /// Replaces a lost remote slice by `conn` (the same envs, opened on another hub): its
    /// envs come back reset, truncated, with the loss in their info.
    pub fn replace_remote(&mut self, spec: ReadySpec, conn: Box<dyn RemoteSlice>, lost: String) {
        self.conn = Conn::Remote(conn);
        self.spec = spec;
        self.pending = false;
        self.response = None;
        self.restarts += 1;
        self.restarted = true;
        self.lost_hub = Some(lost);
    }

    /// The worker's pid (on its hub's machine for a remote slice).
    pub fn pid(&self) -> u32 {
        self.spec.pid
    }

    /// The iceoryx2 channel of a local worker.
    pub fn local_channel(&self) -> Option<&ClientChannel> {
        match &self.conn {
            Conn::Local(l) => Some(&l.channel),
            Conn::Remote(_) => None,
        }
    }

    /// The remote slice, if this link is one.
    pub fn remote_conn(&self) -> Option<&dyn RemoteSlice> {
        match &self.conn {
            Conn::Remote(r) => Some(r.as_ref()),
            Conn::Local(_) => None,
        }
    }

    /// How long a wait for this worker may spin before blocking.
    pub fn spin_budget(&self) -> Duration {
        match &self.conn {
            Conn::Local(l) => l.channel.spin_budget(),
            Conn::Remote(_) => Duration::ZERO,
        }
    }

    /// Sends a step of the `selected` envs (all if `None`); results go to slot `slot`.
    pub fn send_step(
        &mut self,
        slot: u32,
        actions: &[u8],
        selected: Option<&[bool]>,
    ) -> Result<(), HubError> {
        match &mut self.conn {
            Conn::Local(l) => {
                l.channel.send_step(slot, actions, selected)?;
            }
            Conn::Remote(r) => r.send(
                command::STEP,
                slot,
                &RequestBody {
                    actions: Some(actions),
                    selected,
                    seeds: &[],
                    options: b"",
                },
            )?,
        }
        Ok(())
    }

    /// Sends a reset of the `selected` envs (all if `None`).
    pub fn send_reset(
        &mut self,
        slot: u32,
        seeds: &[Option<u64>],
        selected: Option<&[bool]>,
        options_json: &str,
    ) -> Result<(), HubError> {
        match &mut self.conn {
            Conn::Local(l) => {
                l.channel.send_reset(slot, seeds, selected, options_json)?;
            }
            Conn::Remote(r) => r.send(
                command::RESET,
                slot,
                &RequestBody {
                    actions: None,
                    selected,
                    seeds,
                    options: options_json.as_bytes(),
                },
            )?,
        }
        Ok(())
    }

    /// Asks for a frame of every env.
    pub fn send_render(&mut self) -> Result<(), HubError> {
        match &mut self.conn {
            Conn::Local(l) => {
                l.channel.send_render(None)?;
            }
            Conn::Remote(r) => r.send(command::RENDER, envhub_shm::NO_SLOT, &RequestBody::NONE)?,
        }
        self.pending = true;
        self.sent_at = Instant::now();
        Ok(())
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
    ) -> Result<Answer, HubError> {
        const INTERRUPTED: &str = "interrupted";
        const TIMED_OUT: &str = "timed out";
        let deadline = self.sent_at + timeout;
        let local = match &mut self.conn {
            // The hub applies the same step timeout to its own workers and then answers with
            // what happened: give its answer time to arrive before calling the hub silent.
            Conn::Remote(_) => {
                return self.wait_remote(deadline + REMOTE_GRACE, timeout, interrupt);
            }
            Conn::Local(l) => l,
        };
        let watch = &local.watch;
        let result = local.channel.receive(|| {
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
                Ok(Answer::Local(response))
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

    /// [`WorkerLink::wait`] for a remote slice: the answer, the hub's loss, the interrupt or
    /// the timeout, whichever comes first; a request unanswered for a while is sent again.
    fn wait_remote(
        &mut self,
        deadline: Instant,
        timeout: Duration,
        interrupt: &InterruptCheck,
    ) -> Result<Answer, HubError> {
        const TICK: Duration = Duration::from_millis(5);
        // A short spin first (yielding the core): an answer a network round trip away is
        // caught without a sleeping thread's wake-up.
        let spin_until = Instant::now() + REMOTE_SPIN;
        while Instant::now() < spin_until {
            if let Some(answer) = self.try_take()? {
                return Ok(answer);
            }
            std::thread::yield_now();
        }
        loop {
            if let Some(answer) = self.poll()? {
                return Ok(answer);
            }
            if interrupt() {
                return Err(HubError::Interrupted);
            }
            if Instant::now() >= deadline {
                return Err(self.hung(timeout));
            }
            self.resend_if_silent()?;
            if let Conn::Remote(r) = &self.conn {
                r.wait(TICK);
            }
        }
    }

    /// Sends a remote slice's request in flight again if it has gone unanswered for a while
    /// (a request or answer lost with a Zenoh link that dropped and came back): every wait
    /// on a remote link calls it each tick, or one lost message hangs the session until the
    /// step timeout. A local worker's channel loses nothing; for it this does nothing.
    pub fn resend_if_silent(&mut self) -> Result<(), HubError> {
        match &mut self.conn {
            Conn::Remote(r) if self.pending => r.resend_if_silent(),
            _ => Ok(()),
        }
    }

    /// Whether the request in flight has been waited on for longer than `timeout`.
    pub fn overdue(&self, timeout: Duration) -> bool {
        let limit = match self.conn {
            Conn::Local(_) => timeout,
            Conn::Remote(_) => timeout + REMOTE_GRACE,
        };
        self.pending && self.sent_at.elapsed() >= limit
    }

    /// The response if it has arrived, without asking whether the worker lives (cheap: for
    /// spinning).
    pub fn try_take(&mut self) -> Result<Option<Answer>, HubError> {
        if !self.pending {
            return Ok(None);
        }
        let r = match &mut self.conn {
            Conn::Local(l) => l.channel.try_receive()?.map(Answer::Local),
            Conn::Remote(r) => r.try_take()?.map(Answer::Remote),
        };
        if r.is_some() {
            self.pending = false;
        }
        Ok(r)
    }

    /// The response if it has arrived; a dead worker is an error.
    pub fn poll(&mut self) -> Result<Option<Answer>, HubError> {
        if let Some(r) = self.try_take()? {
            return Ok(Some(r));
        }
        if !self.pending {
            return Ok(None);
        }
        let gone = match &self.conn {
            Conn::Local(l) => l.watch.exited(),
            Conn::Remote(r) => !r.alive(),
        };
        if gone {
            return Err(self.exited());
        }
        Ok(None)
    }

    /// Kills a worker that did not answer within `timeout` and describes it.
    pub fn hung(&mut self, timeout: Duration) -> HubError {
        self.pending = false;
        let local = match &mut self.conn {
            Conn::Local(l) => l,
            Conn::Remote(r) => {
                r.close();
                return HubError::HubLost {
                    hub: r.hub().to_string(),
                    envs: env_range(&self.job),
                    why: format!(
                        "it did not answer within {timeout:?} (step timeout); its session was closed"
                    ),
                };
            }
        };
        local.process.kill();
        HubError::WorkerDied {
            worker: self.index,
            envs: env_range(&self.job),
            pid: self.pid(),
            why: format!("did not answer within {timeout:?} (step timeout) and was killed"),
        }
    }

    fn exited(&mut self) -> HubError {
        self.pending = false;
        let local = match &mut self.conn {
            Conn::Local(l) => l,
            Conn::Remote(r) => {
                return HubError::HubLost {
                    hub: r.hub().to_string(),
                    envs: env_range(&self.job),
                    why: "its liveliness token went away (the hub exited, froze past its lease, or the network to it was cut)".into(),
                };
            }
        };
        let why = match local.process.exit_status(Duration::from_millis(500)) {
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
        let Conn::Local(local) = &self.conn else {
            return Err(HubError::Internal(
                "a remote slice is placed again by its session, not restarted".into(),
            ));
        };
        let fresh = WorkerLink::start(
            self.index,
            self.job.clone(),
            session,
            local.generation + 1,
            policy,
            start_timeout,
            &local.launcher,
            local.bell.clone(),
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
        match &mut self.conn {
            Conn::Local(l) => {
                let asked = l.channel.send_close().is_ok();
                if !asked || l.process.exit_status(Duration::from_secs(2)).is_none() {
                    l.process.kill();
                }
            }
            Conn::Remote(r) => r.close(),
        }
    }

    /// Kills the worker at once (the caller gave up on the session, e.g. on Ctrl-C).
    pub fn abort(&mut self) {
        self.response = None;
        self.pending = false;
        match &mut self.conn {
            Conn::Local(l) => l.process.kill_now(),
            Conn::Remote(r) => r.close(),
        }
    }
}

impl Drop for LocalConn {
    fn drop(&mut self) {
        if !self.watch.exited() {
            self.process.kill();
        }
    }
}

pub(crate) fn env_range(job: &WorkerJob) -> String {
    format!("{}..{}", job.env_offset, job.env_offset + job.worker_envs)
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
