//! The two ends of a channel: the client sends requests and reads responses in place; the
//! worker reads requests in place and writes responses into loaned samples.

use crate::DataPlaneError;
use crate::layout::{
    Layout, RequestHeader, ResponseBlocks, ResponseBlocksMut, ResponseHeader, command, env_flag,
    status,
};
use crate::transport::{ChannelName, Ipc, Ports, client_ports, node, worker_ports};
use crate::wait::{AdaptiveSpin, WaitPolicy, next_sample};
use iceoryx2::node::Node;
use iceoryx2::sample::Sample;

/// Room reserved in every response for the info section; bigger info takes a slower path.
pub(crate) fn info_reserve(num_envs: usize) -> usize {
    1024 + 256 * num_envs
}

fn send_failed<E: std::fmt::Debug>(what: &'static str) -> impl FnOnce(E) -> DataPlaneError {
    move |e| DataPlaneError::Ipc {
        what,
        detail: format!("{e:?}"),
    }
}

/// The client's end of a channel to one worker.
pub struct ClientChannel {
    ports: Ports<RequestHeader, ResponseHeader>,
    layout: Layout,
    seq: u64,
    policy: WaitPolicy,
    spin: AdaptiveSpin,
    sent_at: std::time::Instant,
    _node: Node<Ipc>,
}

/// A response, viewed in place in shared memory. Holding it keeps the sample alive.
pub struct Response {
    sample: Sample<Ipc, [u8], ResponseHeader>,
    layout: Layout,
}

impl Response {
    /// The header.
    pub fn header(&self) -> &ResponseHeader {
        self.sample.user_header()
    }

    /// The blocks, viewed in place.
    pub fn blocks(&self) -> ResponseBlocks<'_> {
        self.layout.response(self.sample.payload())
    }

    /// The info section as JSON text (`[{...}, ...]`, one object per env), if any.
    pub fn info_json(&self) -> Option<&str> {
        let len = self.header().info_len as usize;
        (len > 0).then(|| std::str::from_utf8(&self.blocks().info[..len]).unwrap_or(""))
    }

    /// The raw info section (frames, for a render).
    pub fn info_bytes(&self) -> &[u8] {
        &self.blocks().info[..self.header().info_len as usize]
    }

    /// The worker's error message when the status is [`status::ERROR`].
    pub fn error(&self) -> Option<String> {
        (self.header().status == status::ERROR).then(|| {
            let len = self.header().info_len as usize;
            String::from_utf8_lossy(&self.blocks().info[..len]).into_owned()
        })
    }

    /// The layout this response was written with.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }
}

impl ClientChannel {
    /// Creates the channel's services and the client's ports. Call before starting the
    /// worker, which opens them.
    pub fn create(
        name: &ChannelName,
        node_name: &str,
        layout: Layout,
        policy: WaitPolicy,
    ) -> Result<ClientChannel, DataPlaneError> {
        let node = node(&name.prefix, node_name)?;
        let ports = client_ports(&node, name, layout.req_options)?;
        Ok(ClientChannel {
            ports,
            layout,
            seq: 0,
            policy,
            spin: AdaptiveSpin::default(),
            sent_at: std::time::Instant::now(),
            _node: node,
        })
    }

    /// The layout of this channel's samples.
    pub fn layout(&self) -> &Layout {
        &self.layout
    }

    /// Sets the layout once the worker has reported its spaces.
    pub fn set_layout(&mut self, layout: Layout) {
        self.layout = layout;
    }

    fn send(
        &mut self,
        command: u32,
        options: &[u8],
        fill: impl FnOnce(&Layout, &mut [u8]),
    ) -> Result<u64, DataPlaneError> {
        self.seq += 1;
        let len = self.layout.req_options + options.len();
        let sample = self
            .ports
            .publisher
            .loan_slice_uninit(len)
            .map_err(send_failed("loan request"))?;
        // SAFETY: u8 has no invalid values and shared memory is zero-filled when created; every
        // block the worker reads for this command is written below.
        let mut sample = unsafe { sample.assume_init() };
        *sample.user_header_mut() = RequestHeader {
            seq: self.seq,
            command,
            num_envs: self.layout.num_envs as u32,
            options_len: options.len() as u32,
            reserved: 0,
        };
        let payload = sample.payload_mut();
        payload[self.layout.req_options..].copy_from_slice(options);
        fill(&self.layout, payload);
        sample.send().map_err(send_failed("send request"))?;
        self.ports
            .notifier
            .notify()
            .map_err(send_failed("notify"))?;
        Ok(self.seq)
    }

    /// Sends a step: `actions` holds one action per env; only `selected` envs (all if `None`)
    /// are stepped.
    pub fn send_step(
        &mut self,
        actions: &[u8],
        selected: Option<&[bool]>,
    ) -> Result<u64, DataPlaneError> {
        assert_eq!(
            actions.len(),
            self.layout.num_envs * self.layout.act_bytes,
            "one action per env"
        );
        self.send(command::STEP, &[], |l, p| {
            p[l.req_actions..l.req_actions + actions.len()].copy_from_slice(actions);
            write_flags(l, p, selected, &[]);
        })
    }

