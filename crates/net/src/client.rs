//! A client's view of the network: one Zenoh session per process and network config, which
//! watches the hubs' liveliness tokens (history on, so hubs already up are seen at once),
//! asks hubs for their info, catalog and adapters, and opens sessions on them.
//!
//! The client holds its own token (`envhub/client/<id>`): hubs end its sessions when it goes.
//!
//! Each hub also holds an identity token naming its Zenoh id (`envhub/hub/<name>/zid/<zid>`):
//! the client takes answers to its queries of a hub only from that id, so a peer that declares
//! a queryable under a live hub's name is not answered in its place (docs/design/security.md says
//! what this does and does not stop).

use crate::config::{self, NetConfig};
use envhub_protocol::handshake;
use envhub_protocol::seal::{Cipher, SessionKey};
use envhub_protocol::{HubError, HubInfo, OpenReply, OpenRequest, keys};
use serde::de::DeserializeOwned;
use serde_json::Value;
use std::collections::{BTreeSet, HashMap, VecDeque};
use std::sync::{Arc, Condvar, Mutex, Weak};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How long a wait for an echo spins (yielding the core) before it sleeps.
const SPIN: Duration = Duration::from_micros(300);

/// How long `hubs()` waits for hubs to show up when none has yet (discovery, connecting).
pub const DISCOVERY: Duration = Duration::from_secs(2);
/// After the last hub showed up, how long to wait for more.
const SETTLE: Duration = Duration::from_millis(300);

/// The live hubs and who waits on news of them.
#[derive(Default)]
struct Liveness {
    seen: Mutex<Seen>,
    changed: Condvar,
    inboxes: Mutex<Vec<Weak<Inbox>>>,
}

/// What the hubs' tokens say.
#[derive(Default)]
struct Seen {
    /// The hubs holding their token, with when it showed up.
    alive: HashMap<String, Instant>,
    /// The Zenoh ids of each hub's live identity tokens (one, unless two claim a name).
    ids: HashMap<String, BTreeSet<String>>,
}

impl Seen {
    /// Notes a token's coming (`put`) or going; whether the key was a hub's.
    fn note(&mut self, key: &str, put: bool) -> bool {
        if let Some(name) = keys::hub_of_token(key) {
            if put {
                self.alive.insert(name.to_string(), Instant::now());
            } else {
                tracing::warn!(hub = name, "hub lost");
                self.alive.remove(name);
            }
            return true;
        }
        let Some((name, zid)) = keys::hub_id_of_token(key) else {
            return false;
        };
        if put {
            self.ids
                .entry(name.to_string())
                .or_default()
                .insert(zid.to_string());
        } else if let Some(ids) = self.ids.get_mut(name) {
            ids.remove(zid);
            if ids.is_empty() {
                self.ids.remove(name);
            }
        }
        true
    }

    /// The names of the hubs holding their token, sorted.
    fn names(&self) -> Vec<String> {
        let mut names: Vec<String> = self.alive.keys().cloned().collect();
        names.sort();
        names
    }

    /// The one Zenoh id hub `name` answers from; `None` while its identity token is unseen.
    fn id_of(&self, name: &str) -> Result<Option<String>, HubError> {
        let Some(ids) = self.ids.get(name) else {
            return Ok(None);
        };
        let ids: Vec<&str> = ids.iter().map(String::as_str).collect();
        match ids[..] {
            [] => Ok(None),
            [id] => Ok(Some(id.to_string())),
            _ => Err(HubError::Network {
                reason: format!(
                    "hub `{name}` is claimed by more than one Zenoh peer (ids {}); its answers cannot be told from an impostor's",
                    ids.join(" and ")
                ),
                hint: "only one hub of a name runs on a network: stop the other, or find the peer that holds a token in its name".into(),
            }),
        }
    }
}

/// The ciphers a session's open offers, preferred first: the one `ENVHUB_SESSION_CIPHER`
/// names, else both with the faster on this CPU first.
fn cipher_offer() -> Result<Vec<Cipher>, HubError> {
    use envhub_core::env_vars::ENVHUB_SESSION_CIPHER;
    match std::env::var(ENVHUB_SESSION_CIPHER) {
        Ok(name) => Cipher::from_name(name.trim())
            .map(|c| vec![c])
            .ok_or_else(|| HubError::InvalidConfig {
                what: ENVHUB_SESSION_CIPHER,
                reason: format!(
                    "{name:?} is no cipher; valid: {}",
                    Cipher::ALL.map(Cipher::name).join(", ")
                ),
            }),
        Err(_) => {
            let first = Cipher::fastest_here();
            let rest = Cipher::ALL.into_iter().filter(|&c| c != first);
            Ok(std::iter::once(first).chain(rest).collect())
        }
    }
}

