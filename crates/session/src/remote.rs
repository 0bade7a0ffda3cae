//! Slices of a session that another hub hosts, as the engine sees them: something that takes
//! a request for its envs and answers with their result rows, the same statuses as a local
//! worker. How they are reached (Zenoh, in `envhub-net`) is the layer above's business.

use envhub_protocol::batch_codec::{RemoteAnswer, RequestBody};
use envhub_protocol::{HubError, OpenReply, OpenRequest};
use envhub_shm::BatchLayout;
use std::time::Duration;

/// The place name of this machine's own workers (in [`Slice::place`] and
/// `VecEnv::placement`).
pub const LOCAL: &str = "local";

/// A run of a session's envs and where it runs: [`LOCAL`] or a hub's name.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Slice {
    /// A hub's name, or [`LOCAL`].
    pub place: String,
    /// How many envs.
    pub num_envs: usize,
}

/// One remote hub's slice of a session, connected.
pub trait RemoteSlice: Send {
    /// The hub's name.
    fn hub(&self) -> &str;
    /// Its mailbox in the session's shared inbox (see [`SliceOpener::wait_any`]).
    fn mailbox(&self) -> usize;
    /// The layout of the result rows it answers with (its envs only).
    fn rows_layout(&self) -> &BatchLayout;
    /// Sends a request (a new sequence number).
    fn send(&mut self, command: u32, slot: u32, body: &RequestBody<'_>) -> Result<(), HubError>;
    /// The answer to the request in flight, if it has arrived.
    fn try_take(&mut self) -> Result<Option<RemoteAnswer>, HubError>;
    /// Whether the hub is still there.
    fn alive(&self) -> bool;
    /// Sends the request in flight again if it has gone unanswered for a while.
    fn resend_if_silent(&mut self) -> Result<(), HubError>;
    /// Blocks until something arrives for this slice or `timeout`.
    fn wait(&self, timeout: Duration);
    /// Asks the hub to end the slice's session (no answer awaited).
    fn close(&mut self);
}

/// Opens a session's slices on other hubs; one per session (its slices share one inbox).
pub trait SliceOpener: Send + Sync {
    /// This client's identity on the network (what hubs watch to end its sessions).
    fn client_id(&self) -> String;
    /// Opens `request` on `hub` and connects to it as mailbox `mailbox`; `with_final`: the
    /// rows carry final observations (`same_step` autoreset).
    fn open(
        &self,
        hub: &str,
        request: &OpenRequest,
        mailbox: usize,
        with_final: bool,
        start_timeout: Duration,
    ) -> Result<(OpenReply, Box<dyn RemoteSlice>), HubError>;
    /// Whether `hub` is live.
    fn is_alive(&self, hub: &str) -> bool;
    /// Blocks until something arrives for one of `mailboxes` or `timeout`.
    fn wait_any(&self, mailboxes: &[usize], timeout: Duration);
}
