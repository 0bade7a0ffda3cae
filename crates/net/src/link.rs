//! The client's end of one remote session: the slice of a `VecEnv` that a remote hub hosts.
//!
//! One request and one response per round trip, on express publishers with blocking
//! congestion control (nothing dropped, nothing waits in a batch queue). Responses land in the
//! session's shared [`Inbox`], so one wait covers every hub of the session. A request
//! unanswered for [`RESEND`] is sent again with the same sequence number: the hub answers a
//! repeat from its last answer without stepping twice, and answers to older requests are
//! dropped here, so nothing is lost, repeated or reordered.
//!
//! Requests are sealed with the session's key and answers opened with it
//! ([`envhub_protocol::seal`]) as they arrive, on Zenoh's thread: an answer that does not open
//! (from a peer that is not the hub, or changed on the way) is dropped and counted, never
//! filed, so it can neither fail the session nor crowd out the hub's answers; nor is a sealed
//! answer to another request than the one in flight (a replay).

use crate::client::{Inbox, Network};
use envhub_protocol::batch_codec::{self, RemoteAnswer, RequestBody};
use envhub_protocol::seal::{Direction, SessionKey};
use envhub_protocol::{HubError, keys};
use envhub_shm::{BatchLayout, DataPlaneError, Layout, command};
use std::sync::Arc;
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Silence after which a request is sent again.
pub(crate) const RESEND: Duration = Duration::from_secs(1);

/// Answers this process dropped because they were not sealed with their session's key.
pub static UNSEALED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Requests this process sent again because no answer came within [`RESEND`].
pub static RESENT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// A remote hub's slice of a session.
pub(crate) struct RemoteConn {
    pub hub: String,
    /// The session's id on its hub (for messages).
    session: String,
    network: Arc<Network>,
    publisher: zenoh::pubsub::Publisher<'static>,
    _subscriber: zenoh::pubsub::Subscriber<()>,
    inbox: Arc<Inbox>,
    /// Index of this link in the session (its mailbox in the inbox).
    pub link: usize,
    /// What this connection's answers are filed under ([`Inbox::connection`]).
    connection: u64,
    layout: Layout,
    key: Arc<SessionKey>,
    /// The sequence number of the request in flight: the only answer filed.
    awaited: Arc<std::sync::atomic::AtomicU64>,
    /// Layout of the hub's result rows (its envs only).
    pub rows_layout: BatchLayout,
    seq: u64,
    /// The request in flight, kept for sending again (a shared buffer, not a copy).
    last_request: zenoh::bytes::ZBytes,
    last_sent: Instant,
    closed: bool,
}

impl RemoteConn {
    /// Connects to session `session` on `hub`, sealed with `key`, whose `num_envs` envs have
    /// actions of `act_bytes` and observations of `obs_bytes`.
    #[allow(clippy::too_many_arguments)] // one remote slice's identity, used in one place
    pub fn connect(
        network: Arc<Network>,
        inbox: Arc<Inbox>,
        link: usize,
        hub: &str,
        session: &str,
        key: SessionKey,
        num_envs: usize,
        act_bytes: usize,
        rows_layout: BatchLayout,
    ) -> Result<RemoteConn, HubError> {
        let failed = |e: zenoh::Error| HubError::Network {
            reason: format!("session `{session}` on hub `{hub}`: {e}"),
            hint: "the Zenoh session is failing".into(),
        };
        let z = network.zenoh();
        let connection = Inbox::connection();
        let key = Arc::new(key);
        let awaited = Arc::new(std::sync::atomic::AtomicU64::new(0));
        let subscriber = {
            let (inbox, key, hub) = (inbox.clone(), key.clone(), hub.to_string());
            let awaited = awaited.clone();
            z.declare_subscriber(keys::responses(hub.as_str(), session))
                .callback(move |sample| {
                    let mut bytes = sample.payload().to_bytes().into_owned();
                    match key.open(Direction::Response, &mut bytes) {
                        Ok(seq) if seq == awaited.load(std::sync::atomic::Ordering::Acquire) => {
                            inbox.post(link, connection, bytes)
                        }
                        Ok(seq) => tracing::debug!(hub = %hub, seq, "dropped an answer to an earlier request"),
                        Err(why) => {
                            UNSEALED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                            tracing::debug!(hub = %hub, ?why, "dropped an answer not sealed with the session's key");
                        }
                    }
                })
                .wait()
                .map_err(failed)?
        };
        let publisher = z
            .declare_publisher(keys::requests(hub, session))
            .express(true)
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .priority(zenoh::qos::Priority::DataHigh)
            .wait()
            .map_err(failed)?;
        network.watch(&inbox);
        // A link placed again keeps its mailbox: what the lost hub sent (before or after this)
        // must not pass for an answer of the new one, so answers are taken by connection.
        Ok(RemoteConn {
            connection,
            hub: hub.to_string(),
            session: session.to_string(),
            network,
            publisher,
            _subscriber: subscriber,
            inbox,
            link,
            layout: Layout::new(num_envs, act_bytes),
            key,
            awaited,
            rows_layout,
            seq: 0,
            last_request: zenoh::bytes::ZBytes::default(),
            last_sent: Instant::now(),
            closed: false,
        })
    }

