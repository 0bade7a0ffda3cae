//! A session's last results: which envs they are for, where they lie (in place in a slot, or
//! gathered into a copy), and their infos.

/// Where the last results are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Place {
    #[default]
    Nowhere,
    /// Rows `first..first + env_ids.len()` of batch slot `index`.
    Slot { index: u32, first: usize },
    /// Copied into the session's gather buffers.
    Gathered,
}

/// Results copied out of the slots because they do not lie contiguously in one.
#[derive(Default)]
pub(crate) struct Gathered {
    pub(crate) obs: Vec<u64>,
    pub(crate) obs_len: usize,
    pub(crate) rewards: Vec<f64>,
    pub(crate) terminated: Vec<bool>,
    pub(crate) truncated: Vec<bool>,
    pub(crate) final_mask: Vec<u8>,
    pub(crate) final_obs: Vec<u8>,
    pub(crate) info_cols: Vec<u8>,
}

impl Gathered {
    pub(crate) fn clear(&mut self) {
        self.obs_len = 0;
        self.rewards.clear();
        self.terminated.clear();
        self.truncated.clear();
        self.final_mask.clear();
        self.final_obs.clear();
        self.info_cols.clear();
    }

    pub(crate) fn push_obs(&mut self, bytes: &[u8]) {
        let end = self.obs_len + bytes.len();
        if self.obs.len() * 8 < end {
            self.obs.resize(end.div_ceil(8), 0);
        }
        let all: &mut [u8] = bytemuck::cast_slice_mut(&mut self.obs);
        all[self.obs_len..end].copy_from_slice(bytes);
        self.obs_len = end;
    }

    pub(crate) fn obs_bytes(&self) -> &[u8] {
        &bytemuck::cast_slice(&self.obs)[..self.obs_len]
    }
}

/// The session's last results: which envs, where they lie, and their infos.
#[derive(Default)]
pub(crate) struct Results {
    pub(crate) env_ids: Vec<usize>,
    pub(crate) place: Place,
    /// One per env of `env_ids` when any reported info, else empty.
    pub(crate) infos: Vec<serde_json::Value>,
    pub(crate) gathered: Gathered,
    /// Scratch for the `(slot, env)` rows being placed, kept to avoid allocating per step.
    pub(crate) rows: Vec<(u32, usize)>,
}

impl Results {
    pub fn is_set(&self) -> bool {
        self.place != Place::Nowhere
    }
}
