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

/// An env whose results arrived: the slot its row is in, and its info.
pub(crate) struct Arrived {
    pub(crate) env: usize,
    pub(crate) slot: u32,
    pub(crate) info: serde_json::Value,
    /// Keeps the slot from being written again until the row is handed out: a worker's
    /// request clears the reward and flags of its envs it does not step.
    pub(crate) _lease: Option<envhub_shm::SlotLease>,
}

/// The EnvPool mode's state: each env's place, queued actions, and arrived results.
pub(crate) struct EnvPoolState {
    pub(crate) batch_size: usize,
    pub(crate) state: Vec<EnvState>,
    /// One action row per env, valid where the env is queued.
    pub(crate) actions: Vec<u8>,
    /// Envs whose results arrived, in the order they arrived.
    pub(crate) arrived: VecDeque<Arrived>,
}

impl EnvPoolState {
    pub(crate) fn new(batch_size: usize, num_envs: usize, action_bytes: usize) -> EnvPoolState {
        EnvPoolState {
            batch_size,
            state: vec![EnvState::Idle; num_envs],
            actions: vec![0; num_envs * action_bytes],
            arrived: VecDeque::new(),
        }
    }

    /// Whether any env is queued, in flight or not handed out.
    pub(crate) fn busy(&self) -> bool {
        self.state.iter().any(|&s| s != EnvState::Idle)
    }

    pub(crate) fn count(&self, s: EnvState) -> usize {
        self.state.iter().filter(|&&x| x == s).count()
    }
}
