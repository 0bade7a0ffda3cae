//! The two ends of a channel: the client sends requests and reads responses; the worker reads
//! requests in place, writes its envs' results into the batch slot the request names, and
//! answers with a small response (status and info section).

use crate::DataPlaneError;
use crate::layout::{
    Layout, RequestHeader, ResponseBlocksMut, ResponseHeader, command, env_flag, status,
};
use crate::slots::{Bell, Side, SlotMap};
use crate::transport::{
    ChannelName, Ipc, Ports, client_ports, node, request_publisher, worker_ports,
};
use crate::wait::{AdaptiveSpin, Blocked, WaitPolicy, next_sample, ring};
use iceoryx2::node::Node;
use iceoryx2::prelude::{CallbackProgression, SignalHandlingMode, WaitSetBuilder};
use iceoryx2::sample::Sample;
use std::time::Duration;

/// Usual room for the info section of a response; more takes a reallocation.
fn info_reserve(num_envs: usize) -> usize {
    1024 + 256 * num_envs
}

/// Slack for reset options in a request before the publisher reallocates.
const OPTIONS_RESERVE: usize = 1024;

/// Slot index of requests that write no results (render, close).
pub const NO_SLOT: u32 = u32::MAX;

fn send_failed<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> DataPlaneError {
    move |e| DataPlaneError::Ipc {
        what,
        detail: format!("{e:?}"),
    }
}

/// The client's end of a channel to one worker.
pub struct ClientChannel {
    ports: Ports<RequestHeader, ResponseHeader>,
    layout: Option<Layout>,
    seq: u64,
    policy: WaitPolicy,
    spin: AdaptiveSpin,
    sent_at: std::time::Instant,
    bell: Option<Bell>,
    _node: Node<Ipc>,
}

/// A response: status and info section, viewed in place. Results are in the batch slot.
pub struct Response {
    sample: Sample<Ipc, [u8], ResponseHeader>,
}

impl Response {
    /// The header.
    pub fn header(&self) -> &ResponseHeader {
        self.sample.user_header()
    }

    /// The raw info section (frames, for a render).
    pub fn info_bytes(&self) -> &[u8] {
        let payload = self.sample.payload();
        &payload[..(self.header().info_len as usize).min(payload.len())]
    }

    /// The info section as JSON text (`[{...}, ...]`, one object per env), if any.
    pub fn info_json(&self) -> Option<&str> {
        let bytes = self.info_bytes();
        (!bytes.is_empty()).then(|| std::str::from_utf8(bytes).unwrap_or(""))
    }

    /// The worker's error message when the status is [`status::ERROR`].
    pub fn error(&self) -> Option<String> {
        (self.header().status == status::ERROR)
            .then(|| String::from_utf8_lossy(self.info_bytes()).into_owned())
    }
}

impl ClientChannel {
    /// Creates the channel's services and the client's ports. Call before starting the
    /// worker, which opens them; then [`ClientChannel::set_layout`] once its spaces are known.
    pub fn create(
        name: &ChannelName,
        node_name: &str,
        policy: WaitPolicy,
    ) -> Result<ClientChannel, DataPlaneError> {
        let node = node(&name.prefix, node_name)?;
        let ports = client_ports(&node, name)?;
        Ok(ClientChannel {
            ports,
            layout: None,
            seq: 0,
            policy,
            spin: AdaptiveSpin::default(),
            sent_at: std::time::Instant::now(),
            bell: None,
            _node: node,
        })
    }

    /// Uses `bell`'s flags: the worker is notified only while it is blocked, and says when this
    /// side must be (without a bell, every send notifies).
    pub fn set_bell(&mut self, bell: Bell) {
        self.bell = Some(bell);
    }

    fn flag(&self, side: Side) -> Option<&std::sync::atomic::AtomicU32> {
        self.bell.as_ref().map(|b| b.flag(side))
    }

    /// Sets the request layout once the worker has reported its spaces, and makes the request
    /// publisher for that size.
    pub fn set_layout(&mut self, layout: Layout) -> Result<(), DataPlaneError> {
        self.ports.publisher = None;
        self.ports.publisher = Some(request_publisher(
            &self.ports.services.0,
            layout.req_options + OPTIONS_RESERVE,
        )?);
        self.layout = Some(layout);
        Ok(())
    }

    fn layout(&self) -> Result<Layout, DataPlaneError> {
        self.layout
            .ok_or_else(|| DataPlaneError::Protocol("the worker has not reported ready".into()))
    }

