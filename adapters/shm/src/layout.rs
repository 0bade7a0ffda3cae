//! Byte layout of request and response samples.
//!
//! One request and one response per worker and round trip, each a single iceoryx2 sample:
//! a `#[repr(C)]` user header plus a `[u8]` payload cut into blocks, one per field, each block
//! holding that field for every env of the worker back to back. A reader views a block as a
//! typed array (`[n, *obs_shape]`) in place; nothing is serialized on the hot path except an
//! optional info section, written only when some env reports info.

use bytemuck::{Pod, Zeroable};
use iceoryx2::prelude::ZeroCopySend;

/// Alignment of the payload start and of every block inside it.
pub const BLOCK_ALIGN: usize = 8;

/// Commands a client sends.
pub mod command {
    /// Reset the selected envs (all, for a plain reset).
    pub const RESET: u32 = 1;
    /// Step the selected envs with their actions.
    pub const STEP: u32 = 2;
    /// Close the envs and exit.
    pub const CLOSE: u32 = 3;
    /// Render the selected envs; the frames travel in the info section (see `EnvBatch::render`).
    pub const RENDER: u32 = 4;
}

/// Statuses a worker answers with.
pub mod status {
    /// The blocks hold the result.
    pub const OK: u32 = 0;
    /// The info section holds an error message (UTF-8); the blocks are undefined.
    pub const ERROR: u32 = 1;
    /// The worker closed its envs and is exiting.
    pub const CLOSED: u32 = 2;
}

/// Per-env flags of a request.
pub mod env_flag {
    /// The command applies to this env.
    pub const SELECTED: u8 = 1;
    /// The request carries a seed for this env (reset only).
    pub const SEEDED: u8 = 2;
}

/// Header of a client → worker request.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, Pod, Zeroable, ZeroCopySend)]
#[type_name("envhub::RequestHeader")]
pub struct RequestHeader {
    /// Sequence number, echoed by the response.
    pub seq: u64,
    /// One of [`command`].
    pub command: u32,
    /// Envs of the worker (a check that both sides agree on the layout).
    pub num_envs: u32,
    /// Bytes of JSON reset options after the fixed blocks (0: none).
    pub options_len: u32,
    /// Reserved.
    pub reserved: u32,
}

/// Header of a worker → client response.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, Pod, Zeroable, ZeroCopySend)]
#[type_name("envhub::ResponseHeader")]
pub struct ResponseHeader {
    /// Sequence number of the request answered.
    pub seq: u64,
    /// One of [`status`].
    pub status: u32,
    /// Envs of the worker.
    pub num_envs: u32,
    /// Bytes of the info section (JSON) after the fixed blocks (0: no env reported info).
    pub info_len: u32,
    /// Reserved.
    pub reserved: u32,
}

fn align(n: usize) -> usize {
    n.div_ceil(BLOCK_ALIGN) * BLOCK_ALIGN
}

/// Offsets of every block for a worker with `num_envs` envs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Envs of the worker.
    pub num_envs: usize,
    /// Bytes of one observation.
    pub obs_bytes: usize,
    /// Bytes of one action.
    pub act_bytes: usize,
    /// Whether responses carry final observations (`same_step` autoreset).
    pub with_final_obs: bool,
    // Request blocks.
    /// Actions `[n, act_bytes]`.
    pub req_actions: usize,
    /// Seeds `[n] u64`.
    pub req_seeds: usize,
    /// Flags `[n] u8` ([`env_flag`]).
    pub req_flags: usize,
    /// Start of the reset options; also the fixed size of a request.
    pub req_options: usize,
    // Response blocks.
    /// Observations `[n, obs_bytes]`.
    pub resp_obs: usize,
    /// Rewards `[n] f64`.
    pub resp_rewards: usize,
    /// Terminated `[n] u8`.
    pub resp_terminated: usize,
    /// Truncated `[n] u8`.
    pub resp_truncated: usize,
    /// Final-observation mask `[n] u8` (same_step: the env finished and was reset).
    pub resp_final_mask: usize,
    /// Final observations `[n, obs_bytes]` (only with `with_final_obs`).
    pub resp_final_obs: usize,
    /// Start of the info section; also the fixed size of a response.
    pub resp_info: usize,
}

impl Layout {
    /// The layout for `num_envs` envs with the given observation and action sizes.
    pub fn new(
        num_envs: usize,
        obs_bytes: usize,
        act_bytes: usize,
        with_final_obs: bool,
    ) -> Layout {
        let n = num_envs;
        let req_actions = 0;
        let req_seeds = align(req_actions + n * act_bytes);
        let req_flags = req_seeds + n * 8;
        let req_options = align(req_flags + n);
        let resp_obs = 0;
        let resp_rewards = align(n * obs_bytes);
        let resp_terminated = resp_rewards + n * 8;
        let resp_truncated = resp_terminated + n;
        let resp_final_mask = resp_truncated + n;
        let resp_final_obs = align(resp_final_mask + n);
        let resp_info = align(resp_final_obs + if with_final_obs { n * obs_bytes } else { 0 });
        Layout {
            num_envs,
            obs_bytes,
            act_bytes,
            with_final_obs,
            req_actions,
            req_seeds,
            req_flags,
            req_options,
            resp_obs,
            resp_rewards,
            resp_terminated,
            resp_truncated,
            resp_final_mask,
            resp_final_obs,
            resp_info,
        }
    }