/// This process's presence on the network.
pub struct Network {
    session: zenoh::Session,
    client_id: String,
    /// This process's identity in key exchanges (what hubs' per-client limits count).
    identity: envhub_protocol::handshake::Identity,
    /// The hub identities this user pinned.
    known: crate::identity::KnownHubs,
    _token: zenoh::liveliness::LivelinessToken,
    _watch: zenoh::pubsub::Subscriber<()>,
    liveness: Arc<Liveness>,
    opened: Instant,
}

impl std::fmt::Debug for Network {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Network")
            .field("client", &self.client_id)
            .finish()
    }
}

impl Network {
    /// The process's network for `net` (opened on first use, then shared).
    /// A config that names no endpoint reaches this user's local hubs: when they change (a
    /// hub started or left), a new network is opened for what follows (sessions keep theirs).
    pub fn get(net: &NetConfig) -> Result<Arc<Network>, HubError> {
        static OPEN: Mutex<Vec<(NetConfig, NetConfig, Arc<Network>)>> = Mutex::new(Vec::new());
        let resolved = net.with_local_hubs();
        let mut open = OPEN.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((_, _, n)) = open.iter().find(|(c, r, _)| c == net && *r == resolved) {
            return Ok(n.clone());
        }
        let n = Arc::new(Network::open(&resolved)?);
        open.retain(|(c, _, _)| c != net);
        open.push((net.clone(), resolved, n.clone()));
        Ok(n)
    }

    fn open(net: &NetConfig) -> Result<Network, HubError> {
        let session = config::open(net, false)?;
        let failed = |e: zenoh::Error| HubError::Network {
            reason: e.to_string(),
            hint: "the Zenoh session is failing".into(),
        };
        let identity = envhub_protocol::handshake::Identity::generate()
            .map_err(|e| HubError::Internal(format!("cannot make a client identity: {e}")))?;
        // The token is named by the identity: a hub ends a session when the token of the key
        // that opened it goes, so a session cannot outlive its client on another's token.
        let client_id = identity.public_hex();
        let liveness = Arc::new(Liveness::default());
        let watch = {
            let liveness = liveness.clone();
            session
                .liveliness()
                .declare_subscriber(keys::ALL_HUB_TOKENS)
                .history(true)
                .callback(move |sample| {
                    let put = sample.kind() == zenoh::sample::SampleKind::Put;
                    let mut seen = liveness.seen.lock().unwrap_or_else(|e| e.into_inner());
                    if !seen.note(sample.key_expr().as_str(), put) {
                        return;
                    }
                    drop(seen);
                    liveness.changed.notify_all();
                    let inboxes = liveness.inboxes.lock().unwrap_or_else(|e| e.into_inner());
                    for inbox in inboxes.iter().filter_map(Weak::upgrade) {
                        inbox.ring();
                    }
                })
                .wait()
                .map_err(failed)?
        };
        let token = session
            .liveliness()
            .declare_token(keys::client_token(&client_id))
            .wait()
            .map_err(failed)?;
        Ok(Network {
            session,
            client_id,
            identity,
            known: crate::identity::KnownHubs::new(net.known_hubs.as_deref()),
            _token: token,
            _watch: watch,
            liveness,
            opened: Instant::now(),
        })
    }

    /// This client's id: its identity's public key, 64 hex digits (its token is
    /// `envhub/client/<id>`).
    pub fn client_id(&self) -> &str {
        &self.client_id
    }

    /// Whether hub `name` holds its token.
    pub fn is_alive(&self, name: &str) -> bool {
        self.seen().alive.contains_key(name)
    }

