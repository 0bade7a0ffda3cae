//! The EnvPool mode's state (`env_pool.rs` drives it): where each env is, the actions
//! queued for busy workers, and the results that arrived but were not handed out.

use std::collections::VecDeque;

/// Where an env is in the EnvPool mode.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum EnvState {
    /// Handed to the caller (or never started): it may be sent.
    Idle,
    /// Sent while its worker was busy: goes out when the worker answers.
    Queued,
    /// In a request a worker is serving.
    InFlight,
    /// Its results arrived and wait to be handed out.
    Ready,
}

/// One worker answer's envs whose results arrived and are not all handed out yet: the slot
/// their rows are in, their infos, and how many of them were handed out. Kept per answer,
/// not per env, so taking an answer costs the same for 1 env as for 1,000.
pub(crate) struct Arrived {
    pub(crate) slot: u32,
    /// The envs, in row order.
    pub(crate) envs: Vec<usize>,
    /// One info per env, or empty when the answer carried none.
    pub(crate) infos: Vec<serde_json::Value>,
    /// The first env not handed out yet.
    pub(crate) next: usize,
    /// Keeps the slot from being written again until the rows are handed out: a worker's
    /// request clears the reward and flags of its envs it does not step.
    pub(crate) _lease: Option<envhub_shm::SlotLease>,
}

impl Arrived {
    /// The envs not handed out yet.
    pub(crate) fn left(&self) -> &[usize] {
        &self.envs[self.next..]
    }
}

/// The EnvPool mode's state: each env's place, queued actions, and arrived results.
pub(crate) struct EnvPoolState {
    pub(crate) batch_size: usize,
    pub(crate) state: Vec<EnvState>,
    /// One action row per env, valid where the env is queued.
    pub(crate) actions: Vec<u8>,
    /// Answers whose results arrived, in the order they arrived.
    pub(crate) arrived: VecDeque<Arrived>,
    /// How many envs `arrived` holds that were not handed out.
    pub(crate) arrived_envs: usize,
}

impl EnvPoolState {
    pub(crate) fn new(batch_size: usize, num_envs: usize, action_bytes: usize) -> EnvPoolState {
        EnvPoolState {
            batch_size,
            state: vec![EnvState::Idle; num_envs],
            actions: vec![0; num_envs * action_bytes],
            arrived: VecDeque::new(),
            arrived_envs: 0,
        }
    }

    /// Whether any env is queued, in flight or not handed out.
    pub(crate) fn busy(&self) -> bool {
        self.state.iter().any(|&s| s != EnvState::Idle)
    }

    /// Whether any row of `slot` in `envs` was not handed out yet.
    pub(crate) fn holds_rows(&self, slot: u32, envs: std::ops::Range<usize>) -> bool {
        self.arrived
            .iter()
            .any(|a| a.slot == slot && a.left().iter().any(|e| envs.contains(e)))
    }

    /// Drops every arrived result.
    pub(crate) fn clear_arrived(&mut self) {
        self.arrived.clear();
        self.arrived_envs = 0;
    }

    pub(crate) fn count(&self, s: EnvState) -> usize {
        self.state.iter().filter(|&&x| x == s).count()
    }
}
