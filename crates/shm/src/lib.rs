//! envhub's data plane: iceoryx2 channels between a client and the workers that host its envs.
//!
//! Each worker gets its own channel, so the hub is never on the per-step path. A request and
//! a response are one iceoryx2 sample each (command, actions, status, info); the results go to
//! a batch slot ([`SlotPool`]) that all the session's workers share, each writing its own rows:
//! the env writes its observation straight into the slot, and the client hands the whole
//! `[num_envs, ...]` block to its user where it lies, whatever the number of workers. The
//! trade-off: slots are shared-memory objects of envhub's own (iceoryx2 gives each publisher
//! its own segment, so several workers cannot fill one sample), named per session and removed
//! when it closes or its owner dies.
//!
//! Waiting blocks on iceoryx2 events after a short spin, so idle workers cost no CPU.

mod batch;
mod channel;
mod job;
mod layout;
mod pingpong;
mod process;
mod serve;
mod slots;
mod transport;
mod wait;

pub use batch::{EnvBatch, Frame, frames_section};
pub use channel::{ClientChannel, NO_SLOT, Reply, Request, Response, WorkerChannel, wait_any};
pub use job::{ReadySpec, WORKER_PROTOCOL, WorkerIdentity, WorkerJob, WorkerPython, WorkerReply};
pub use layout::{
    BLOCK_ALIGN, BatchLayout, Layout, RequestHeader, ResponseBlocks, ResponseBlocksMut,
    ResponseHeader, command, env_flag, status,
};
pub use pingpong::{ping, pong};
pub use process::{PidFd, ProcessWatch, die_with_parent, kill};
pub use serve::{ServedBatch, serve_batch};
pub use slots::{
    Bell, Doorbells, MAX_SLOTS, Side, Slot, SlotLease, SlotMap, SlotPool, SlotsName,
    remove_stale_slots, shm_free_bytes,
};
pub use transport::{ChannelName, cleanup_dead_nodes, remove_namespace};
pub use wait::WaitPolicy;

/// A failure of the data plane itself.
#[derive(Debug, thiserror::Error)]
pub enum DataPlaneError {
    /// An iceoryx2 call failed.
    #[error("shared-memory {what} failed: {detail}")]
    Ipc {
        /// What was attempted.
        what: &'static str,
        /// iceoryx2's error.
        detail: String,
    },
    /// The two sides disagree about the protocol.
    #[error("data-plane protocol error: {0}")]
    Protocol(String),
    /// The peer process is gone or stopped answering.
    #[error("{0}")]
    PeerGone(String),
    /// `/dev/shm` cannot hold a shared-memory object the session needs (reserved up front, so
    /// a full `/dev/shm` is this error instead of a worker's SIGBUS on first touch).
    #[error(
        "`/dev/shm` is too small for {what}: it needs {needed} bytes, {free} bytes are free\nhint: make `/dev/shm` larger (`mount -o remount,size=8g /dev/shm`; Docker: `--shm-size=8g`), remove stale `/dev/shm` files, or use fewer envs or a smaller `pool_bytes`"
    )]
    NoSpace {
        /// What was being created.
        what: &'static str,
        /// Bytes it needs.
        needed: u64,
        /// Bytes free in `/dev/shm` when it failed.
        free: u64,
    },
}