    fn seen(&self) -> std::sync::MutexGuard<'_, Seen> {
        self.liveness.seen.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Waits up to `wait` for a hub to come or go; what is seen then.
    fn seen_after<'a>(
        &'a self,
        seen: std::sync::MutexGuard<'a, Seen>,
        wait: Duration,
    ) -> std::sync::MutexGuard<'a, Seen> {
        self.liveness
            .changed
            .wait_timeout(seen, wait)
            .unwrap_or_else(|e| e.into_inner())
            .0
    }

    /// Names of the live hubs, sorted. Right after the network opens, waits (up to
    /// `discovery`) for the hubs to show up and settle.
    pub fn live_hubs(&self, discovery: Duration) -> Vec<String> {
        let deadline = self.opened + discovery;
        let mut seen = self.seen();
        loop {
            let now = Instant::now();
            let newest = seen.alive.values().max().copied();
            let settled = newest.is_some_and(|t| now.duration_since(t) >= SETTLE);
            if settled || now >= deadline {
                break;
            }
            let wait = match newest {
                Some(t) => (t + SETTLE).saturating_duration_since(now),
                None => deadline - now,
            };
            seen = self.seen_after(seen, wait.max(Duration::from_millis(1)));
        }
        seen.names()
    }

    /// Waits up to `timeout` for every hub of `names` to be live; the first missing one is
    /// an error naming the live hubs and the closest names.
    pub fn wait_for(&self, names: &[String], timeout: Duration) -> Result<(), HubError> {
        let deadline = Instant::now() + timeout;
        let mut seen = self.seen();
        loop {
            let missing = names.iter().find(|n| !seen.alive.contains_key(*n));
            let Some(missing) = missing else {
                return Ok(());
            };
            let now = Instant::now();
            if now >= deadline {
                return Err(unknown_hub(missing, &seen.names()));
            }
            seen = self.seen_after(seen, deadline - now);
        }
    }

    /// The info of every live hub (waiting for discovery as [`Network::live_hubs`]).
    pub fn hubs(&self, discovery: Duration) -> Result<Vec<HubInfo>, HubError> {
        let names = self.live_hubs(discovery);
        let mut infos = Vec::new();
        for name in names {
            match self.query::<HubInfo>(&name, &keys::hub_info(&name), None, Duration::from_secs(3))
            {
                Ok(info) => infos.push(info),
                // Gone between the token and the query, or not answering: not live.
                Err(e) => tracing::debug!(hub = %name, error = %e, "hub did not answer"),
            }
        }
        Ok(infos)
    }

    /// The Zenoh id hub `name` answers from, as its identity token says. Waits up to `wait`
    /// for the token (a hub reached through `--connect` right after the network opened); two
    /// ids for one name are an error naming both.
    pub fn hub_id(&self, name: &str, wait: Duration) -> Result<String, HubError> {
        let deadline = Instant::now() + wait;
        let mut seen = self.seen();
        loop {
            if let Some(id) = seen.id_of(name)? {
                return Ok(id);
            }
            let now = Instant::now();
            if now >= deadline {
                if !seen.alive.contains_key(name) {
                    return Err(unknown_hub(name, &seen.names()));
                }
                return Err(HubError::Network {
                    reason: format!(
                        "hub `{name}` holds no identity token (`{}`), so its answers cannot be told from an impostor's",
                        keys::hub_id_token(name, "<zenoh id>")
                    ),
                    hint: "the hub runs an older envhub than this client: update it".into(),
                });
            }
            seen = self.seen_after(seen, deadline - now);
        }
    }

    /// Asks hub `hub` a query; its `{"ok": ...}` reply, or the error it sent. Only an answer
    /// from the hub's Zenoh id ([`Network::hub_id`]) is taken, the first one, as soon as it
    /// comes: answers of other peers are dropped, and the query's end is not waited for (a
    /// query waiting for every answerer stalled opens across a veth until the link's lease).
    pub fn query<T: DeserializeOwned>(
        &self,
        hub: &str,
        key: &str,
        payload: Option<Vec<u8>>,
        timeout: Duration,
    ) -> Result<T, HubError> {
        let from = self.hub_id(hub, DISCOVERY)?;
        let lost = |why: String| HubError::HubLost {
            hub: hub.to_string(),
            envs: "-".into(),
            why,
        };
        let (tx, rx) = std::sync::mpsc::channel();
        // No consolidation: each answer is handed over as it arrives (the default keeps them
        // all until the query ends).
        let mut get = self
            .session
            .get(key)
            .timeout(timeout)
            .consolidation(zenoh::query::ConsolidationMode::None);
        if let Some(p) = payload {
            get = get.payload(p);
        }
        get.callback(move |reply| {
            let _ = tx.send(reply);
        })
        .wait()
        .map_err(|e| lost(format!("query failed: {e}")))?;
        let deadline = Instant::now() + timeout + Duration::from_secs(1);
        loop {
            // The channel closes (Err) when the query ends.
            let reply = rx
                .recv_timeout(deadline.saturating_duration_since(Instant::now()))
                .map_err(|_| {
                    lost(format!(
                        "no answer to `{key}` from the hub's Zenoh id {from} within {timeout:?}"
                    ))
                })?;
            let replier = reply.replier_id().map(|id| id.zid().to_string());
            if replier.as_deref() == Some(from.as_str()) {
                return read_reply(hub, &reply);
            }
            tracing::debug!(
                hub,
                key,
                replier = replier.as_deref().unwrap_or("none"),
                expected = %from,
                "dropped an answer that is not from the hub's Zenoh id"
            );
        }
    }

    /// Opens a session on `hub` (starting its workers takes up to `start_timeout`), with the
    /// first answer from the hub's Zenoh id ([`Network::query`]): the reply and the session's
    /// key, agreed by a key exchange bound to the hub's pinned identity
    /// ([`envhub_protocol::handshake`], [`crate::identity`]).
    pub(crate) fn open_session(
        &self,
        hub: &str,
        request: &OpenRequest,
        start_timeout: Duration,
    ) -> Result<(OpenReply, SessionKey), HubError> {
        let (hello, pending) =
            handshake::client_hello(&self.identity, hub, unix_ms(), &cipher_offer()?)
                .map_err(|e| HubError::Internal(format!("cannot start a key exchange: {e}")))?;
        let payload = serde_json::to_vec(&serde_json::json!({"request": request, "hello": hello}))
            .expect("requests serialize");
        // A hub reads no longer request: say so here, naming the hub and the limit.
        envhub_protocol::untrusted::check_open_request_size(payload.len()).map_err(|why| {
            HubError::InvalidConfig {
                what: "open request",
                reason: format!(
                    "the request to open `{}` on hub `{hub}` is {why}\nhint: pass large data to \
                     the env some other way than kwargs (a registry entry on the hub)",
                    request.id
                ),
            }
        })?;
        let reply: OpenReply = self.query(
            hub,
            &keys::hub_open(hub),
            Some(payload.clone()),
            start_timeout + Duration::from_secs(5),
        )?;
        let (identity, key) = pending
            .finish(hub, &reply.session, &payload, &reply.hello)
            .map_err(|e| envhub_protocol::untrusted::lying(hub, e))?;
        self.known.check(hub, &identity)?;
        Ok((reply, key))
    }

    /// Times `n` raw Zenoh round trips of `bytes`-byte messages to hub `hub`'s echo, with the
    /// data path's QoS and the same kind of wake-up (a channel) as a session's wait.
    pub fn echo_round_trips(
        &self,
        hub: &str,
        bytes: usize,
        n: usize,
    ) -> Result<Vec<Duration>, HubError> {
        let failed = |e: zenoh::Error| HubError::Network {
            reason: format!("echo of hub `{hub}`: {e}"),
            hint: "the Zenoh session is failing".into(),
        };
        let (req, rep) = keys::hub_echo(hub);
        let (tx, rx) = std::sync::mpsc::channel();
        let _subscriber = self
            .session
            .declare_subscriber(rep)
            .callback(move |s| {
                let _ = tx.send(s.payload().len());
            })
            .wait()
            .map_err(failed)?;
        let publisher = self
            .session
            .declare_publisher(req)
            .express(true)
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .priority(zenoh::qos::Priority::DataHigh)
            .wait()
            .map_err(failed)?;
        // One buffer, shared by every put (a clone is a reference): the echo times the wire,
        // not a copy of the message here.
        let payload = zenoh::bytes::ZBytes::from(vec![0u8; bytes]);
        let lost = || HubError::HubLost {
            hub: hub.to_string(),
            envs: "-".into(),
            why: "no echo within 2 s".into(),
        };
        // Until the subscriber's declaration has reached the hub, echoes can be missed.
        let ready = Instant::now();
        loop {
            publisher.put(payload.clone()).wait().map_err(failed)?;
            if rx.recv_timeout(Duration::from_millis(100)).is_ok() {
                break;
            }
            if ready.elapsed() > Duration::from_secs(2) {
                return Err(lost());
            }
        }
        while rx.try_recv().is_ok() {}
        let mut times = Vec::with_capacity(n);
        for _ in 0..n {
            let t = Instant::now();
            publisher.put(payload.clone()).wait().map_err(failed)?;
            // The same wait as a session's: a short spin, then sleep.
            let mut got = false;
            while t.elapsed() < SPIN {
                if rx.try_recv().is_ok() {
                    got = true;
                    break;
                }
                std::thread::yield_now();
            }
            if !got {
                rx.recv_timeout(Duration::from_secs(2))
                    .map_err(|_| lost())?;
            }
            times.push(t.elapsed());
        }
        Ok(times)
    }

    pub(crate) fn zenoh(&self) -> &zenoh::Session {
        &self.session
    }

    /// Rings `inbox` whenever a hub comes or goes (waiters then check their hubs).
    pub(crate) fn watch(&self, inbox: &Arc<Inbox>) {
        let mut inboxes = self
            .liveness
            .inboxes
            .lock()
            .unwrap_or_else(|e| e.into_inner());
        inboxes.retain(|w| w.strong_count() > 0);
        inboxes.push(Arc::downgrade(inbox));
    }
}

