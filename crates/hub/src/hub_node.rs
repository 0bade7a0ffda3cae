//! A hub on the network: `envhub serve` joins Zenoh, holds its liveliness token, answers
//! queries (info, catalog, adapters, open a session) and bridges remote sessions to its local
//! workers (`envhub_net`'s bridge).
//!
//! Remote clients get what a registry id of this hub's own catalog runs, nothing more: a
//! request that would reach a file on the hub (`asset_path`, model-file kwargs) is refused
//! unless the hub's owner allows it, and `--max-envs` / `--max-workers` are checked before
//! anything starts. Clients' own Python adapters never travel (they would be code run here).

use crate::hub::Hub;
use crate::launcher::Launcher;
use crate::python_host::UserAdapters;
use envhub_net::{NetConfig, ServePolicy, Sessions};
use envhub_protocol::handshake::{Identity, SeenHellos, check_client_hello, hub_answer};
use envhub_protocol::seal::Cipher;
use envhub_protocol::{HubError, HubInfo, OpenReply, OpenRequest, keys};
use envhub_session::{SessionOptions, VecEnv};
use serde_json::{Value, json};
use std::sync::Arc;
use std::time::Duration;
use zenoh::Wait;

/// How long an open waits for sessions lent to other clients past their share to close and
/// give it room (a session ends within a tick of its thread and its workers' exit).
const RECLAIM_WAIT: Duration = Duration::from_secs(10);

/// A hub joined to Zenoh. Dropping it leaves (the token goes, sessions end).
pub struct HubNode {
    name: String,
    _session: zenoh::Session,
    _token: zenoh::liveliness::LivelinessToken,
    _id_token: zenoh::liveliness::LivelinessToken,
    _queryables: Vec<zenoh::query::Queryable<()>>,
    _requests: zenoh::pubsub::Subscriber<()>,
    _clients: zenoh::pubsub::Subscriber<()>,
    /// Keys of client tokens gone, for the watcher thread (which ends when this goes).
    _gone: Arc<GoneClients>,
    _echo: zenoh::pubsub::Subscriber<()>,
    sessions: Arc<Sessions>,
    exposure_notice: Option<String>,
    /// Its entry among this machine's hubs (loopback only), removed when it leaves.
    _local: Option<envhub_net::local::Published>,
}

impl HubNode {
    /// Its name on the network.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Remote sessions open now.
    pub fn session_count(&self) -> usize {
        self.sessions.len()
    }

    /// What to tell the operator about the hub's reach: a warning when it is open to the
    /// network without credentials (`--insecure-listen`), or how to open it up when it was
    /// kept on loopback.
    pub fn exposure_notice(&self) -> Option<&str> {
        self.exposure_notice.as_deref()
    }
}

impl Drop for HubNode {
    fn drop(&mut self) {
        self.sessions.stop_all();
    }
}

/// The machine's host name (the default hub name).
pub fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|s| s.trim().to_string())
        .ok()
        .filter(|s| !s.is_empty())
        .unwrap_or_else(|| "localhost".into())
}

/// Joins the network as hub `name`: declares the token and queryables and serves remote
/// sessions with `hub`'s catalog until the returned node is dropped.
///
/// Its steps: open the hub's Zenoh session (its exposure decided first); make sure no hub
/// of that name is live; declare the queryables (info, catalog, adapters, open), the
/// session requests' subscriber, the watch on clients that leave and the echo; and last
/// the tokens that tell clients the hub is there.
pub fn join(
    hub: Arc<Hub>,
    name: &str,
    net: &NetConfig,
    policy: ServePolicy,
) -> Result<HubNode, HubError> {
    keys::check_name(name)?;
    let envhub_net::HubSession {
        session,
        notice: exposure_notice,
        local,
    } = envhub_net::open_hub(name, net, &policy)?;
    refuse_a_namesake(&session, name)?;
    let sessions = Arc::new(Sessions::default());
    let state = Arc::new(State {
        hub,
        name: name.to_string(),
        policy,
        sessions: sessions.clone(),
        zenoh: session.clone(),
        identity: envhub_net::identity::hub_identity()?,
        hellos: std::sync::Mutex::new(SeenHellos::default()),
    });
    let queryables = declare_queryables(&session, name, &state)?;
    let requests = declare_requests(&session, name, &sessions)?;
    let (gone, clients) = watch_clients(&session, &sessions)?;
    let echo = declare_echo(&session, name)?;
    // The identity first: a client that sees the name can then tell this hub's answers.
    let id_token = session
        .liveliness()
        .declare_token(keys::hub_id_token(name, &session.zid().to_string()))
        .wait()
        .map_err(zenoh_error("declare identity token"))?;
    let token = session
        .liveliness()
        .declare_token(keys::hub_token(name))
        .wait()
        .map_err(zenoh_error("declare token"))?;
    // Last: this user's clients take the entry to mean the hub answers.
    let local = local.and_then(envhub_net::LocalEntry::publish);
    Ok(HubNode {
        name: name.to_string(),
        _session: session,
        _token: token,
        _id_token: id_token,
        _queryables: queryables,
        _requests: requests,
        _clients: clients,
        _gone: gone,
        _echo: echo,
        sessions,
        exposure_notice,
        _local: local,
    })
}

