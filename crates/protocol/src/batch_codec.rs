//! The messages of a remote session: one request and one response per hub and round trip,
//! each carrying the hub's whole slice in the data plane's own byte layout — no per-env
//! messages and no serialisation on the hot path.
//!
//! - Request: a [`RequestHeader`] (`#[repr(C)]`, 24 bytes), then the request blocks of a
//!   [`Layout`] for the hub's envs (actions, seeds, flags), then the reset options (JSON).
//! - Response: a [`ResponseHeader`] whose `reserved` field holds the bytes of result rows that
//!   follow it — a [`BatchLayout`] of the hub's envs, the blocks a batch slot holds — then the
//!   info section (`info_len` bytes: JSON, rendered frames or an error).
//!
//! Messages arrive at any alignment, so every multi-byte value is read and written by copying
//! bytes; nothing is cast in place.

use crate::HubError;
use envhub_shm::{
    BatchLayout, Layout, RequestHeader, ResponseBlocksMut, ResponseHeader, command, env_flag,
};

/// Bytes of a request header.
pub const REQUEST_HEADER: usize = std::mem::size_of::<RequestHeader>();
/// Bytes of a response header.
pub const RESPONSE_HEADER: usize = std::mem::size_of::<ResponseHeader>();

/// What a request asks, besides its header fields.
pub struct RequestBody<'a> {
    /// One action per env of the hub (zeros for envs not selected); `None` for no actions.
    pub actions: Option<&'a [u8]>,
    /// The envs it applies to (`None`: all).
    pub selected: Option<&'a [bool]>,
    /// Per-env seeds (reset).
    pub seeds: &'a [Option<u64>],
    /// Reset options as JSON (empty: none).
    pub options: &'a [u8],
}

impl RequestBody<'_> {
    /// A request that carries nothing but its command (render, close).
    pub const NONE: RequestBody<'static> = RequestBody {
        actions: None,
        selected: None,
        seeds: &[],
        options: b"",
    };
}

/// Encodes a request for a hub whose envs have request layout `layout`.
pub fn encode_request(
    layout: &Layout,
    seq: u64,
    command: u32,
    slot: u32,
    body: &RequestBody<'_>,
) -> Vec<u8> {
    let n = layout.num_envs;
    let header = RequestHeader {
        seq,
        command,
        num_envs: n as u32,
        options_len: body.options.len() as u32,
        slot,
    };
    let mut out = with_room_for_the_tag(REQUEST_HEADER + layout.req_options + body.options.len());
    out[..REQUEST_HEADER].copy_from_slice(bytemuck::bytes_of(&header));
    let p = &mut out[REQUEST_HEADER..];
    if let Some(actions) = body.actions {
        p[layout.req_actions..layout.req_actions + actions.len()].copy_from_slice(actions);
    }
    for i in 0..n {
        let mut flag = 0;
        if body.selected.is_none_or(|s| s[i]) {
            flag |= env_flag::SELECTED;
        }
        if let Some(seed) = body.seeds.get(i).copied().flatten() {
            p[layout.req_seeds + 8 * i..layout.req_seeds + 8 * (i + 1)]
                .copy_from_slice(&seed.to_le_bytes());
            flag |= env_flag::SEEDED;
        }
        p[layout.req_flags + i] = flag;
    }
    p[layout.req_options..].copy_from_slice(body.options);
    out
}

/// `len` zero bytes, with room for the seal's tag (so sealing does not copy the message).
fn with_room_for_the_tag(len: usize) -> Vec<u8> {
    let mut out = Vec::with_capacity(len + crate::seal::TAG_LEN);
    out.resize(len, 0);
    out
}

/// The longest reset options a remote request may carry (JSON).
pub const MAX_OPTIONS_BYTES: usize = 1 << 20;

/// The sizes a sealed request of a session of `layout` may have: its fixed blocks, and at
/// most [`MAX_OPTIONS_BYTES`] of options (checked before a request is queued).
pub fn sealed_request_sizes(layout: &Layout) -> std::ops::RangeInclusive<usize> {
    let fixed = REQUEST_HEADER + layout.req_options + crate::seal::TAG_LEN;
    fixed..=fixed + MAX_OPTIONS_BYTES
}

/// A request as the hub reads it.
#[derive(Debug)]
pub struct ParsedRequest<'a> {
    /// Its header.
    pub header: RequestHeader,
    /// Actions of every env, back to back.
    pub actions: &'a [u8],
    /// Per-env seeds (reset).
    pub seeds: Vec<Option<u64>>,
    /// Which envs it applies to.
    pub selected: Vec<bool>,
    /// Reset options (JSON; empty: none).
    pub options: &'a str,
}

