//! Byte layout of request samples and of batch slots.
//!
//! One request and one response per worker and round trip, each a single iceoryx2 sample with
//! a `#[repr(C)]` user header. A request's payload is cut into blocks, one per field, each
//! holding that field for every env of the worker back to back; a response's payload is only
//! the info section (JSON, written only when some env reports info) or an error message. The
//! results themselves go to a batch slot ([`BatchLayout`]) shared by all the session's
//! workers, where a reader views each block as a typed `[num_envs, ...]` array in place.

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
    /// Render the selected envs; the frames travel as the response payload (see `EnvBatch::render`).
    pub const RENDER: u32 = 4;
}

/// Statuses a worker answers with.
pub mod status {
    /// The worker's rows of the named slot hold the results.
    pub const OK: u32 = 0;
    /// The payload is an error message (UTF-8); the slot rows are undefined.
    pub const ERROR: u32 = 1;
    /// The worker closed its envs and is exiting.
    pub const CLOSED: u32 = 2;
    /// Some envs failed, the others' results are in the slot. The payload is JSON:
    /// `{"failed": [[env index in the worker, message], ...], "info": <info section or null>}`.
    pub const ENV_FAILED: u32 = 3;
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
#[type_name("envhub_hub::RequestHeader")]
pub struct RequestHeader {
    /// Sequence number, echoed by the response.
    pub seq: u64,
    /// One of [`command`].
    pub command: u32,
    /// Envs of the worker (a check that both sides agree on the layout).
    pub num_envs: u32,
    /// Bytes of JSON reset options after the fixed blocks (0: none).
    pub options_len: u32,
    /// The batch slot the results go to.
    pub slot: u32,
}

/// Header of a worker → client response.
#[repr(C)]
#[derive(Debug, Default, Clone, Copy, Pod, Zeroable, ZeroCopySend)]
#[type_name("envhub_hub::ResponseHeader")]
pub struct ResponseHeader {
    /// Sequence number of the request answered.
    pub seq: u64,
    /// One of [`status`].
    pub status: u32,
    /// Envs of the worker.
    pub num_envs: u32,
    /// Bytes of the info section (JSON), the whole payload (0: no env reported info).
    pub info_len: u32,
    /// Reserved.
    pub reserved: u32,
}

fn align(n: usize) -> usize {
    n.div_ceil(BLOCK_ALIGN) * BLOCK_ALIGN
}

/// Offsets of the blocks of one worker's request sample.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Envs of the worker.
    pub num_envs: usize,
    /// Bytes of one action.
    pub act_bytes: usize,
    /// Actions `[n, act_bytes]`.
    pub req_actions: usize,
    /// Seeds `[n] u64`.
    pub req_seeds: usize,
    /// Flags `[n] u8` ([`env_flag`]).
    pub req_flags: usize,
    /// Start of the reset options; also the fixed size of a request.
    pub req_options: usize,
}

impl Layout {
    /// [`new`](Self::new) for sizes another process sent: `None` when the request's size
    /// does not fit in an `isize`.
    pub fn checked(num_envs: usize, act_bytes: usize) -> Option<Layout> {
        let size = num_envs
            .checked_mul(act_bytes)?
            .checked_add(num_envs.checked_mul(9)?)?
            .checked_add(2 * BLOCK_ALIGN)?;
        (size <= isize::MAX as usize).then(|| Layout::new(num_envs, act_bytes))
    }

    /// The request layout of a worker with `num_envs` envs and actions of `act_bytes`.
    pub fn new(num_envs: usize, act_bytes: usize) -> Layout {
        let n = num_envs;
        let req_actions = 0;
        let req_seeds = align(req_actions + n * act_bytes);
        let req_flags = req_seeds + n * 8;
        let req_options = align(req_flags + n);
        Layout {
            num_envs,
            act_bytes,
            req_actions,
            req_seeds,
            req_flags,
            req_options,
        }
    }
}