/// Now, in milliseconds since the Unix epoch (a hello's time).
pub(crate) fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// A hub's `{"ok": ...}` reply, or the error it sent.
fn read_reply<T: DeserializeOwned>(hub: &str, reply: &zenoh::query::Reply) -> Result<T, HubError> {
    let lost = |why: String| HubError::HubLost {
        hub: hub.to_string(),
        envs: "-".into(),
        why,
    };
    let sample = reply
        .result()
        .map_err(|e| lost(format!("error reply: {:?}", e.payload().to_bytes())))?;
    let mut value: Value = serde_json::from_slice(&sample.payload().to_bytes())
        .map_err(|e| lost(format!("unreadable reply: {e}")))?;
    if let Some(error) = value.get_mut("error").map(Value::take)
        && let Ok(error) = serde_json::from_value::<HubError>(error)
    {
        return Err(envhub_protocol::untrusted::from_hub(hub, error));
    }
    if let Some(err) = value.get("err") {
        return Err(envhub_protocol::untrusted::from_hub(
            hub,
            HubError::Remote(err.as_str().unwrap_or("error").to_string()),
        ));
    }
    serde_json::from_value(value.get_mut("ok").map(Value::take).unwrap_or(Value::Null))
        .map_err(|e| lost(format!("unreadable reply: {e}")))
}