    fn send(
        &mut self,
        command: u32,
        slot: u32,
        options: &[u8],
        fill: impl FnOnce(&Layout, &mut [u8]),
    ) -> Result<u64, DataPlaneError> {
        let layout = self.layout()?;
        let publisher = self.ports.publisher.as_ref().expect("made with the layout");
        self.seq += 1;
        let len = layout.req_options + options.len();
        let sample = publisher
            .loan_slice_uninit(len)
            .map_err(send_failed("loan request"))?;
        // SAFETY: u8 has no invalid values and shared memory is zero-filled when created; every
        // block the worker reads for this command is written below.
        let mut sample = unsafe { sample.assume_init() };
        *sample.user_header_mut() = RequestHeader {
            seq: self.seq,
            command,
            num_envs: layout.num_envs as u32,
            options_len: options.len() as u32,
            slot,
        };
        let payload = sample.payload_mut();
        payload[layout.req_options..].copy_from_slice(options);
        fill(&layout, payload);
        sample.send().map_err(send_failed("send request"))?;
        self.sent_at = std::time::Instant::now();
        ring(&self.ports.notifier, self.flag(Side::Worker))?;
        Ok(self.seq)
    }

    /// Sends a step: `actions` holds one action per env; only `selected` envs (all if `None`)
    /// are stepped, and their results go to batch slot `slot`.
    pub fn send_step(
        &mut self,
        slot: u32,
        actions: &[u8],
        selected: Option<&[bool]>,
    ) -> Result<u64, DataPlaneError> {
        let layout = self.layout()?;
        if actions.len() != layout.num_envs * layout.act_bytes {
            return Err(DataPlaneError::Protocol(format!(
                "{} bytes of actions for {} envs of {} bytes",
                actions.len(),
                layout.num_envs,
                layout.act_bytes
            )));
        }
        self.send(command::STEP, slot, &[], |l, p| {
            p[l.req_actions..l.req_actions + actions.len()].copy_from_slice(actions);
            write_flags(l, p, selected, &[]);
        })
    }

    /// Sends a reset of the `selected` envs (all if `None`), each with its seed if given; the
    /// results go to batch slot `slot`.
    pub fn send_reset(
        &mut self,
        slot: u32,
        seeds: &[Option<u64>],
        selected: Option<&[bool]>,
        options_json: &str,
    ) -> Result<u64, DataPlaneError> {
        self.send(command::RESET, slot, options_json.as_bytes(), |l, p| {
            write_flags(l, p, selected, seeds);
        })
    }

    /// Asks the worker to render the `selected` envs (all if `None`).
    pub fn send_render(&mut self, selected: Option<&[bool]>) -> Result<u64, DataPlaneError> {
        self.send(command::RENDER, NO_SLOT, &[], |l, p| {
            write_flags(l, p, selected, &[])
        })
    }

    /// Asks the worker to close its envs and exit.
    pub fn send_close(&mut self) -> Result<u64, DataPlaneError> {
        self.send(command::CLOSE, NO_SLOT, &[], |l, p| {
            write_flags(l, p, None, &[])
        })
    }

    /// Waits for the response to the last request, calling `alive` every tick while waiting.
    pub fn receive(
        &mut self,
        alive: impl FnMut() -> Result<(), DataPlaneError>,
    ) -> Result<Response, DataPlaneError> {
        let mut alive = alive;
        loop {
            let sample = next_sample(
                &self.ports.subscriber,
                &self.ports.listener,
                self.spin.budget(&self.policy),
                self.policy.tick,
                self.bell.as_ref().map(|b| b.flag(Side::Client)),
                &mut alive,
            )?;
            // A response to an earlier request (one abandoned after an error) is skipped.
            if sample.user_header().seq == self.seq {
                self.spin.observe(self.sent_at.elapsed());
                return Ok(Response { sample });
            }
        }
    }

    /// The response to the last request if it has arrived, without waiting.
    pub fn try_receive(&mut self) -> Result<Option<Response>, DataPlaneError> {
        while let Some(sample) = self
            .ports
            .subscriber
            .receive()
            .map_err(send_failed("receive"))?
        {
            if sample.user_header().seq == self.seq {
                self.spin.observe(self.sent_at.elapsed());
                return Ok(Some(Response { sample }));
            }
        }
        Ok(None)
    }

    /// The spin budget this channel's recent waits call for.
    pub fn spin_budget(&self) -> Duration {
        self.spin.budget(&self.policy)
    }
}

