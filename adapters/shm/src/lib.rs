//! envhub's data plane: iceoryx2 channels between a client and the workers that host its envs.
//!
//! Each worker gets its own channel, so the hub is never on the per-step path. A request and
//! a response are one shared-memory sample each, with one block per field covering all of the
//! worker's envs (see [`Layout`]): the env writes its observation straight into the response
//! sample and the client reads it where it lies. The trade-off: a session with several
//! workers has its observations in several samples, so a contiguous batch over all envs costs
//! one copy per worker on the client; with one worker nothing is copied.
//!
//! Waiting blocks on iceoryx2 events after a short spin, so idle workers cost no CPU.

mod batch;
mod channel;
mod job;
mod layout;
mod process;
mod serve;
mod transport;
mod wait;

pub use batch::{EnvBatch, Frame, frames_section};
pub use channel::{ClientChannel, Reply, Request, Response, WorkerChannel};
pub use job::{ReadySpec, WorkerJob, WorkerReply};
pub use layout::{
    BLOCK_ALIGN, Layout, RequestHeader, ResponseBlocks, ResponseBlocksMut, ResponseHeader, command,
    env_flag, status,
};
pub use process::{ProcessWatch, die_with_parent, kill};
pub use serve::{ServedBatch, serve_batch};
pub use transport::{ChannelName, MAX_BORROWED_RESPONSES, cleanup_dead_nodes, remove_namespace};
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
}