/// Offsets of the blocks of a batch slot: each field of every env of the session, env after
/// env, so a block is a `[num_envs, ...]` array whichever worker wrote which rows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BatchLayout {
    /// Envs of the session.
    pub num_envs: usize,
    /// Bytes of one observation.
    pub obs_bytes: usize,
    /// Whether slots carry final observations (`same_step` autoreset).
    pub with_final_obs: bool,
    /// Observations `[n, obs_bytes]`.
    pub obs: usize,
    /// Rewards `[n] f64`.
    pub rewards: usize,
    /// Terminated `[n] u8`.
    pub terminated: usize,
    /// Truncated `[n] u8`.
    pub truncated: usize,
    /// Final-observation mask `[n] u8` (same_step: the env finished and was reset).
    pub final_mask: usize,
    /// Final observations `[n, obs_bytes]` (only with `with_final_obs`).
    pub final_obs: usize,
    /// Bytes of one env's row of typed info columns (0: the slot has none).
    pub info_row_bytes: usize,
    /// Typed info columns `[n, info_row_bytes]`, the last block, so a slot with them keeps
    /// every other block where a reader that does not know them looks (native workers).
    pub info_cols: usize,
    size: usize,
}

impl BatchLayout {
    /// The layout for a session of `num_envs` envs with observations of `obs_bytes`.
    pub fn new(num_envs: usize, obs_bytes: usize, with_final_obs: bool) -> BatchLayout {
        let n = num_envs;
        let obs = 0;
        let rewards = align(n * obs_bytes);
        let terminated = rewards + n * 8;
        let truncated = terminated + n;
        let final_mask = truncated + n;
        let final_obs = align(final_mask + n);
        let size = align(final_obs + if with_final_obs { n * obs_bytes } else { 0 });
        BatchLayout {
            num_envs,
            obs_bytes,
            with_final_obs,
            obs,
            rewards,
            terminated,
            truncated,
            final_mask,
            final_obs,
            info_row_bytes: 0,
            info_cols: size,
            size,
        }
    }

    /// This layout with a block of typed info columns of `row_bytes` per env (a multiple of
    /// [`BLOCK_ALIGN`], so every row starts aligned) after the other blocks; `None` when
    /// `row_bytes` is not such a multiple or the slot would not fit in an `isize`.
    pub fn with_info_columns(self, row_bytes: usize) -> Option<BatchLayout> {
        if !row_bytes.is_multiple_of(BLOCK_ALIGN) {
            return None;
        }
        let base = self.info_cols;
        let size = self.num_envs.checked_mul(row_bytes)?.checked_add(base)?;
        (size <= isize::MAX as usize).then_some(BatchLayout {
            info_row_bytes: row_bytes,
            size,
            ..self
        })
    }

    /// [`new`](Self::new) for sizes another process sent: `None` when the slot's size does
    /// not fit in an `isize` (what a mapping and a slice can hold).
    pub fn checked(num_envs: usize, obs_bytes: usize, with_final_obs: bool) -> Option<BatchLayout> {
        let obs = num_envs.checked_mul(obs_bytes)?;
        let size = obs
            .checked_next_multiple_of(BLOCK_ALIGN)?
            .checked_add(num_envs.checked_mul(11)?)?
            .checked_add(2 * BLOCK_ALIGN)?
            .checked_add(if with_final_obs { obs } else { 0 })?
            .checked_next_multiple_of(BLOCK_ALIGN)?;
        (size <= isize::MAX as usize).then(|| BatchLayout::new(num_envs, obs_bytes, with_final_obs))
    }

    /// Bytes of one slot.
    pub fn size(&self) -> usize {
        self.size
    }

    fn check_rows(&self, first: usize, n: usize) {
        assert!(
            first + n <= self.num_envs,
            "rows {first}..{} of a batch of {}",
            first + n,
            self.num_envs
        );
    }