/// Blocks until one of `channels` is notified of a response, or `timeout` passes (an
/// iceoryx2 WaitSet over their listeners): whichever worker answers first wakes the caller.
/// Returns at once if a notification is already pending. Callers then poll each channel.
pub fn wait_any(channels: &[&ClientChannel], timeout: Duration) -> Result<(), DataPlaneError> {
    if channels.is_empty() {
        std::thread::sleep(timeout);
        return Ok(());
    }
    // Blocked from here on, as the workers must know before they answer; a response that
    // came before the flags went up is seen below, without waiting.
    let _blocked: Vec<Blocked<'_>> = channels
        .iter()
        .map(|c| Blocked::raise(c.flag(Side::Client)))
        .collect();
    for c in channels {
        if c.ports
            .subscriber
            .has_samples()
            .map_err(send_failed("look for responses"))?
        {
            return Ok(());
        }
    }
    let waitset = WaitSetBuilder::new()
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<Ipc>()
        .map_err(send_failed("create wait set"))?;
    let guards = channels
        .iter()
        .map(|c| waitset.attach_notification(&c.ports.listener))
        .collect::<Result<Vec<_>, _>>()
        .map_err(send_failed("attach to wait set"))?;
    // At least 1 µs: a zero timeout would mean "forever" further down.
    waitset
        .wait_and_process_once_with_timeout(
            |_| CallbackProgression::Stop,
            timeout.max(Duration::from_micros(1)),
        )
        .map_err(send_failed("wait"))?;
    drop(guards);
    // Consume the notifications so the next wait blocks until a new one arrives.
    for c in channels {
        c.ports
            .listener
            .try_wait(|_| {})
            .map_err(send_failed("drain notifications"))?;
    }
    Ok(())
}

/// Each env's flags, and the seeds given. A seed is read only where its env's flag has
/// [`env_flag::SEEDED`], so the others are not written: a step writes a byte per env, not
/// nine (a profile of CartPole x 256 found the seeds' 2 KB written on every step).
fn write_flags(l: &Layout, p: &mut [u8], selected: Option<&[bool]>, seeds: &[Option<u64>]) {
    let n = l.num_envs;
    let (seed_block, flag_block) = p[l.req_seeds..l.req_flags + n].split_at_mut(n * 8);
    match selected {
        None => flag_block.fill(env_flag::SELECTED),
        Some(s) => {
            for (i, f) in flag_block.iter_mut().enumerate() {
                *f = if s.get(i) == Some(&true) {
                    env_flag::SELECTED
                } else {
                    0
                };
            }
        }
    }
    let seed_block: &mut [u64] = bytemuck::cast_slice_mut(seed_block);
    for (i, seed) in seeds.iter().enumerate().take(n) {
        if let Some(seed) = *seed {
            seed_block[i] = seed;
            flag_block[i] |= env_flag::SEEDED;
        }
    }
}

/// A request, viewed in place.
pub struct Request<'a> {
    /// The header.
    pub header: RequestHeader,
    /// Actions, `act_bytes` per env.
    pub actions: &'a [u8],
    /// Seeds (valid where the flag has [`env_flag::SEEDED`]).
    pub seeds: &'a [u64],
    /// Per-env flags ([`env_flag`]).
    pub flags: &'a [u8],
    /// Reset options as JSON text (empty: none).
    pub options: &'a str,
}

/// The worker's end of a channel.
pub struct WorkerChannel {
    ports: Ports<ResponseHeader, RequestHeader>,
    layout: Layout,
    slots: SlotMap,
    first_env: usize,
    policy: WaitPolicy,
    spin: AdaptiveSpin,
    bell: Option<Bell>,
    _node: Node<Ipc>,
}

impl WorkerChannel {
    /// Opens the channel the client created. The worker's envs are rows
    /// `first_env..first_env + layout.num_envs` of the session's batch slots.
    pub fn open(
        name: &ChannelName,
        node_name: &str,
        layout: Layout,
        slots: SlotMap,
        first_env: usize,
        policy: WaitPolicy,
    ) -> Result<WorkerChannel, DataPlaneError> {
        let node = node(&name.prefix, node_name)?;
        let ports = worker_ports(&node, name, info_reserve(layout.num_envs))?;
        Ok(WorkerChannel {
            ports,
            layout,
            slots,
            first_env,
            policy,
            spin: AdaptiveSpin::default(),
            bell: None,
            _node: node,
        })
    }