/// A Zenoh failure while joining, as the error the operator sees.
fn zenoh_error(what: &'static str) -> impl FnOnce(zenoh::Error) -> HubError {
    move |e: zenoh::Error| HubError::Network {
        reason: format!("{what}: {e}"),
        hint: "another hub with this name may be running; pick another `--name`".into(),
    }
}

/// Refuses to join when a hub of the same name is already live: both would be unreachable
/// by name.
fn refuse_a_namesake(session: &zenoh::Session, name: &str) -> Result<(), HubError> {
    let existing = session
        .liveliness()
        .get(keys::hub_token(name))
        .timeout(Duration::from_millis(300))
        .wait()
        .map_err(zenoh_error("liveliness query"))?;
    if existing.recv().is_ok_and(|r| r.result().is_ok()) {
        return Err(HubError::Network {
            reason: format!("a hub named `{name}` is already live on this network"),
            hint: "give this one another `--name`".into(),
        });
    }
    Ok(())
}

/// The queryables of info, catalog, adapters and open. Queries being answered now: each
/// takes a thread (opening starts workers, seconds), so their number is bounded; past it a
/// query is answered "busy" on Zenoh's thread.
fn declare_queryables(
    session: &zenoh::Session,
    name: &str,
    state: &Arc<State>,
) -> Result<Vec<zenoh::query::Queryable<()>>, HubError> {
    let in_flight = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let mut queryables = Vec::new();
    for (op, key) in [
        ("info", keys::hub_info(name)),
        ("catalog", keys::hub_catalog(name)),
        ("adapters", keys::hub_adapters(name)),
        ("open", keys::hub_open(name)),
    ] {
        let (state, in_flight) = (state.clone(), in_flight.clone());
        let q = session
            .declare_queryable(key)
            .callback(move |query| {
                // An open request longer than any real one is refused by its length, here on
                // Zenoh's thread: it is neither copied nor read, nor does it take a place
                // among the queries answered at once.
                if op == "open"
                    && let Err(why) = envhub_protocol::untrusted::check_open_request_size(
                        query.payload().map_or(0, |p| p.len()),
                    )
                {
                    state.reply(&query, Err(state.unreadable_open(why)));
                    return;
                }
                let Some(slot) = QuerySlot::take(&in_flight) else {
                    state.reply(&query, Err(state.busy(op)));
                    return;
                };
                let state = state.clone();
                // Opening starts workers (seconds): never on Zenoh's own threads.
                let spawned = std::thread::Builder::new()
                    .name(format!("envhub-query-{op}"))
                    .spawn(move || {
                        let _slot = slot;
                        state.answer(op, query);
                    });
                if let Err(e) = spawned {
                    tracing::warn!(op, error = %e, "cannot start a thread for a query");
                }
            })
            .wait()
            .map_err(zenoh_error("declare queryable"))?;
        queryables.push(q);
    }
    Ok(queryables)
}

/// The subscriber of remote sessions' requests, handed to the bridge.
fn declare_requests(
    session: &zenoh::Session,
    name: &str,
    sessions: &Arc<Sessions>,
) -> Result<zenoh::pubsub::Subscriber<()>, HubError> {
    let (sessions, zenoh, name) = (sessions.clone(), session.clone(), name.to_string());
    session
        .declare_subscriber(keys::all_requests(&name))
        .callback(move |sample| {
            envhub_net::dispatch(
                &sessions,
                &zenoh,
                &name,
                sample.key_expr().as_str(),
                &sample.payload().to_bytes(),
            );
        })
        .wait()
        .map_err(zenoh_error("declare subscriber"))
}