    /// The blocks of envs `first..first + n` in `slot` (`size()` bytes), viewed in place.
    pub fn rows<'a>(&self, slot: &'a [u8], first: usize, n: usize) -> ResponseBlocks<'a> {
        self.check_rows(first, n);
        let ob = self.obs_bytes;
        let at =
            |start: usize, width: usize| &slot[start + first * width..start + (first + n) * width];
        ResponseBlocks {
            obs: at(self.obs, ob),
            rewards: bytemuck::cast_slice(at(self.rewards, 8)),
            terminated: at(self.terminated, 1),
            truncated: at(self.truncated, 1),
            final_mask: at(self.final_mask, 1),
            final_obs: if self.with_final_obs {
                at(self.final_obs, ob)
            } else {
                &[]
            },
            info_cols: at(self.info_cols, self.info_row_bytes),
        }
    }

    /// The blocks of envs `first..first + n` of the slot at `base`, for writing. Only those
    /// rows are borrowed: other workers may write the other rows at the same time.
    ///
    /// # Safety
    /// `base` must point to `size()` bytes, 8-byte aligned, and no one else may access these
    /// rows while the returned blocks live.
    pub unsafe fn rows_mut<'a>(
        &self,
        base: *mut u8,
        first: usize,
        n: usize,
    ) -> ResponseBlocksMut<'a> {
        self.check_rows(first, n);
        let ob = self.obs_bytes;
        // SAFETY: every block lies inside the slot (offsets from `new`, rows checked above) and
        // the blocks are disjoint; the caller guarantees exclusive access to these rows.
        let at = |start: usize, width: usize| unsafe {
            std::slice::from_raw_parts_mut(base.add(start + first * width), n * width)
        };
        ResponseBlocksMut {
            obs: at(self.obs, ob),
            rewards: bytemuck::cast_slice_mut(at(self.rewards, 8)),
            terminated: at(self.terminated, 1),
            truncated: at(self.truncated, 1),
            final_mask: at(self.final_mask, 1),
            final_obs: if self.with_final_obs {
                at(self.final_obs, ob)
            } else {
                &mut []
            },
            info_cols: at(self.info_cols, self.info_row_bytes),
        }
    }
}

/// The results of some envs, viewed in place in a batch slot.
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
    /// Typed info columns, `info_row_bytes` per env (empty when the slot has none).
    pub info_cols: &'a [u8],
}

/// The results of one worker's envs being written.
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
    /// Typed info columns, `info_row_bytes` per env (empty when the slot has none).
    pub info_cols: &'a mut [u8],
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blocks_are_aligned_and_disjoint() {
        for n in [1, 3, 8, 64, 257] {
            for (obs, act) in [(16, 8), (4, 4), (108, 32), (1, 1)] {
                let r = Layout::new(n, act);
                assert_eq!(r.req_seeds % 8, 0);
                assert!(r.req_options >= r.req_flags + n);
                for fin in [false, true] {
                    let l = BatchLayout::new(n, obs, fin);
                    assert_eq!(l.rewards % 8, 0);
                    assert_eq!(l.size() % 8, 0);
                    assert!(l.rewards >= n * obs);
                    let mut words = vec![0u64; l.size() / 8];
                    let base = words.as_mut_ptr().cast::<u8>();
                    // Two workers' rows, written at once through disjoint borrows.
                    let half = n / 2;
                    // SAFETY: `words` holds the slot; the two row ranges are disjoint.
                    let (a, b) =
                        unsafe { (l.rows_mut(base, 0, half), l.rows_mut(base, half, n - half)) };
                    assert_eq!(a.obs.len() + b.obs.len(), n * obs);
                    a.rewards.fill(1.0);
                    b.rewards.fill(2.0);
                    b.terminated.fill(1);
                    assert_eq!(b.final_obs.len(), if fin { (n - half) * obs } else { 0 });
                    let bytes: &[u8] = bytemuck::cast_slice(&words);
                    let all = l.rows(bytes, 0, n);
                    assert_eq!(all.rewards.iter().filter(|&&r| r == 2.0).count(), n - half);
                    assert_eq!(all.terminated.iter().filter(|&&t| t == 1).count(), n - half);
                    assert_eq!(all.final_mask.len(), n);
                    assert!(all.info_cols.is_empty());
                }
            }
        }
    }

    #[test]
    fn info_columns_come_last_and_leave_the_other_blocks_in_place() {
        let plain = BatchLayout::new(5, 12, true);
        let cols = plain.with_info_columns(64).unwrap();
        assert_eq!(
            (cols.obs, cols.rewards, cols.final_obs),
            (plain.obs, plain.rewards, plain.final_obs)
        );
        assert_eq!(cols.info_cols, plain.size());
        assert_eq!(cols.size(), plain.size() + 5 * 64);
        assert!(plain.with_info_columns(12).is_none());
        assert!(plain.with_info_columns(usize::MAX - 7).is_none());
        let mut words = vec![0u64; cols.size() / 8];
        // SAFETY: `words` holds the slot; one borrow.
        let rows = unsafe { cols.rows_mut(words.as_mut_ptr().cast(), 1, 3) };
        assert_eq!(rows.info_cols.len(), 3 * 64);
        rows.info_cols[0] = 7;
        let bytes: &[u8] = bytemuck::cast_slice(&words);
        assert_eq!(cols.rows(bytes, 0, 5).info_cols[64], 7);
    }
}