/// Reads a request for a hub session of `layout`; the error says what is wrong with it.
pub fn parse_request<'a>(bytes: &'a [u8], layout: &Layout) -> Result<ParsedRequest<'a>, String> {
    let n = layout.num_envs;
    let header: RequestHeader =
        bytemuck::pod_read_unaligned(bytes.get(..REQUEST_HEADER).ok_or(format!(
            "a request of {} bytes is shorter than its {REQUEST_HEADER}-byte header",
            bytes.len()
        ))?);
    if !matches!(
        header.command,
        command::RESET | command::STEP | command::RENDER | command::CLOSE
    ) {
        return Err(format!(
            "unknown command {}; valid: reset {}, step {}, close {}, render {}",
            header.command,
            command::RESET,
            command::STEP,
            command::CLOSE,
            command::RENDER
        ));
    }
    let body = &bytes[REQUEST_HEADER..];
    let want = layout.req_options + header.options_len as usize;
    if header.num_envs as usize != n || body.len() != want {
        return Err(format!(
            "a request for {} envs with {} bytes after the header; this session has {n} envs and takes {want} bytes",
            header.num_envs,
            body.len()
        ));
    }
    let flags = &body[layout.req_flags..layout.req_flags + n];
    let seeds = (0..n)
        .map(|i| {
            (flags[i] & env_flag::SEEDED != 0).then(|| {
                let at = layout.req_seeds + 8 * i;
                u64::from_le_bytes(body[at..at + 8].try_into().expect("8 bytes"))
            })
        })
        .collect();
    let options = std::str::from_utf8(&body[layout.req_options..])
        .map_err(|e| format!("reset options are not UTF-8: {e}"))?;
    Ok(ParsedRequest {
        header,
        actions: &body[layout.req_actions..layout.req_actions + n * layout.act_bytes],
        seeds,
        selected: flags.iter().map(|f| f & env_flag::SELECTED != 0).collect(),
        options,
    })
}

/// Encodes a response: header, result rows (empty when there are none) and info section.
pub fn encode_response(
    seq: u64,
    status: u32,
    num_envs: usize,
    rows: &[u8],
    info: &[u8],
) -> Vec<u8> {
    let header = ResponseHeader {
        seq,
        status,
        num_envs: num_envs as u32,
        info_len: info.len() as u32,
        reserved: rows.len() as u32,
    };
    let mut out =
        Vec::with_capacity(RESPONSE_HEADER + rows.len() + info.len() + crate::seal::TAG_LEN);
    out.extend_from_slice(bytemuck::bytes_of(&header));
    out.extend_from_slice(rows);
    out.extend_from_slice(info);
    out
}

/// Status of a response that carries an error for the hub's whole slice (its session there
/// is over): the info section is the [`HubError`] serialized.
pub const HUB_ERROR: u32 = 16;

/// The response that ends a session with `error`.
pub fn encode_error(seq: u64, num_envs: usize, error: &HubError) -> Vec<u8> {
    let json = serde_json::to_vec(error).expect("errors serialize");
    encode_response(seq, HUB_ERROR, num_envs, &[], &json)
}

/// The error a [`HUB_ERROR`] response carries, as the hub named `hub` sent it; text that is
/// not one becomes [`HubError::Remote`] with it. Not yet filtered: the caller maps what it
/// understands (a hub's `WorkerDied`) and passes the rest through
/// [`crate::untrusted::from_hub`].
pub fn decode_error(hub: &str, info: &[u8]) -> HubError {
    match serde_json::from_slice::<HubError>(info) {
        Ok(e) => e,
        Err(_) => HubError::Remote(format!("hub `{hub}`: {}", String::from_utf8_lossy(info))),
    }
}

/// A response as the client received it.
pub struct RemoteAnswer {
    header: ResponseHeader,
    bytes: Vec<u8>,
}

impl RemoteAnswer {
    /// Reads a response; `None` when it is too short for what its header says.
    pub fn parse(bytes: Vec<u8>) -> Option<RemoteAnswer> {
        let header: ResponseHeader = bytemuck::pod_read_unaligned(bytes.get(..RESPONSE_HEADER)?);
        let need = RESPONSE_HEADER + header.reserved as usize + header.info_len as usize;
        (bytes.len() == need).then_some(RemoteAnswer { header, bytes })
    }

    /// Its header.
    pub fn header(&self) -> &ResponseHeader {
        &self.header
    }

    /// The result rows: a [`BatchLayout`] of the hub's envs (empty: none).
    pub fn rows(&self) -> &[u8] {
        &self.bytes[RESPONSE_HEADER..RESPONSE_HEADER + self.header.reserved as usize]
    }

    /// Its info section (JSON infos, rendered frames, or the error of [`HUB_ERROR`]).
    pub fn info_bytes(&self) -> &[u8] {
        &self.bytes[RESPONSE_HEADER + self.header.reserved as usize..]
    }
}