/// A client that leaves (exits, crashes, or is cut off past its lease) takes its sessions.
/// Any peer can declare and drop a token of the same key, so a deletion ends sessions only
/// once no token of that key is left on the network: the real client's still answers.
/// The check is a query: one watcher thread makes them, for the keys gone since it last
/// looked (a set, so a flapping token costs one check, and bounded).
fn watch_clients(
    session: &zenoh::Session,
    sessions: &Arc<Sessions>,
) -> Result<(Arc<GoneClients>, zenoh::pubsub::Subscriber<()>), HubError> {
    let gone = Arc::new(GoneClients::default());
    {
        let (gone, sessions, zenoh) = (Arc::downgrade(&gone), sessions.clone(), session.clone());
        std::thread::Builder::new()
            .name("envhub-clients".into())
            .spawn(move || {
                while let Some(keys) = GoneClients::next(&gone) {
                    for key in keys {
                        if client_token_remains(&zenoh, &key) {
                            tracing::warn!(client = %key, "a token of a live client was dropped by another peer: its sessions go on");
                        } else {
                            sessions.client_gone(&key);
                        }
                    }
                }
            })
            .map_err(|e| HubError::Internal(format!("cannot start the client watcher: {e}")))?;
    }
    let clients = {
        let gone = gone.clone();
        session
            .liveliness()
            .declare_subscriber(keys::ALL_CLIENTS)
            .callback(move |sample| {
                if sample.kind() == zenoh::sample::SampleKind::Delete {
                    gone.push(sample.key_expr().as_str());
                }
            })
            .wait()
            .map_err(zenoh_error("declare client watch"))?
    };
    Ok((gone, clients))
}

/// The echo: answers on Zenoh's own thread, with the data path's QoS — the floor under a
/// remote round trip.
fn declare_echo(
    session: &zenoh::Session,
    name: &str,
) -> Result<zenoh::pubsub::Subscriber<()>, HubError> {
    let (req, rep) = keys::hub_echo(name);
    let publisher = session
        .declare_publisher(rep)
        .express(true)
        .congestion_control(zenoh::qos::CongestionControl::Drop)
        .priority(zenoh::qos::Priority::DataHigh)
        .wait()
        .map_err(zenoh_error("declare echo"))?;
    session
        .declare_subscriber(req)
        .callback(move |sample| {
            let _ = publisher.put(sample.payload().clone()).wait();
        })
        .wait()
        .map_err(zenoh_error("declare echo"))
}

/// Client token keys deleted and not yet checked: a set (a key flapping a thousand times is
/// checked once), of at most [`GoneClients::MAX`] keys (past it a deletion is dropped; the
/// idle timeout still ends a session whose client is gone).
#[derive(Default)]
struct GoneClients {
    keys: std::sync::Mutex<std::collections::HashSet<String>>,
    bell: std::sync::Condvar,
}

impl GoneClients {
    const MAX: usize = 4096;

    fn push(&self, key: &str) {
        let mut keys = self.keys.lock().unwrap_or_else(|e| e.into_inner());
        if keys.len() < Self::MAX {
            keys.insert(key.to_string());
            self.bell.notify_one();
        } else {
            tracing::warn!(client = key, "too many clients gone at once: not checked");
        }
    }

    /// The keys gone since the last call (waiting for some); `None` once the hub has left.
    fn next(this: &std::sync::Weak<GoneClients>) -> Option<Vec<String>> {
        loop {
            let gone = this.upgrade()?;
            let keys = gone.keys.lock().unwrap_or_else(|e| e.into_inner());
            let (mut keys, _) = gone
                .bell
                .wait_timeout_while(keys, Duration::from_millis(500), |k| k.is_empty())
                .unwrap_or_else(|e| e.into_inner());
            if !keys.is_empty() {
                return Some(keys.drain().collect());
            }
        }
    }
}

/// A place among the queries answered at once, given back when dropped.
struct QuerySlot(Arc<std::sync::atomic::AtomicUsize>);