/// The error for a hub name that is not live: the live ones and the closest names.
pub fn unknown_hub(name: &str, live: &[String]) -> HubError {
    let mut scored: Vec<(f64, &String)> = live
        .iter()
        .map(|l| (strsim::normalized_levenshtein(name, l), l))
        .filter(|(s, _)| *s >= 0.4)
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    let closest: Vec<&str> = scored.iter().take(3).map(|(_, l)| l.as_str()).collect();
    HubError::UnknownHub {
        name: name.to_string(),
        live: if live.is_empty() {
            "none".into()
        } else {
            live.join(", ")
        },
        closest: if closest.is_empty() {
            String::new()
        } else {
            format!(" (closest: {})", closest.join(", "))
        },
    }
}

/// Answers one link of a session keeps waiting at most.
pub(crate) const INBOX_LIMIT: usize = 16;

/// Per link, its responses with the connection that received each.
type Mailboxes = HashMap<usize, VecDeque<(u64, Vec<u8>)>>;

/// Responses of a session's remote links, as they arrive; waiters block on its condvar.
#[derive(Default)]
pub(crate) struct Inbox {
    /// Per link: `(connection, response)`, the connection being the [`Inbox::connection`]
    /// number of the subscriber that received it.
    mail: Mutex<Mailboxes>,
    bell: Condvar,
}