/// Copies rows `envs` (indices within the hub's slice) of a hub's result block `from`
/// (laid out by `layout`) into `to`, the same envs' rows of a batch slot.
pub fn land_rows(
    layout: &BatchLayout,
    from: &[u8],
    envs: &[usize],
    to: &mut ResponseBlocksMut<'_>,
    first: usize,
) {
    let ob = layout.obs_bytes;
    let rewards: &mut [u8] = bytemuck::cast_slice_mut(to.rewards);
    let contiguous = envs.windows(2).all(|p| p[1] == p[0] + 1);
    if let (true, Some(&lo)) = (contiguous, envs.first()) {
        // The usual case (every env of the hub): one copy per block.
        let (n, k) = (envs.len(), lo - first);
        to.obs[k * ob..(k + n) * ob].copy_from_slice(&from[layout.obs + lo * ob..][..n * ob]);
        rewards[k * 8..(k + n) * 8].copy_from_slice(&from[layout.rewards + lo * 8..][..n * 8]);
        to.terminated[k..k + n].copy_from_slice(&from[layout.terminated + lo..][..n]);
        to.truncated[k..k + n].copy_from_slice(&from[layout.truncated + lo..][..n]);
        to.final_mask[k..k + n].copy_from_slice(&from[layout.final_mask + lo..][..n]);
        if layout.with_final_obs {
            to.final_obs[k * ob..(k + n) * ob]
                .copy_from_slice(&from[layout.final_obs + lo * ob..][..n * ob]);
        }
        return;
    }
    for &e in envs {
        let k = e - first;
        to.obs[k * ob..(k + 1) * ob].copy_from_slice(&from[layout.obs + e * ob..][..ob]);
        rewards[k * 8..(k + 1) * 8].copy_from_slice(&from[layout.rewards + e * 8..][..8]);
        to.terminated[k] = from[layout.terminated + e];
        to.truncated[k] = from[layout.truncated + e];
        to.final_mask[k] = from[layout.final_mask + e];
        if layout.with_final_obs {
            to.final_obs[k * ob..(k + 1) * ob]
                .copy_from_slice(&from[layout.final_obs + e * ob..][..ob]);
        }
    }
}
/// The result blocks of a hub's session (all its envs), which [`write_rows`] picks rows of.
pub struct RowsOut<'a> {
    /// Observations.
    pub obs: &'a [u8],
    /// Rewards.
    pub rewards: &'a [f64],
    /// Terminated flags.
    pub terminated: &'a [bool],
    /// Truncated flags.
    pub truncated: &'a [bool],
    /// Final-observation mask (`same_step`).
    pub final_mask: &'a [u8],
    /// Final observations (`same_step`).
    pub final_obs: &'a [u8],
}