impl QuerySlot {
    fn take(in_flight: &Arc<std::sync::atomic::AtomicUsize>) -> Option<QuerySlot> {
        use std::sync::atomic::Ordering;
        in_flight
            .fetch_update(Ordering::AcqRel, Ordering::Acquire, |n| {
                (n < envhub_net::MAX_QUERIES_IN_FLIGHT).then_some(n + 1)
            })
            .ok()
            .map(|_| QuerySlot(in_flight.clone()))
    }
}

impl Drop for QuerySlot {
    fn drop(&mut self) {
        self.0.fetch_sub(1, std::sync::atomic::Ordering::AcqRel);
    }
}

struct State {
    hub: Arc<Hub>,
    name: String,
    policy: ServePolicy,
    sessions: Arc<Sessions>,
    zenoh: zenoh::Session,
    /// This hub's identity in key exchanges (its user's, kept in their config folder).
    identity: Identity,
    /// Clients' exchange keys seen lately: a replayed open is refused.
    hellos: std::sync::Mutex<SeenHellos>,
}

impl State {
    fn answer(&self, op: &str, query: zenoh::query::Query) {
        let result = self.handle(op, &query);
        self.reply(&query, result);
    }

    fn busy(&self, op: &str) -> HubError {
        tracing::warn!(op, "too many queries at once: refused");
        self.refuse(
            format!(
                "it is answering {} queries already",
                envhub_net::MAX_QUERIES_IN_FLIGHT
            ),
            "try again in a moment",
        )
    }

    /// An open request refused before it was parsed (too long, too deep, too many values)
    /// or that did not parse.
    fn unreadable_open(&self, why: String) -> HubError {
        tracing::debug!(%why, "open request refused");
        HubError::InvalidConfig {
            what: "open request",
            reason: why,
        }
    }

    fn reply(&self, query: &zenoh::query::Query, result: Result<Value, HubError>) {
        let reply = match result {
            Ok(ok) => json!({ "ok": ok }),
            Err(e) => json!({ "err": e.to_string(), "error": e }),
        };
        if let Err(e) = query
            .reply(query.key_expr().clone(), reply.to_string())
            .wait()
        {
            tracing::warn!(key = %query.key_expr(), error = %e, "could not answer a query");
        }
    }

    fn handle(&self, op: &str, query: &zenoh::query::Query) -> Result<Value, HubError> {
        match op {
            "info" => Ok(serde_json::to_value(self.info()).expect("info serializes")),
            "catalog" => {
                Ok(serde_json::to_value(self.hub.registry().entries()).expect("entries serialize"))
            }
            "adapters" => {
                Ok(serde_json::to_value(self.hub.adapters()?).expect("adapters serialize"))
            }
            "open" => {
                let bytes = query.payload().map(|p| p.to_bytes()).unwrap_or_default();
                let message = envhub_protocol::untrusted::read_open_request(&bytes)
                    .map_err(|why| self.unreadable_open(why))?;
                // Who asks, and that it is not a replay, before anything else is looked at.
                let now = unix_ms();
                let (exchange, cipher) = check_client_hello(&self.name, &message.hello, now)
                    .and_then(|(exchange, cipher)| {
                        self.hellos
                            .lock()
                            .unwrap_or_else(|e| e.into_inner())
                            .note(&exchange, now)
                            .map(|()| (exchange, cipher))
                    })
                    .map_err(|why| {
                        self.refuse(
                            format!("its key exchange was refused: {why}"),
                            "open again (each open makes a new exchange); check that this machine's clock is right",
                        )
                    })?;
                let hello = Hello {
                    identity: &message.hello.identity,
                    exchange: &exchange,
                    cipher,
                    request: &bytes,
                };
                Ok(serde_json::to_value(self.open(message.request, hello)?)
                    .expect("replies serialize"))
            }
            _ => unreachable!("only the ops declared above"),
        }
    }

    fn info(&self) -> HubInfo {
        let (envs, workers) = self.sessions.totals();
        HubInfo {
            name: self.name.clone(),
            host: host_name(),
            cores: envhub_session::cores(),
            version: env!("CARGO_PKG_VERSION").to_string(),
            adapters: self
                .hub
                .adapters()
                .map(|all| {
                    all.iter()
                        .filter(|a| a.availability.is_available())
                        .map(|a| a.name.clone())
                        .collect()
                })
                .unwrap_or_default(),
            catalog: self.hub.registry().len(),
            envs,
            workers,
            sessions: self.sessions.len(),
            load: std::fs::read_to_string("/proc/loadavg")
                .ok()
                .and_then(|s| s.split_whitespace().next()?.parse().ok())
                .unwrap_or(0.0),
            max_envs: self.policy.max_envs,
            max_workers: self.policy.max_workers,
        }
    }

