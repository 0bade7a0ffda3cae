//! A session's slices on other hubs, opened over Zenoh: the engine's [`SliceOpener`] and
//! [`RemoteSlice`] for the network.

use crate::client::{Inbox, Network};
use crate::link::RemoteConn;
use envhub_protocol::batch_codec::{RemoteAnswer, RequestBody};
use envhub_protocol::untrusted::check_open_reply;
use envhub_protocol::{HubError, OpenReply, OpenRequest};
use envhub_session::{RemoteSlice, SliceOpener};
use envhub_shm::BatchLayout;
use std::sync::Arc;
use std::time::Duration;

/// Opens the remote slices of one session; they share its inbox, so one wait covers them all.
pub struct ZenohSlices {
    network: Arc<Network>,
    inbox: Arc<Inbox>,
}

impl ZenohSlices {
    /// The opener of a new session over `network`.
    pub fn new(network: Arc<Network>) -> Arc<ZenohSlices> {
        Arc::new(ZenohSlices {
            network,
            inbox: Arc::new(Inbox::default()),
        })
    }
}

impl SliceOpener for ZenohSlices {
    fn client_id(&self) -> String {
        self.network.client_id().to_string()
    }

    fn open(
        &self,
        hub: &str,
        request: &OpenRequest,
        mailbox: usize,
        with_final: bool,
        start_timeout: Duration,
    ) -> Result<(OpenReply, Box<dyn RemoteSlice>), HubError> {
        let (reply, key) = self.network.open_session(hub, request, start_timeout)?;
        let n = request.config.num_envs;
        // The hub's word on its spaces and session id is checked before any size is computed
        // from it.
        let (layout, rows_layout) = check_open_reply(hub, &reply, n, with_final)?;
        let conn = RemoteConn::connect(
            self.network.clone(),
            self.inbox.clone(),
            mailbox,
            hub,
            &reply.session,
            key,
            n,
            layout.act_bytes,
            rows_layout,
        )?;
        Ok((reply, Box::new(conn)))
    }

    fn is_alive(&self, hub: &str) -> bool {
        self.network.is_alive(hub)
    }

    fn wait_any(&self, mailboxes: &[usize], timeout: Duration) {
        self.inbox.wait(mailboxes, timeout);
    }
}

impl RemoteSlice for RemoteConn {
    fn hub(&self) -> &str {
        &self.hub
    }

    fn mailbox(&self) -> usize {
        self.link
    }

    fn rows_layout(&self) -> &BatchLayout {
        &self.rows_layout
    }

    fn send(&mut self, command: u32, slot: u32, body: &RequestBody<'_>) -> Result<(), HubError> {
        RemoteConn::send(self, command, slot, body)
    }

    fn try_take(&mut self) -> Result<Option<RemoteAnswer>, HubError> {
        RemoteConn::try_take(self)
    }

    fn alive(&self) -> bool {
        self.hub_alive()
    }

    fn resend_if_silent(&mut self) -> Result<(), HubError> {
        RemoteConn::resend_if_silent(self)
    }

    fn wait(&self, timeout: Duration) {
        RemoteConn::wait(self, timeout);
    }

    fn close(&mut self) {
        RemoteConn::close(self);
    }
}