impl Inbox {
    /// A number for a new connection of a link, never given before: a link placed again on
    /// another hub gets a new one, so what the lost hub still sends is told apart.
    pub fn connection() -> u64 {
        static NEXT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(1);
        NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed)
    }

    /// Files a response that connection `from` of link `link` received and wakes the waiters.
    /// A link holds at most [`INBOX_LIMIT`] answers (a hub sends one per request, and a few
    /// repeats); past it the oldest goes.
    pub fn post(&self, link: usize, from: u64, bytes: Vec<u8>) {
        let mut mail = self.lock();
        let queue = mail.entry(link).or_default();
        if queue.len() >= INBOX_LIMIT {
            queue.pop_front();
            tracing::warn!(link, "too many answers waiting: dropped the oldest");
        }
        queue.push_back((from, bytes));
        self.bell.notify_all();
    }

    /// Wakes the waiters (something changed: a hub came or went).
    pub fn ring(&self) {
        let _guard = self.lock();
        self.bell.notify_all();
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Mailboxes> {
        self.mail.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// The oldest response of `link` received by connection `from`; what other connections
    /// of the link received (a hub declared lost, still sending) is dropped.
    pub fn take(&self, link: usize, from: u64) -> Option<Vec<u8>> {
        let mut mail = self.lock();
        let queue = mail.get_mut(&link)?;
        while let Some((by, bytes)) = queue.pop_front() {
            if by == from {
                return Some(bytes);
            }
            tracing::warn!(
                link,
                "dropped an answer from a replaced connection (a lost hub)"
            );
        }
        None
    }

    /// Blocks until a response for one of `links` is filed, a ring, or `timeout`.
    pub fn wait(&self, links: &[usize], timeout: Duration) {
        let mail = self.lock();
        if links
            .iter()
            .any(|l| mail.get(l).is_some_and(|q| !q.is_empty()))
        {
            return;
        }
        let _ = self.bell.wait_timeout(mail, timeout);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unknown_hub_names_the_live_ones_and_the_closest() {
        let live = vec![
            "lab-a".to_string(),
            "lab-b".to_string(),
            "gpu-box".to_string(),
        ];
        let err = unknown_hub("lab-c", &live).to_string();
        assert!(err.contains("live hubs: lab-a, lab-b, gpu-box"), "{err}");
        assert!(err.contains("closest: lab-a, lab-b"), "{err}");
        let none = unknown_hub("x", &[]).to_string();
        assert!(none.contains("live hubs: none"), "{none}");
    }

    #[test]
    fn a_hub_answers_from_the_one_id_its_identity_token_names() {
        let mut seen = Seen::default();
        assert!(seen.note(&keys::hub_token("lab"), true));
        assert_eq!(seen.id_of("lab").unwrap(), None, "no identity token yet");
        assert!(seen.note(&keys::hub_id_token("lab", "a1"), true));
        assert!(
            !seen.note("envhub/hub/lab/open", true),
            "not a token of a hub"
        );
        assert_eq!(seen.id_of("lab").unwrap().as_deref(), Some("a1"));
        // A second identity in the name: neither is believed, and the error names both.
        seen.note(&keys::hub_id_token("lab", "b2"), true);
        let err = seen.id_of("lab").unwrap_err().to_string();
        assert!(err.contains("a1 and b2") && err.contains("`lab`"), "{err}");
        seen.note(&keys::hub_id_token("lab", "b2"), false);
        assert_eq!(seen.id_of("lab").unwrap().as_deref(), Some("a1"));
        seen.note(&keys::hub_id_token("lab", "a1"), false);
        assert_eq!(seen.id_of("lab").unwrap(), None);
        assert!(seen.alive.contains_key("lab"), "the name token is apart");
    }

    #[test]
    fn answers_of_a_replaced_connection_are_not_taken_as_the_new_one_s() {
        let inbox = Inbox::default();
        let (lost, new) = (Inbox::connection(), Inbox::connection());
        inbox.post(0, lost, b"from the lost hub".to_vec());
        inbox.post(0, new, b"from its successor".to_vec());
        inbox.post(0, lost, b"late, from the lost hub".to_vec());
        assert_eq!(
            inbox.take(0, new).as_deref(),
            Some(&b"from its successor"[..])
        );
        assert_eq!(inbox.take(0, new), None);
    }

    #[test]
    fn an_inbox_keeps_a_bounded_number_of_answers_per_link() {
        let inbox = Inbox::default();
        let c = Inbox::connection();
        for i in 0..(INBOX_LIMIT + 10) {
            inbox.post(0, c, vec![i as u8]);
        }
        let mut kept = Vec::new();
        while let Some(b) = inbox.take(0, c) {
            kept.push(b[0] as usize);
        }
        assert_eq!(
            kept,
            (10..INBOX_LIMIT + 10).collect::<Vec<_>>(),
            "the newest are kept"
        );
    }
}