    fn refuse(&self, reason: String, hint: &str) -> HubError {
        HubError::Refused {
            hub: self.name.clone(),
            reason,
            hint: hint.to_string(),
        }
    }

    fn open(&self, request: OpenRequest, hello: Hello<'_>) -> Result<OpenReply, HubError> {
        let config = request.config;
        if !self.policy.allow_remote_files {
            if let Some(path) = &config.asset_path {
                return Err(self.refuse(
                    format!("`asset_path` ({}) names a file on this hub", path.display()),
                    "remote clients run the hub's own registry entries; its owner can allow files with `envhub serve --allow-remote-files`",
                ));
            }
            if let Some(key) = config.extra.keys().find(|k| names_a_file(k)) {
                return Err(self.refuse(
                    format!("kwarg `{key}` names a file on this hub"),
                    "remote clients run the hub's own registry entries; its owner can allow files with `envhub serve --allow-remote-files`",
                ));
            }
            // An allowlist of values: numbers, booleans, strings that name no file, and
            // lists and maps of those.
            if let Err(why) = envhub_protocol::untrusted::check_remote_kwargs(&config.extra) {
                return Err(self.refuse(
                    format!("a kwarg is not a plain value: {why}"),
                    "remote clients may pass numbers, booleans, strings that are not paths, and lists and maps of those; its owner can allow files with `envhub serve --allow-remote-files`",
                ));
            }
        }
        // The session ends when the token of the key that opens it goes: a token of another
        // client (whose sessions would then outlive their opener) or of no one (until the
        // idle timeout) is refused.
        if request.client != hello.identity {
            return Err(self.refuse(
                format!(
                    "the client's liveliness token `{}` is not named by the identity that signed the open ({})",
                    keys::client_token(&request.client).escape_debug(),
                    hello.identity
                ),
                "a session lives as long as its opener's token `envhub/client/<identity>`: open sessions from an envhub client",
            ));
        }
        if !client_token_appears(&self.zenoh, &keys::client_token(&request.client)) {
            return Err(self.refuse(
                format!(
                    "the client's liveliness token `{}` is not on the network",
                    keys::client_token(&request.client).escape_debug()
                ),
                "a session lives as long as its client's token: open sessions from an envhub client",
            ));
        }
        let num_envs = config.num_envs;
        let workers = envhub_session::workers_for(&config, num_envs.max(1));
        let route = self
            .hub
            .route_provisioning(
                &request.id,
                &config,
                &UserAdapters::default(),
                self.policy.allow_provision,
            )
            .map_err(|e| match e {
                HubError::PythonEnv { message, .. } if !self.policy.allow_provision => self.refuse(
                    message.split("\nhint:").next().unwrap_or_default().to_string(),
                    "its owner can build it with `envhub env sync`, or let remote clients' sessions build it with `envhub serve --allow-provision`",
                ),
                e => e,
            })?;
        let step_timeout = Duration::from_millis(request.step_timeout_ms.max(1));
        if step_timeout > self.policy.max_step_timeout {
            return Err(self.refuse(
                format!(
                    "a step timeout of {:?} exceeds its limit of {:?}",
                    step_timeout, self.policy.max_step_timeout
                ),
                "ask for a shorter `step_timeout`; the hub's owner sets the limit with `envhub serve --max-step-timeout SECS`",
            ));
        }
        let mut options: SessionOptions = self.hub.options().clone();
        options.restart_on_crash = request.restart_on_crash;
        options.step_timeout = step_timeout;
        // Reserve the envs and workers before anything starts, so two clients cannot both
        // pass the limits; sessions lent to other clients past their share may be closing
        // to make room for this one.
        let reservation = self
            .sessions
            .reserve_waiting(
                hello.identity,
                num_envs,
                workers,
                &self.policy,
                RECLAIM_WAIT,
            )
            .map_err(|(reason, hint)| self.refuse(reason, &hint))?;
        let vec = VecEnv::start(&request.id, route.clone(), options, &Launcher::local())?;
        let spec = envhub_shm::ReadySpec {
            observation_space: vec.observation_space().clone(),
            action_space: vec.action_space().clone(),
            max_episode_steps: vec.max_episode_steps(),
            render_fps: vec.render_fps(),
            pid: vec.worker_pids().first().copied().unwrap_or(0),
            worker: None,
        };
        let workers = vec.num_workers();
        let session = envhub_net::new_session_id()?;
        let (answer, key) = hub_answer(
            &self.identity,
            &self.name,
            &session,
            hello.request,
            hello.exchange,
            hello.cipher,
        )
        .map_err(|e| HubError::Internal(format!("the key exchange failed: {e}")))?;
        envhub_net::start(
            &self.sessions,
            &self.zenoh,
            &self.name,
            session.clone(),
            envhub_net::Client {
                token: &request.client,
                identity: hello.identity,
            },
            key,
            vec,
            reservation,
            self.policy.idle_timeout,
        )?;
        tracing::info!(id = %request.id, num_envs, workers, client = %request.client, identity = hello.identity, %session, "remote session opened");
        Ok(OpenReply {
            session,
            spec,
            route,
            workers,
            hello: answer,
        })
    }
}