    /// Uses `bell`'s flags (see [`ClientChannel::set_bell`]).
    pub fn set_bell(&mut self, bell: Bell) {
        self.bell = Some(bell);
    }

    /// The session's batch slots as this worker maps them.
    pub fn slots(&self) -> &SlotMap {
        &self.slots
    }

    /// Waits for the next request and hands it to `handle` with this worker's rows of the slot
    /// it names (`None` for a request that writes no results), then sends the response.
    /// `alive` runs every tick while idle (to notice that the client is gone).
    pub fn serve_one(
        &mut self,
        alive: impl FnMut() -> Result<(), DataPlaneError>,
        handle: impl FnOnce(&Request<'_>, Option<&mut ResponseBlocksMut<'_>>) -> Reply,
    ) -> Result<u32, DataPlaneError> {
        let idle_since = std::time::Instant::now();
        let sample = next_sample(
            &self.ports.subscriber,
            &self.ports.listener,
            self.spin.budget(&self.policy),
            self.policy.tick,
            self.bell.as_ref().map(|b| b.flag(Side::Worker)),
            alive,
        )?;
        self.spin.observe(idle_since.elapsed());
        let header = *sample.user_header();
        let l = self.layout;
        let payload = sample.payload();
        if header.num_envs as usize != l.num_envs
            || payload.len() < l.req_options + header.options_len as usize
        {
            return Err(DataPlaneError::Protocol(format!(
                "request for {} envs with {} bytes; this worker has {} envs and expects at least {} bytes",
                header.num_envs,
                payload.len(),
                l.num_envs,
                l.req_options
            )));
        }
        let n = l.num_envs;
        let request = Request {
            header,
            actions: &payload[l.req_actions..l.req_actions + n * l.act_bytes],
            seeds: bytemuck::cast_slice(&payload[l.req_seeds..l.req_seeds + n * 8]),
            flags: &payload[l.req_flags..l.req_flags + n],
            options: std::str::from_utf8(
                &payload[l.req_options..l.req_options + header.options_len as usize],
            )
            .unwrap_or(""),
        };
        let reply = if header.slot == NO_SLOT {
            handle(&request, None)
        } else {
            // SAFETY: the client names a slot for these rows in one request at a time and reads
            // them only after our response, so they are ours until we send it.
            match unsafe { self.slots.rows_mut(header.slot, self.first_env, n) } {
                Ok(mut rows) => handle(&request, Some(&mut rows)),
                Err(e) => Reply::Error(format!("cannot write the results: {e}")),
            }
        };
        let command = header.command;
        drop(sample);
        let report;
        let (status, info) = match &reply {
            Reply::Ok { info } => (status::OK, info.as_slice()),
            Reply::Error(message) => (status::ERROR, message.as_bytes()),
            Reply::Closed => (status::CLOSED, &[][..]),
            Reply::EnvFailed { failed, info } => {
                let info: Option<serde_json::Value> = serde_json::from_slice(info).ok();
                report = serde_json::json!({ "failed": failed, "info": info }).to_string();
                (status::ENV_FAILED, report.as_bytes())
            }
        };
        let publisher = self.ports.publisher.as_ref().expect("a worker publishes");
        let out = publisher
            .loan_slice_uninit(info.len().max(1))
            .map_err(send_failed("loan response"))?;
        // SAFETY: u8 has no invalid values; the info bytes are written below and the client
        // reads no further than `info_len`.
        let mut out = unsafe { out.assume_init() };
        out.payload_mut()[..info.len()].copy_from_slice(info);
        *out.user_header_mut() = ResponseHeader {
            seq: header.seq,
            status,
            num_envs: n as u32,
            info_len: info.len() as u32,
            reserved: 0,
        };
        out.send().map_err(send_failed("send response"))?;
        ring(
            &self.ports.notifier,
            self.bell.as_ref().map(|b| b.flag(Side::Client)),
        )?;
        Ok(command)
    }
}

/// What a request handler answers.
pub enum Reply {
    /// The blocks are written; `info` is the info section (empty for none).
    Ok {
        /// JSON info section.
        info: Vec<u8>,
    },
    /// The request failed; the message goes to the client.
    Error(String),
    /// Some envs failed (`(index in the worker, message)`); the others' results are written.
    EnvFailed {
        /// The envs that failed and why.
        failed: Vec<(usize, String)>,
        /// JSON info section of the others (empty for none).
        info: Vec<u8>,
    },
    /// The worker closed its envs.
    Closed,
}