    /// Splits a response payload into its blocks.
    pub fn response<'a>(&self, payload: &'a [u8]) -> ResponseBlocks<'a> {
        let n = self.num_envs;
        ResponseBlocks {
            obs: &payload[self.resp_obs..self.resp_obs + n * self.obs_bytes],
            rewards: bytemuck::cast_slice(&payload[self.resp_rewards..self.resp_rewards + n * 8]),
            terminated: &payload[self.resp_terminated..self.resp_terminated + n],
            truncated: &payload[self.resp_truncated..self.resp_truncated + n],
            final_mask: &payload[self.resp_final_mask..self.resp_final_mask + n],
            final_obs: if self.with_final_obs {
                &payload[self.resp_final_obs..self.resp_final_obs + n * self.obs_bytes]
            } else {
                &[]
            },
            info: &payload[self.resp_info..],
        }
    }

    /// Splits a response payload into its blocks, for writing.
    pub fn response_mut<'a>(&self, payload: &'a mut [u8]) -> ResponseBlocksMut<'a> {
        let n = self.num_envs;
        let (obs, rest) = payload.split_at_mut(self.resp_rewards);
        let (rewards, rest) = rest.split_at_mut(n * 8);
        let (terminated, rest) = rest.split_at_mut(n);
        let (truncated, rest) = rest.split_at_mut(n);
        let (final_mask, rest) = rest.split_at_mut(n);
        let rest = &mut rest[self.resp_final_obs - (self.resp_final_mask + n)..];
        let (final_obs, rest) = rest.split_at_mut(if self.with_final_obs {
            n * self.obs_bytes
        } else {
            0
        });
        let info_skip = self.resp_info - (self.resp_final_obs + final_obs.len());
        ResponseBlocksMut {
            obs: &mut obs[..n * self.obs_bytes],
            rewards: bytemuck::cast_slice_mut(rewards),
            terminated,
            truncated,
            final_mask,
            final_obs,
            info: &mut rest[info_skip..],
        }
    }
}

/// The blocks of a received response, viewed in place.
pub struct ResponseBlocks<'a> {
    /// Observations, `obs_bytes` per env.
    pub obs: &'a [u8],
    /// Rewards.
    pub rewards: &'a [f64],
    /// 1 where the episode terminated.
    pub terminated: &'a [u8],
    /// 1 where the episode was truncated.
    pub truncated: &'a [u8],
    /// 1 where `final_obs` holds the last observation of a finished episode.
    pub final_mask: &'a [u8],
    /// Final observations (same_step autoreset), else empty.
    pub final_obs: &'a [u8],
    /// The info section (JSON) or error message; its length is in the header.
    pub info: &'a [u8],
}

/// The blocks of a response being written.
pub struct ResponseBlocksMut<'a> {
    /// Observations, `obs_bytes` per env.
    pub obs: &'a mut [u8],
    /// Rewards.
    pub rewards: &'a mut [f64],
    /// 1 where the episode terminated.
    pub terminated: &'a mut [u8],
    /// 1 where the episode was truncated.
    pub truncated: &'a mut [u8],
    /// 1 where `final_obs` holds a final observation.
    pub final_mask: &'a mut [u8],
    /// Final observations (same_step autoreset), else empty.
    pub final_obs: &'a mut [u8],
    /// Room for the info section.
    pub info: &'a mut [u8],
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_are_aligned_and_disjoint() {
        for n in [1, 3, 8, 64, 257] {
            for (obs, act) in [(16, 8), (4, 4), (108, 32), (1, 1)] {
                for fin in [false, true] {
                    let l = Layout::new(n, obs, act, fin);
                    assert_eq!(l.resp_rewards % 8, 0);
                    assert_eq!(l.req_seeds % 8, 0);
                    assert_eq!(l.resp_info % 8, 0);
                    assert!(l.resp_rewards >= n * obs);
                    let mut words = vec![0u64; (l.resp_info + 16) / 8];
                    let buf: &mut [u8] = bytemuck::cast_slice_mut(&mut words);
                    let b = l.response_mut(buf);
                    assert_eq!(b.obs.len(), n * obs);
                    assert_eq!(b.rewards.len(), n);
                    assert_eq!(b.final_obs.len(), if fin { n * obs } else { 0 });
                    assert_eq!(b.info.len(), 16);
                    let r = l.response(buf);
                    assert_eq!(r.final_mask.len(), n);
                }
            }
        }
    }
}