/// A checked client hello: who opens, its exchange key, and the open request's bytes as they
/// arrived (the transcript covers them).
struct Hello<'a> {
    identity: &'a str,
    exchange: &'a [u8; 32],
    /// What the hub picked from the client's offer (`None`: it offered none).
    cipher: Option<Cipher>,
    request: &'a [u8],
}

/// Now, in milliseconds since the Unix epoch.
fn unix_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// Whether a client's token `key` is still held by someone (the client itself, when another
/// peer declared and dropped a copy to end its sessions).
fn client_token_remains(zenoh: &zenoh::Session, key: &str) -> bool {
    let Ok(replies) = zenoh
        .liveliness()
        .get(key)
        .timeout(Duration::from_millis(250))
        .wait()
    else {
        return false;
    };
    replies.recv().is_ok_and(|r| r.result().is_ok())
}

/// [`client_token_remains`] with patience, for an open: through a router, a client's token
/// reaches the hub a moment after the client declared it, and its first open can come
/// sooner (a lab client on a loaded machine was refused so). Asks again until the token is
/// seen or `TOKEN_PATIENCE` has passed; the open's thread waits, not Zenoh's.
fn client_token_appears(zenoh: &zenoh::Session, key: &str) -> bool {
    const TOKEN_PATIENCE: Duration = Duration::from_millis(1500);
    let deadline = std::time::Instant::now() + TOKEN_PATIENCE;
    loop {
        if client_token_remains(zenoh, key) {
            return true;
        }
        if std::time::Instant::now() >= deadline {
            return false;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Whether a kwarg's name says it names a file or folder (`xml_file`, `model_path`,
/// `asset_dir`, ...).
fn names_a_file(key: &str) -> bool {
    let key = key.to_ascii_lowercase();
    ["file", "path", "dir", "xml", "mjcf", "urdf", "asset"]
        .iter()
        .any(|w| {
            key.split(['_', '-'])
                .any(|part| part == *w || part == format!("{w}s"))
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_flapping_client_token_is_checked_once_and_the_set_is_bounded() {
        let gone = Arc::new(GoneClients::default());
        for _ in 0..100_000 {
            gone.push("envhub/client/flapper");
        }
        for i in 0..(2 * GoneClients::MAX) {
            gone.push(&format!("envhub/client/{i}"));
        }
        let keys = GoneClients::next(&Arc::downgrade(&gone)).unwrap();
        assert_eq!(keys.len(), GoneClients::MAX);
        assert_eq!(
            keys.iter()
                .filter(|k| *k == "envhub/client/flapper")
                .count(),
            1
        );
        let weak = Arc::downgrade(&gone);
        drop(gone);
        assert!(
            GoneClients::next(&weak).is_none(),
            "the watcher ends with the hub"
        );
    }

    #[test]
    fn kwargs_that_name_files_are_recognised() {
        for k in [
            "xml_file",
            "model_path",
            "asset_dir",
            "urdf",
            "robot-xml",
            "assets",
        ] {
            assert!(names_a_file(k), "{k}");
        }
        for k in [
            "frame_skip",
            "reset_noise_scale",
            "ctrl_cost_weight",
            "profile",
        ] {
            assert!(!names_a_file(k), "{k}");
        }
    }
}