    /// Sends a reset of the `selected` envs (all if `None`), each with its seed if given.
    pub fn send_reset(
        &mut self,
        seeds: &[Option<u64>],
        selected: Option<&[bool]>,
        options_json: &str,
    ) -> Result<u64, DataPlaneError> {
        self.send(command::RESET, options_json.as_bytes(), |l, p| {
            write_flags(l, p, selected, seeds);
        })
    }

    /// Asks the worker to render the `selected` envs (all if `None`).
    pub fn send_render(&mut self, selected: Option<&[bool]>) -> Result<u64, DataPlaneError> {
        self.send(command::RENDER, &[], |l, p| {
            write_flags(l, p, selected, &[])
        })
    }

    /// Asks the worker to close its envs and exit.
    pub fn send_close(&mut self) -> Result<u64, DataPlaneError> {
        self.send(command::CLOSE, &[], |l, p| write_flags(l, p, None, &[]))
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
                &mut alive,
            )?;
            // A response to an earlier request (one abandoned after an error) is skipped.
            if sample.user_header().seq == self.seq {
                self.spin.observe(self.sent_at.elapsed());
                return Ok(Response {
                    sample,
                    layout: self.layout,
                });
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
                return Ok(Some(Response {
                    sample,
                    layout: self.layout,
                }));
            }
        }
        Ok(None)
    }
}

fn write_flags(l: &Layout, p: &mut [u8], selected: Option<&[bool]>, seeds: &[Option<u64>]) {
    let n = l.num_envs;
    let (seed_block, flag_block) = p[l.req_seeds..l.req_flags + n].split_at_mut(n * 8);
    let seed_block: &mut [u64] = bytemuck::cast_slice_mut(seed_block);
    for i in 0..n {
        let mut f = 0;
        if selected.is_none_or(|s| s[i]) {
            f |= env_flag::SELECTED;
        }
        match seeds.get(i).copied().flatten() {
            Some(seed) => {
                seed_block[i] = seed;
                f |= env_flag::SEEDED;
            }
            None => seed_block[i] = 0,
        }
        flag_block[i] = f;
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
    policy: WaitPolicy,
    spin: AdaptiveSpin,
    _node: Node<Ipc>,
}

impl WorkerChannel {
    /// Opens the channel the client created.
    pub fn open(
        name: &ChannelName,
        node_name: &str,
        layout: Layout,
        policy: WaitPolicy,
    ) -> Result<WorkerChannel, DataPlaneError> {
        let node = node(&name.prefix, node_name)?;
        let ports = worker_ports(
            &node,
            name,
            layout.resp_info + info_reserve(layout.num_envs),
        )?;
        Ok(WorkerChannel {
            ports,
            layout,
            policy,
            spin: AdaptiveSpin::default(),
            _node: node,
        })
    }

    /// Waits for the next request and hands it to `handle`, which writes the response.
    /// `alive` runs every tick while idle (to notice that the client is gone).
    pub fn serve_one(
        &mut self,
        alive: impl FnMut() -> Result<(), DataPlaneError>,
        handle: impl FnOnce(&Request<'_>, &mut ResponseBlocksMut<'_>) -> Reply,
    ) -> Result<u32, DataPlaneError> {
        let idle_since = std::time::Instant::now();
        let sample = next_sample(
            &self.ports.subscriber,
            &self.ports.listener,
            self.spin.budget(&self.policy),
            self.policy.tick,
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
        let capacity = l.resp_info + info_reserve(n);
        let loan = self
            .ports
            .publisher
            .loan_slice_uninit(capacity)
            .map_err(send_failed("loan response"))?;
        // SAFETY: u8 has no invalid values and shared memory is zero-filled when created; the
        // handler writes every block the client reads for this command.
        let mut out = unsafe { loan.assume_init() };
        let reply = {
            let mut blocks = l.response_mut(out.payload_mut());
            handle(&request, &mut blocks)
        };
        let command = header.command;
        drop(sample);
        let (status, info) = match &reply {
            Reply::Ok { info } => (status::OK, info.as_slice()),
            Reply::Error(message) => (status::ERROR, message.as_bytes()),
            Reply::Closed => (status::CLOSED, &[][..]),
        };
        let out = if info.len() <= capacity - l.resp_info {
            let mut out = out;
            out.payload_mut()[l.resp_info..l.resp_info + info.len()].copy_from_slice(info);
            out
        } else {
            // Rare: more info than reserved. Move the blocks into a bigger sample.
            let bigger = self
                .ports
                .publisher
                .loan_slice_uninit(l.resp_info + info.len())
                .map_err(send_failed("loan response"))?;
            // SAFETY: as above; every byte up to the end of the info is written here.
            let mut bigger = unsafe { bigger.assume_init() };
            bigger.payload_mut()[..l.resp_info].copy_from_slice(&out.payload()[..l.resp_info]);
            bigger.payload_mut()[l.resp_info..].copy_from_slice(info);
            bigger
        };
        let mut out = out;
        *out.user_header_mut() = ResponseHeader {
            seq: header.seq,
            status,
            num_envs: n as u32,
            info_len: info.len() as u32,
            reserved: 0,
        };
        out.send().map_err(send_failed("send response"))?;
        self.ports
            .notifier
            .notify()
            .map_err(send_failed("notify"))?;
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
    /// The worker closed its envs.
    Closed,
}
