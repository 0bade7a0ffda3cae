//! What a reset, step or `recv` returns: the results of some envs, viewed in place in a batch
//! slot when they lie there contiguously, else gathered.

/// The results of a reset or step, for every env of the batch (or, from
/// `VecEnv::recv`, for exactly the envs listed in `env_ids`).
/// Observations, rewards and flags are viewed in place in the session's shared-memory batch
/// slot, whatever the number of workers; only results that do not lie contiguously there
/// (`recv` of envs picked out of a worker's) are gathered into a copy.
#[derive(Debug)]
pub struct Batch<'a> {
    /// The envs these results belong to, in order.
    pub env_ids: &'a [usize],
    /// Observations, `observation_space().byte_len()` bytes per env, contiguous.
    pub obs: &'a [u8],
    /// Rewards.
    pub rewards: &'a [f64],
    /// Terminated flags.
    pub terminated: &'a [bool],
    /// Truncated flags.
    pub truncated: &'a [bool],
    pub(crate) infos: &'a [serde_json::Value],
    pub(crate) final_mask: &'a [u8],
    pub(crate) final_obs: &'a [u8],
    pub(crate) info_cols: &'a [u8],
    pub(crate) in_place: bool,
    /// The slot the results lie in, when viewed in place.
    pub(crate) slot: Option<&'a SlotLease>,
}

use envhub_shm::SlotLease;

static NO_INFO: serde_json::Value = serde_json::Value::Null;

impl<'a> Batch<'a> {
    /// Observations as `f32` (when the observation space is a `float32` box).
    pub fn obs_f32(&self) -> &'a [f32] {
        bytemuck::cast_slice(self.obs)
    }

    /// The info of the `k`-th env of the batch (`Null` if it reported none).
    pub fn info(&self, k: usize) -> &'a serde_json::Value {
        self.infos.get(k).unwrap_or(&NO_INFO)
    }

    /// The infos of the batch's envs, in order (empty when none reported any).
    pub fn infos(&self) -> &'a [serde_json::Value] {
        self.infos
    }

    /// The final-observation mask and final observations of the batch (`same_step`
    /// autoreset; empty otherwise), as the slot's blocks.
    pub fn final_blocks(&self) -> (&'a [u8], &'a [u8]) {
        (self.final_mask, self.final_obs)
    }

    /// The batch's rows of typed info columns (`SessionOptions::info_row_bytes` per env,
    /// as the Python worker wrote them; empty when the session has none). Their schema
    /// arrives in the infos: `envhub_protocol::info_columns`.
    pub fn info_columns(&self) -> &'a [u8] {
        self.info_cols
    }

    /// Whether any env reported info.
    pub fn has_info(&self) -> bool {
        !self.infos.is_empty()
    }

    /// Whether the results are viewed in place in a batch slot (else gathered into a copy).
    pub fn in_place(&self) -> bool {
        self.in_place
    }

    /// A lease on the shared-memory slot these results lie in: while it lives, the slot is
    /// neither written again nor unmapped, so the addresses of this batch's blocks stay valid
    /// and their contents unchanged (the Python client makes it the base of its numpy
    /// arrays). `None` when the results were gathered or lie in the scratch slot, which is
    /// reused: copy them instead.
    pub fn lease(&self) -> Option<SlotLease> {
        self.slot.filter(|s| s.lendable()).cloned()
    }

    /// same_step autoreset: the final observation of the `k`-th env if its episode ended
    /// in this step.
    pub fn final_obs(&self, k: usize) -> Option<&'a [u8]> {
        if self.final_mask.get(k).copied().unwrap_or(0) == 0 {
            return None;
        }
        let ob = self.obs.len() / self.env_ids.len().max(1);
        self.final_obs.get(k * ob..(k + 1) * ob)
    }
}

/// Views flag bytes as `bool`s, if every byte is 0 or 1 (the worker writes nothing else;
/// a corrupted slot is caught when the results are collected).
pub(crate) fn as_bools(flags: &[u8]) -> Option<&[bool]> {
    flags.iter().all(|&f| f <= 1).then(|| {
        // SAFETY: every byte is 0 or 1, the two valid bit patterns of `bool`, which has the
        // size and alignment of `u8`.
        unsafe { std::slice::from_raw_parts(flags.as_ptr().cast::<bool>(), flags.len()) }
    })
}