    /// Sends a request (a new sequence number).
    pub fn send(
        &mut self,
        command: u32,
        slot: u32,
        body: &RequestBody<'_>,
    ) -> Result<(), HubError> {
        self.seq += 1;
        let mut request = batch_codec::encode_request(&self.layout, self.seq, command, slot, body);
        self.key.seal(Direction::Request, &mut request);
        self.awaited
            .store(self.seq, std::sync::atomic::Ordering::Release);
        self.last_request = request.into();
        self.put()
    }

    fn put(&mut self) -> Result<(), HubError> {
        self.last_sent = Instant::now();
        self.publisher
            .put(self.last_request.clone())
            .wait()
            .map_err(|e| HubError::Network {
                reason: format!("cannot send to hub `{}`: {e}", self.hub),
                hint: "the Zenoh session is failing".into(),
            })
    }

    /// The answer to the request in flight, if it has arrived.
    pub fn try_take(&mut self) -> Result<Option<RemoteAnswer>, HubError> {
        while let Some(bytes) = self.inbox.take(self.link, self.connection) {
            let Some(answer) = RemoteAnswer::parse(bytes) else {
                return Err(DataPlaneError::Protocol(format!(
                    "hub `{}` sent a response of the wrong size",
                    self.hub
                ))
                .into());
            };
            // Answers to earlier requests (repeats of a resent one) are dropped.
            if answer.header().seq == self.seq {
                return Ok(Some(answer));
            }
        }
        Ok(None)
    }

    /// Whether the hub still holds its token.
    pub fn hub_alive(&self) -> bool {
        self.network.is_alive(&self.hub)
    }

    /// Sends the request in flight again if it has gone unanswered for [`RESEND`].
    pub fn resend_if_silent(&mut self) -> Result<(), HubError> {
        if !self.last_request.is_empty() && self.last_sent.elapsed() >= RESEND {
            tracing::debug!(hub = %self.hub, session = %self.session, seq = self.seq, "no answer yet: sending again");
            RESENT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            self.put()?;
        }
        Ok(())
    }

    /// Blocks until something arrives for this link or `timeout`.
    pub fn wait(&self, timeout: Duration) {
        self.inbox.wait(&[self.link], timeout);
    }

    /// Asks the hub to close the session (no answer awaited: the hub ends it either way
    /// when this client goes).
    pub fn close(&mut self) {
        if std::mem::replace(&mut self.closed, true) || !self.hub_alive() {
            return;
        }
        let _ = self.send(command::CLOSE, envhub_shm::NO_SLOT, &RequestBody::NONE);
    }
}

impl Drop for RemoteConn {
    fn drop(&mut self) {
        self.close();
    }
}