/// Writes results into a hub's result block (laid out by `layout`): the rows of `envs`
/// (indices within the slice), in order, from the blocks given.
pub fn write_rows(layout: &BatchLayout, to: &mut [u8], envs: &[usize], rows: &RowsOut<'_>) {
    let ob = layout.obs_bytes;
    let contiguous = envs.windows(2).all(|p| p[1] == p[0] + 1);
    if let (true, Some(&first)) = (contiguous, envs.first()) {
        // The usual case (a whole batch): one copy per block.
        let n = envs.len();
        to[layout.obs + first * ob..][..n * ob].copy_from_slice(&rows.obs[..n * ob]);
        to[layout.rewards + first * 8..][..n * 8]
            .copy_from_slice(bytemuck::cast_slice(&rows.rewards[..n]));
        for k in 0..n {
            to[layout.terminated + first + k] = u8::from(rows.terminated[k]);
            to[layout.truncated + first + k] = u8::from(rows.truncated[k]);
        }
        if !rows.final_mask.is_empty() {
            to[layout.final_mask + first..][..n].copy_from_slice(&rows.final_mask[..n]);
        }
        if layout.with_final_obs && !rows.final_obs.is_empty() {
            to[layout.final_obs + first * ob..][..n * ob]
                .copy_from_slice(&rows.final_obs[..n * ob]);
        }
        return;
    }
    for (k, &e) in envs.iter().enumerate() {
        to[layout.obs + e * ob..][..ob].copy_from_slice(&rows.obs[k * ob..(k + 1) * ob]);
        to[layout.rewards + e * 8..][..8].copy_from_slice(&rows.rewards[k].to_le_bytes());
        to[layout.terminated + e] = u8::from(rows.terminated[k]);
        to[layout.truncated + e] = u8::from(rows.truncated[k]);
        if let Some(&m) = rows.final_mask.get(k) {
            to[layout.final_mask + e] = m;
        }
        if layout.with_final_obs && !rows.final_obs.is_empty() {
            to[layout.final_obs + e * ob..][..ob]
                .copy_from_slice(&rows.final_obs[k * ob..(k + 1) * ob]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hub's error comes back as sent (the engine maps a `WorkerDied` to its own worker and
    /// filters the rest); text that is no error names the hub.
    #[test]
    fn hub_errors_decode_as_sent_and_garbage_names_the_hub() {
        let died = HubError::WorkerDied {
            worker: 0,
            envs: "0..2".into(),
            pid: 7,
            why: "died (signal: 9 (SIGKILL))".into(),
        };
        let response = encode_error(1, 2, &died);
        let answer = RemoteAnswer::parse(response).unwrap();
        assert_eq!(answer.header().status, HUB_ERROR);
        assert!(matches!(
            decode_error("box1", answer.info_bytes()),
            HubError::WorkerDied { pid: 7, .. }
        ));
        let text = decode_error("box1", b"not json").to_string();
        assert!(
            text.contains("hub `box1`") && text.contains("not json"),
            "{text}"
        );
    }

    #[test]
    fn a_request_survives_the_wire_at_any_alignment() {
        let layout = Layout::new(3, 4);
        let actions: Vec<u8> = (0..12).collect();
        let bytes = encode_request(
            &layout,
            7,
            command::RESET,
            2,
            &RequestBody {
                actions: Some(&actions),
                selected: Some(&[true, false, true]),
                seeds: &[Some(5), None, Some(u64::MAX)],
                options: b"{\"a\":1}",
            },
        );
        // Shifted by one byte: nothing may rely on the buffer's alignment.
        let mut shifted = vec![0u8];
        shifted.extend_from_slice(&bytes);
        let r = parse_request(&shifted[1..], &layout).unwrap();
        assert_eq!((r.header.seq, r.header.slot), (7, 2));
        assert_eq!(r.actions, &actions[..]);
        assert_eq!(r.seeds, vec![Some(5), None, Some(u64::MAX)]);
        assert_eq!(r.selected, vec![true, false, true]);
        assert_eq!(r.options, "{\"a\":1}");
    }

    #[test]
    fn rows_land_where_they_belong_whole_or_picked() {
        let layout = BatchLayout::new(3, 4, true);
        let obs: Vec<u8> = (0..12).collect();
        let mut block = vec![0u8; layout.size()];
        let rows = RowsOut {
            obs: &obs,
            rewards: &[1.0, 2.0, 3.0],
            terminated: &[false, true, false],
            truncated: &[true, false, false],
            final_mask: &[0, 1, 0],
            final_obs: &obs,
        };
        write_rows(&layout, &mut block, &[0, 1, 2], &rows);
        for envs in [vec![0, 1, 2], vec![0, 2]] {
            let mut slot = vec![0u64; layout.size().div_ceil(8)];
            let base: &mut [u8] = bytemuck::cast_slice_mut(&mut slot);
            // SAFETY: `base` is `size()` bytes, 8-byte aligned, used only here.
            let mut to = unsafe { layout.rows_mut(base.as_mut_ptr(), 0, 3) };
            land_rows(&layout, &block, &envs, &mut to, 0);
            for &e in &envs {
                assert_eq!(to.obs[e * 4..(e + 1) * 4], obs[e * 4..(e + 1) * 4]);
                assert_eq!(to.rewards[e], rows.rewards[e]);
                assert_eq!(to.terminated[e], u8::from(rows.terminated[e]));
                assert_eq!(to.truncated[e], u8::from(rows.truncated[e]));
                assert_eq!(to.final_mask[e], rows.final_mask[e]);
                assert_eq!(to.final_obs[e * 4..(e + 1) * 4], obs[e * 4..(e + 1) * 4]);
            }
            if envs.len() == 2 {
                assert_eq!(to.rewards[1], 0.0, "an env not sent is left alone");
            }
        }
    }

    #[test]
    fn garbage_is_an_error_that_says_what_is_wrong() {
        let layout = Layout::new(2, 8);
        let e = parse_request(&[1, 2, 3], &layout).unwrap_err();
        assert!(e.contains("shorter than"), "{e}");
        let mut bytes = encode_request(&layout, 1, command::STEP, 0, &RequestBody::NONE);
        bytes[8] = 99; // the command
        let e = parse_request(&bytes, &layout).unwrap_err();
        assert!(e.contains("unknown command 99"), "{e}");
        bytes[8] = command::STEP as u8;
        let e = parse_request(&bytes[..bytes.len() - 1], &Layout::new(3, 8)).unwrap_err();
        assert!(e.contains("this session has 3 envs"), "{e}");
        assert!(RemoteAnswer::parse(vec![0; 10]).is_none());
        let mut answer = encode_response(1, 0, 2, &[0; 16], b"[]");
        answer.pop();
        assert!(RemoteAnswer::parse(answer).is_none());
    }
}
