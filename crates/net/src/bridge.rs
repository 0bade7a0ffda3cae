//! The hub's side of a remote session: a local `VecEnv` (workers over iceoryx2, as any
//! session) driven by the requests that arrive over Zenoh, one thread per session.
//!
//! Every request and response is sealed with the session's key ([`envhub_protocol::seal`]),
//! which only the client that opened the session has. A request is checked as it arrives,
//! before it is queued: one of the wrong size, or that does not open with the key (forged,
//! changed, from another session), or older than the last answered (a replay) is dropped
//! unanswered, counted and logged at debug level, and takes no place in the session's queue;
//! the session goes on. Each request carries a sequence number. The answer to the last
//! one is kept: a request sent again (the client heard nothing back, e.g. across a reconnect)
//! is answered again with the very same bytes, without stepping twice, at most once per
//! [`REPEAT_GAP`]; an older one, or a copy of one already queued (a replay), is dropped by its
//! sequence number before its seal is checked. A sealed request that is unreadable is answered with an error naming what was
//! wrong, and the session goes on.

use crate::policy::{SESSION_QUEUE, ServePolicy};
use envhub_protocol::batch_codec::{self, RowsOut};
use envhub_protocol::seal::{Direction, SessionKey};
use envhub_protocol::{HubError, keys};
use envhub_session::{Batch, VecEnv};
use envhub_shm::{BatchLayout, Layout, command, frames_section, status};
use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, RecvTimeoutError, SyncSender, TrySendError};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How often an idle session looks at its stop flag.
const IDLE_TICK: Duration = Duration::from_millis(100);

struct Entry {
    /// The client's token key: the session ends when it goes.
    client: String,
    /// The client's identity (its key, [`envhub_protocol::handshake`]): what per-client
    /// limits count.
    identity: String,
    envs: usize,
    workers: usize,
    requests: Option<SyncSender<Vec<u8>>>,
    /// The sizes its sealed requests may have (checked before one is queued).
    request_sizes: std::ops::RangeInclusive<usize>,
    /// Its key: a request is opened before it is queued, so forgeries take no place there.
    key: Arc<SessionKey>,
    /// The last sequence number it answered: older requests (replays) are not queued.
    answered: Arc<AtomicU64>,
    /// What it let into its queue lately (replays of newer requests are not queued either).
    gate: Arc<Mutex<Gate>>,
    stop: Arc<AtomicBool>,
    /// Opened past its client's share while no other client waited: lent, and closed again
    /// when another client asks for room within its own share.
    lent: bool,
    /// Opened after every session of a lower number (the newest lent ones go first).
    serial: u64,
    /// Closed to give its room back to another client (its client is told so).
    reclaimed: Arc<AtomicBool>,
}

/// Numbers sessions in the order they open.
static SERIAL: AtomicU64 = AtomicU64::new(0);

/// Messages a hub dropped without answering them: not sealed with their session's key,
/// replays, the wrong size, for no open session, or past a full queue.
pub static DROPPED: AtomicU64 = AtomicU64::new(0);

fn dropped(why: &str, session: &str) {
    DROPPED.fetch_add(1, Ordering::Relaxed);
    tracing::debug!(session, why, "request dropped");
}

/// A session that ended lately: what it takes to tell its client so, sealed.
struct Closed {
    id: String,
    key: Arc<SessionKey>,
    request_sizes: std::ops::RangeInclusive<usize>,
    /// The last sequence number the session answered (never sealed again).
    last_seq: u64,
    /// The "closed" answer sent, kept for a repeat of its request.
    answer: Option<(u64, zenoh::bytes::ZBytes)>,
    /// It was lent past its client's share and given back to another client.
    reclaimed: bool,
}

/// Ended sessions remembered, to answer their clients that they are closed.
const CLOSED_REMEMBERED: usize = 256;

/// A hub's remote sessions, and the envs and workers they hold (for its limits).
#[derive(Default)]
pub struct Sessions {
    entries: Mutex<HashMap<String, Entry>>,
    closed: Mutex<std::collections::VecDeque<Closed>>,
    /// Clients whose token went away (the latest few): a session still starting for one of
    /// them when it went is ended as soon as it is registered.
    gone: Mutex<std::collections::VecDeque<String>>,
    /// What sessions still starting have reserved.
    starting: Mutex<Starting>,
    /// Clients refused for room within their share lately, and until when they count as
    /// waiting: while one waits, no other client is lent past its share.
    waiting: Mutex<HashMap<String, Instant>>,
}

/// How long a client refused for room within its share counts as waiting for it.
const WAITING_FOR: Duration = Duration::from_secs(10);

/// Why an admission was refused: the reason, the hint, and whether room is coming (sessions
/// lent to other clients are closing to give it back: ask again in a moment).
#[derive(Debug)]
pub struct Refusal {
    /// What limit the request would pass.
    pub reason: String,
    /// What would fit, and the flag that sets the limit.
    pub hint: String,
    /// Sessions lent past other clients' shares are being closed for this client.
    pub room_coming: bool,
}

impl From<(String, String)> for Refusal {
    fn from((reason, hint): (String, String)) -> Self {
        Refusal {
            reason,
            hint,
            room_coming: false,
        }
    }
}

/// Envs, workers and sessions (by client identity) set aside by sessions still starting.
#[derive(Default)]
struct Starting {
    envs: usize,
    workers: usize,
    by_client: HashMap<String, Held>,
}

/// What one client holds (or has set aside): what its per-client limits count.
#[derive(Clone, Copy, Default, Debug)]
struct Held {
    sessions: usize,
    envs: usize,
    workers: usize,
}

impl Held {
    fn add(&mut self, other: Held) {
        self.sessions += other.sessions;
        self.envs += other.envs;
        self.workers += other.workers;
    }
}

/// Envs and workers set aside for a session being started; given back if it fails.
pub struct Reservation<'a> {
    sessions: &'a Sessions,
    client: String,
    envs: usize,
    workers: usize,
    /// Past the client's share (no other client waited): the session is lent.
    lent: bool,
}

impl Drop for Reservation<'_> {
    fn drop(&mut self) {
        let mut starting = self.sessions.starting();
        starting.envs -= self.envs;
        starting.workers -= self.workers;
        if let Some(held) = starting.by_client.get_mut(&self.client) {
            held.sessions -= 1;
            held.envs -= self.envs;
            held.workers -= self.workers;
            if held.sessions == 0 {
                starting.by_client.remove(&self.client);
            }
        }
    }
}

impl Sessions {
    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<String, Entry>> {
        self.entries.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn starting(&self) -> std::sync::MutexGuard<'_, Starting> {
        self.starting.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Sessions open now.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// Whether none is open.
    pub fn is_empty(&self) -> bool {
        self.lock().is_empty()
    }

    /// Envs and workers of the open sessions.
    pub fn totals(&self) -> (usize, usize) {
        self.lock()
            .values()
            .fold((0, 0), |(e, w), s| (e + s.envs, w + s.workers))
    }

    /// Sets aside `envs` and `workers` for a session of the client of identity `client` (its
    /// key: names a client cannot pick for another) if the limits allow; else why not and what
    /// would fit.
    ///
    /// A client's share (`max_*_per_client`) holds only while another client waits for room:
    /// a client alone may go past it, and what it opens past it is lent. A client refused for
    /// room within its share waits (for [`WAITING_FOR`]): the newest sessions lent to clients
    /// still past their share are closed to make room for it (the refusal then says that room
    /// is coming: ask again), and no client is lent more meanwhile.
    pub fn reserve(
        &self,
        client: &str,
        envs: usize,
        workers: usize,
        policy: &ServePolicy,
    ) -> Result<Reservation<'_>, Refusal> {
        // `starting` is held while the open sessions are counted: a session that moves from
        // starting to open meanwhile (its entry added, then its reservation given back, which
        // waits for this lock) is counted once or twice, never zero times.
        let mut starting = self.starting();
        let mut entries = self.lock();
        let (mut all, mut of_client, mut closing) =
            (Held::default(), Held::default(), Held::default());
        for s in entries.values() {
            let held = Held {
                sessions: 1,
                envs: s.envs,
                workers: s.workers,
            };
            all.add(held);
            if s.stop.load(Ordering::Relaxed) {
                closing.add(held);
            }
            if s.identity == client {
                of_client.add(held);
            }
        }
        let used_envs = all.envs + starting.envs;
        let used_workers = all.workers + starting.workers;
        if let Some(held) = starting.by_client.get(client) {
            of_client.add(*held);
        }
        let cap = |max, held, asked, noun, scope, flag| Cap {
            max,
            held,
            asked,
            noun,
            scope,
            flag,
        };
        // One client's share: past it, a session is only lent.
        let share = cap(
            policy.max_envs_per_client,
            of_client.envs,
            envs,
            "envs",
            Scope::Client,
            "max-envs-per-client",
        )
        .check()
        .and_then(|()| {
            cap(
                policy.max_workers_per_client,
                of_client.workers,
                workers,
                "workers",
                Scope::Client,
                "max-workers-per-client",
            )
            .check()
        });
        let hub = cap(
            policy.max_envs,
            used_envs,
            envs,
            "envs",
            Scope::Hub,
            "max-envs",
        )
        .check()
        .and_then(|()| {
            cap(
                policy.max_workers,
                used_workers,
                workers,
                "workers",
                Scope::Hub,
                "max-workers",
            )
            .check()
        });
        if let Err(refused) = hub {
            let mut refusal = Refusal::from(refused);
            if share.is_ok() {
                // Within its share: it waits, and what other clients were lent comes back.
                self.wait(client);
                let over = |max: Option<usize>, used: usize, closing: usize, asked: usize| {
                    max.map_or(0, |m| {
                        (used.saturating_sub(closing) + asked).saturating_sub(m)
                    })
                };
                let need = Held {
                    sessions: 0,
                    envs: over(policy.max_envs, used_envs, closing.envs, envs),
                    workers: over(policy.max_workers, used_workers, closing.workers, workers),
                };
                refusal.room_coming = if need.envs == 0 && need.workers == 0 {
                    closing.sessions > 0
                } else {
                    reclaim(&mut entries, &starting, client, need, policy)
                };
                if refusal.room_coming {
                    refusal.reason.push_str(
                        "; sessions lent to other clients past their share are closing to make room",
                    );
                }
            }
            return Err(refusal);
        }
        if let Some(max) = policy.max_sessions_per_client
            && of_client.sessions >= max
        {
            return Err(Refusal::from((
                format!(
                    "this client holds {} sessions here, its limit is {max}",
                    of_client.sessions
                ),
                "close sessions it no longer uses; the hub's owner sets the limit with `envhub serve --max-sessions-per-client N`".to_string(),
            )));
        }
        let lent = share.is_err();
        let mut waiting = self.waiting.lock().unwrap_or_else(|e| e.into_inner());
        if let Err((mut reason, hint)) = share {
            let now = Instant::now();
            if waiting.iter().any(|(c, until)| c != client && *until > now) {
                reason.push_str(", and another client waits for room");
                return Err(Refusal::from((reason, hint)));
            }
        }
        waiting.remove(client);
        drop(waiting);
        drop(entries);
        if lent {
            tracing::info!(
                client,
                envs,
                workers,
                "a session lent past its client's share (no other client waits)"
            );
        }
        starting.envs += envs;
        starting.workers += workers;
        starting
            .by_client
            .entry(client.to_string())
            .or_default()
            .add(Held {
                sessions: 1,
                envs,
                workers,
            });
        Ok(Reservation {
            sessions: self,
            client: client.to_string(),
            envs,
            workers,
            lent,
        })
    }

    /// [`Sessions::reserve`], asking again for up to `wait` while room is coming (sessions lent
    /// to other clients closing for this one).
    pub fn reserve_waiting(
        &self,
        client: &str,
        envs: usize,
        workers: usize,
        policy: &ServePolicy,
        wait: Duration,
    ) -> Result<Reservation<'_>, (String, String)> {
        let deadline = Instant::now() + wait;
        loop {
            match self.reserve(client, envs, workers, policy) {
                Ok(reservation) => return Ok(reservation),
                Err(r) if r.room_coming && Instant::now() < deadline => {
                    std::thread::sleep(Duration::from_millis(20));
                }
                Err(r) => return Err((r.reason, r.hint)),
            }
        }
    }

    /// Notes that `client` waits for room within its share.
    fn wait(&self, client: &str) {
        /// Clients remembered as waiting (keys are free to make: the set is bounded).
        const WAITERS: usize = 4096;
        let now = Instant::now();
        let mut waiting = self.waiting.lock().unwrap_or_else(|e| e.into_inner());
        waiting.retain(|_, until| *until > now);
        if waiting.len() < WAITERS || waiting.contains_key(client) {
            waiting.insert(client.to_string(), now + WAITING_FOR);
        }
    }

    /// Ends the sessions of a client whose token went away.
    pub fn client_gone(&self, client_key: &str) {
        const REMEMBERED: usize = 1024;
        let mut entries = self.lock();
        {
            let mut gone = self.gone.lock().unwrap_or_else(|e| e.into_inner());
            if gone.len() == REMEMBERED {
                gone.pop_front();
            }
            gone.push_back(client_key.to_string());
        }
        for (id, s) in entries.iter_mut() {
            if keys::client_token(&s.client) == client_key {
                tracing::info!(session = %id, client = %s.client, "client gone: closing its session");
                s.stop.store(true, Ordering::Relaxed);
                s.requests = None;
            }
        }
    }

    /// Stops every session (the hub is leaving).
    pub fn stop_all(&self) {
        for s in self.lock().values_mut() {
            s.stop.store(true, Ordering::Relaxed);
            s.requests = None;
        }
    }
}

/// Closes the newest sessions lent to clients other than `client` that are still past their
/// share, enough of them to free `need`; whether it could (else it closes none).
fn reclaim(
    entries: &mut HashMap<String, Entry>,
    starting: &Starting,
    client: &str,
    need: Held,
    policy: &ServePolicy,
) -> bool {
    // What each client holds now (sessions closing already are not counted).
    let mut holds: HashMap<&str, Held> = HashMap::new();
    for s in entries.values().filter(|s| !s.stop.load(Ordering::Relaxed)) {
        holds.entry(&s.identity).or_default().add(Held {
            sessions: 1,
            envs: s.envs,
            workers: s.workers,
        });
    }
    for (c, held) in &starting.by_client {
        holds.entry(c).or_default().add(*held);
    }
    let past = |h: &Held| {
        policy.max_envs_per_client.is_some_and(|m| h.envs > m)
            || policy.max_workers_per_client.is_some_and(|m| h.workers > m)
    };
    let mut lent: Vec<(&String, &Entry)> = entries
        .iter()
        .filter(|(_, s)| s.lent && s.identity != client && !s.stop.load(Ordering::Relaxed))
        .collect();
    lent.sort_by_key(|(_, s)| std::cmp::Reverse(s.serial));
    let (mut freed, mut picked) = (Held::default(), Vec::new());
    for (id, s) in lent {
        if freed.envs >= need.envs && freed.workers >= need.workers {
            break;
        }
        let held = holds.get_mut(s.identity.as_str()).expect("counted above");
        if !past(held) {
            continue;
        }
        held.envs -= s.envs;
        held.workers -= s.workers;
        freed.envs += s.envs;
        freed.workers += s.workers;
        picked.push(id.clone());
    }
    if freed.envs < need.envs || freed.workers < need.workers {
        return false;
    }
    for id in picked {
        let s = entries.get_mut(&id).expect("picked from the entries");
        tracing::info!(session = %id, identity = %s.identity, for_client = client, "closing a session lent past its client's share: another client asks for the room");
        s.reclaimed.store(true, Ordering::Relaxed);
        s.stop.store(true, Ordering::Relaxed);
        s.requests = None;
    }
    true
}

/// Bytes from the OS random source.
fn random<const N: usize>() -> Result<[u8; N], HubError> {
    let mut bytes = [0u8; N];
    // SAFETY: `bytes` is a valid buffer of its length; getrandom fills it or fails.
    let filled = unsafe { libc::getrandom(bytes.as_mut_ptr().cast(), bytes.len(), 0) };
    if filled != bytes.len() as isize {
        return Err(HubError::Internal(format!(
            "the OS random source failed: {}",
            std::io::Error::last_os_error()
        )));
    }
    Ok(bytes)
}

/// A session id no one can guess (128 random bits from the OS). It names the session's keys,
/// which every peer that sees its traffic learns: the session's secret is its key.
pub fn new_session_id() -> Result<String, HubError> {
    let hex: String = random::<16>()?.iter().map(|b| format!("{b:02x}")).collect();
    Ok(format!("s{hex}"))
}

/// Who a session is for: the client's token key (the session ends when it goes) and its
/// identity (what per-client limits count).
pub struct Client<'a> {
    /// Its liveliness token key.
    pub token: &'a str,
    /// Its identity (64 hex digits).
    pub identity: &'a str,
}

/// Registers started session `id` (its key agreed with the client,
/// [`envhub_protocol::handshake`]) and runs it on its own thread.
#[allow(clippy::too_many_arguments)]
pub fn start(
    sessions: &Arc<Sessions>,
    zenoh: &zenoh::Session,
    hub: &str,
    id: String,
    client: Client<'_>,
    key: SessionKey,
    vec: VecEnv,
    reservation: Reservation<'_>,
    idle_timeout: Option<Duration>,
) -> Result<(), HubError> {
    let key = Arc::new(key);
    // A client that does not read its answers must not hold the hub's other sessions back:
    // what does not fit the link's queue is dropped (the client asks again after its resend
    // delay, and a repeat is answered from the kept answer).
    let publisher = zenoh
        .declare_publisher(keys::responses(hub, &id))
        .express(true)
        .congestion_control(zenoh::qos::CongestionControl::Drop)
        .priority(zenoh::qos::Priority::DataHigh)
        .wait()
        .map_err(|e| HubError::Network {
            reason: format!("cannot declare the session's publisher: {e}"),
            hint: "the hub's Zenoh session is failing; see its log".into(),
        })?;
    let (tx, rx) = std::sync::mpsc::sync_channel(SESSION_QUEUE);
    let request_sizes = batch_codec::sealed_request_sizes(&Layout::new(
        vec.num_envs(),
        vec.action_space().byte_len(),
    ));
    let entry_sizes = request_sizes.clone();
    let answered = Arc::new(AtomicU64::new(0));
    let mut entries = sessions.lock();
    // The client may have gone while the workers started (it was killed, or gave up).
    let client_gone = sessions
        .gone
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .contains(&keys::client_token(client.token));
    let stop = Arc::new(AtomicBool::new(client_gone));
    let reclaimed = Arc::new(AtomicBool::new(false));
    entries.insert(
        id.clone(),
        Entry {
            client: client.token.to_string(),
            identity: client.identity.to_string(),
            envs: vec.num_envs(),
            workers: vec.num_workers(),
            requests: Some(tx),
            request_sizes: entry_sizes,
            key: key.clone(),
            answered: answered.clone(),
            gate: Arc::default(),
            stop: stop.clone(),
            lent: reservation.lent,
            serial: SERIAL.fetch_add(1, Ordering::Relaxed),
            reclaimed: reclaimed.clone(),
        },
    );
    drop(entries);
    drop(reservation);
    let (sessions, thread_id) = (sessions.clone(), id.clone());
    std::thread::Builder::new()
        .name(format!("envhub-session-{id}"))
        .spawn(move || {
            let last_seq = run(vec, rx, &publisher, &key, &answered, &stop, idle_timeout);
            // Remembered as closed before it stops being open: a request finds one or the
            // other.
            {
                let mut closed = sessions.closed.lock().unwrap_or_else(|e| e.into_inner());
                if closed.len() == CLOSED_REMEMBERED {
                    closed.pop_front();
                }
                closed.push_back(Closed {
                    id: thread_id.clone(),
                    key,
                    request_sizes,
                    last_seq,
                    answer: None,
                    reclaimed: reclaimed.load(Ordering::Relaxed),
                });
            }
            sessions.lock().remove(&thread_id);
            tracing::info!(session = %thread_id, "remote session closed");
        })
        .map_err(|e| HubError::Internal(format!("cannot start a session thread: {e}")))?;
    Ok(())
}

/// Hands a request to its session's queue, opened, if it is sealed with the session's key and
/// not a replay; anything else is dropped unanswered (nothing unauthenticated is answered).
/// A request of a session that ended lately is answered that it is closed.
pub fn dispatch(sessions: &Sessions, zenoh: &zenoh::Session, hub: &str, key: &str, payload: &[u8]) {
    let Some(id) = keys::session_of(hub, key) else {
        return;
    };
    let entries = sessions.lock();
    let Some((tx, entry)) = entries.get(id).and_then(|s| Some((s.requests.clone()?, s))) else {
        drop(entries);
        return answer_closed(sessions, zenoh, hub, id, payload);
    };
    // The size is checked before anything is copied, the seal before anything is queued.
    if !entry.request_sizes.contains(&payload.len()) {
        return dropped("not the size of this session's requests", id);
    }
    let (key, answered, gate) = (
        entry.key.clone(),
        entry.answered.clone(),
        entry.gate.clone(),
    );
    drop(entries);
    // Replays are dropped by their sequence number (in clear) before the seal is even
    // checked; the gate is moved only by requests whose seal was.
    let clear_seq = u64::from_le_bytes(payload[..8].try_into().expect("checked size"));
    if let Err(why) = gate_of(&gate).admits(clear_seq, answered.load(Ordering::Acquire)) {
        return dropped(why, id);
    }
    let mut request = payload.to_vec();
    let Ok(seq) = key.open(Direction::Request, &mut request) else {
        return dropped("not sealed with the session's key", id);
    };
    let mut gate = gate_of(&gate);
    if let Err(why) = gate.admits(seq, answered.load(Ordering::Acquire)) {
        return dropped(why, id);
    }
    match tx.try_send(request) {
        Ok(()) => gate.passed(seq, answered.load(Ordering::Acquire)),
        Err(TrySendError::Full(_)) => dropped("the session's queue is full", id),
        Err(TrySendError::Disconnected(_)) => dropped("the session is closing", id),
    }
}

/// The shortest time between two repeats of a session's last answered request that are
/// answered: a client repeats a request only after 1 s without an answer, so more are a
/// replay flood, and each would make the hub publish its answer again.
const REPEAT_GAP: Duration = Duration::from_millis(250);

/// What a session let into its queue lately: replays are dropped before any work.
#[derive(Debug, Default)]
struct Gate {
    /// The highest sequence number queued (a copy of one still queued or in work is dropped).
    queued: u64,
    /// When a repeat of the last answered request was last let in.
    last_repeat: Option<Instant>,
}

impl Gate {
    /// Whether request `seq` may go to the queue, the session having answered `answered`.
    fn admits(&self, seq: u64, answered: u64) -> Result<(), &'static str> {
        if seq < answered {
            return Err("out of sequence (a replay)");
        }
        if seq == answered {
            if self.last_repeat.is_some_and(|t| t.elapsed() < REPEAT_GAP) {
                return Err("a repeat of the answered request too soon (a replay)");
            }
        } else if seq <= self.queued {
            return Err("a copy of a request already queued (a replay)");
        }
        Ok(())
    }

    /// Notes that request `seq` (sealed, checked) went to the queue.
    fn passed(&mut self, seq: u64, answered: u64) {
        if seq == answered {
            self.last_repeat = Some(Instant::now());
        }
        self.queued = self.queued.max(seq);
    }
}

fn gate_of(gate: &Mutex<Gate>) -> std::sync::MutexGuard<'_, Gate> {
    gate.lock().unwrap_or_else(|e| e.into_inner())
}

/// Answers a request of a session that ended lately that it is closed (sealed with its key,
/// so its client believes it and fails the call at once); anything else is dropped.
fn answer_closed(sessions: &Sessions, zenoh: &zenoh::Session, hub: &str, id: &str, payload: &[u8]) {
    let mut closed = sessions.closed.lock().unwrap_or_else(|e| e.into_inner());
    let Some(session) = closed.iter_mut().find(|c| c.id == id) else {
        return dropped("no session of this id", id);
    };
    if !session.request_sizes.contains(&payload.len()) {
        return dropped("not the size of this session's requests", id);
    }
    let mut request = payload.to_vec();
    let Ok(seq) = session.key.open(Direction::Request, &mut request) else {
        return dropped("not sealed with the session's key", id);
    };
    let answer = match &session.answer {
        Some((s, answer)) if *s == seq => answer.clone(),
        // Sequence numbers the session (or this answer) sealed already: replays.
        Some((s, _)) if seq < *s => return dropped("out of sequence (a replay)", id),
        _ if seq <= session.last_seq => return dropped("out of sequence (a replay)", id),
        _ => {
            let text = if session.reclaimed {
                format!(
                    "hub `{hub}` closed session `{id}`: it was lent past this client's share of \
                     the hub while no other client asked, and another client asked for the room\n\
                     hint: open at most the client's share (`envhub hubs` shows the hub's limits; \
                     half of them by default), or place envs on other hubs"
                )
            } else {
                format!("hub `{hub}` has no open session `{id}` (closed)")
            };
            let mut answer =
                batch_codec::encode_response(seq, status::ERROR, 0, &[], text.as_bytes());
            session.key.seal(Direction::Response, &mut answer);
            let answer = zenoh::bytes::ZBytes::from(answer);
            session.answer = Some((seq, answer.clone()));
            answer
        }
    };
    drop(closed);
    let _ = zenoh.put(keys::responses(hub, id), answer).wait();
}

/// How long a session's thread looks for the next request (yielding the core) before it
/// sleeps: the client's next request usually follows its last answer within a network round
/// trip, and a thread put to sleep costs tens of µs to wake. `ENVHUB_BRIDGE_SPIN_US`
/// overrides it (0: always sleep).
fn spin_budget() -> Duration {
    let us = std::env::var(envhub_core::env_vars::ENVHUB_BRIDGE_SPIN_US)
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(300);
    Duration::from_micros(us)
}

fn next_request(rx: &Receiver<Vec<u8>>, spin: Duration) -> Result<Vec<u8>, RecvTimeoutError> {
    let start = std::time::Instant::now();
    while start.elapsed() < spin {
        match rx.try_recv() {
            Ok(b) => return Ok(b),
            Err(std::sync::mpsc::TryRecvError::Disconnected) => {
                return Err(RecvTimeoutError::Disconnected);
            }
            Err(std::sync::mpsc::TryRecvError::Empty) => std::thread::yield_now(),
        }
    }
    rx.recv_timeout(IDLE_TICK)
}

fn run(
    mut vec: VecEnv,
    rx: Receiver<Vec<u8>>,
    publisher: &zenoh::pubsub::Publisher<'_>,
    key: &SessionKey,
    answered: &AtomicU64,
    stop: &AtomicBool,
    idle_timeout: Option<Duration>,
) -> u64 {
    let layout = Layout::new(vec.num_envs(), vec.action_space().byte_len());
    let rows_layout = BatchLayout::new(
        vec.num_envs(),
        vec.observation_space().byte_len(),
        vec.autoreset_mode() == envhub_core::AutoresetMode::SameStep,
    );
    let mut last: Option<(u64, zenoh::bytes::ZBytes)> = None;
    let spin = spin_budget();
    let mut last_heard = Instant::now();
    while !stop.load(Ordering::Relaxed) {
        let bytes = match next_request(&rx, spin) {
            Ok(b) => b,
            Err(RecvTimeoutError::Timeout) => {
                if idle_timeout.is_some_and(|idle| last_heard.elapsed() >= idle) {
                    tracing::warn!(
                        idle_s = last_heard.elapsed().as_secs(),
                        "closing a remote session whose client sent nothing (`envhub serve --idle-timeout`)"
                    );
                    break;
                }
                continue;
            }
            Err(RecvTimeoutError::Disconnected) => break,
        };
        // Opened (its seal checked) before it was queued.
        let seq = u64::from_le_bytes(bytes[..8].try_into().expect("a sequence number"));
        last_heard = Instant::now();
        if let Some((last_seq, answer)) = &last
            && seq == *last_seq
        {
            // Sent again: answer again with the same bytes, do not step again.
            let _ = publisher.put(answer.clone()).wait();
            continue;
        }
        let expected = last.as_ref().map_or(1, |(s, _)| s + 1);
        if seq != expected {
            // A replay of an older request (or one the client never sent): dropped. Answering
            // would seal a second message under the same sequence number.
            dropped("out of sequence (a replay)", "");
            continue;
        }
        let (answer, closing) = match batch_codec::parse_request(&bytes, &layout) {
            Ok(request) => {
                let closing = request.header.command == command::CLOSE;
                (serve(&mut vec, &request, &rows_layout), closing)
            }
            Err(message) => {
                tracing::warn!(seq, %message, "unreadable request");
                let text = format!("unreadable request: {message}");
                (
                    batch_codec::encode_response(
                        seq,
                        status::ERROR,
                        layout.num_envs,
                        &[],
                        text.as_bytes(),
                    ),
                    false,
                )
            }
        };
        let mut answer = answer;
        key.seal(Direction::Response, &mut answer);
        // Kept for a repeat of this request: a shared buffer, not a copy.
        let answer = zenoh::bytes::ZBytes::from(answer);
        if let Err(e) = publisher.put(answer.clone()).wait() {
            tracing::warn!(error = %e, "could not send a response");
        }
        last = Some((seq, answer));
        answered.store(seq, Ordering::Release);
        if closing {
            break;
        }
    }
    vec.close();
    last.map_or(0, |(seq, _)| seq)
}

/// Runs one request on the local session; the encoded response.
fn serve(
    vec: &mut VecEnv,
    request: &batch_codec::ParsedRequest<'_>,
    rows_layout: &BatchLayout,
) -> Vec<u8> {
    let seq = request.header.seq;
    let n = vec.num_envs();
    let all = request.selected.iter().all(|&s| s);
    let mut out = Out::new(rows_layout);
    let result = match request.header.command {
        command::RESET => reset(vec, request, all, rows_layout, &mut out),
        command::STEP => step(vec, request, all, rows_layout, &mut out),
        command::RENDER => {
            return match vec.render() {
                Ok(frames) => {
                    let frames: Vec<Option<(usize, usize, Vec<u8>)>> = frames
                        .into_iter()
                        .map(|f| f.map(|f| (f.height, f.width, f.rgb)))
                        .collect();
                    batch_codec::encode_response(seq, status::OK, n, &[], &frames_section(frames))
                }
                Err(e) => batch_codec::encode_error(seq, n, &e),
            };
        }
        _ => {
            vec.close();
            return batch_codec::encode_response(seq, status::CLOSED, n, &[], &[]);
        }
    };
    match result {
        Ok(()) => batch_codec::encode_response(seq, status::OK, n, &out.rows, &out.info()),
        Err(HubError::EnvFailed { envs, message, .. }) => {
            if let Some(batch) = vec.last_batch() {
                out.absorb(rows_layout, &batch);
            }
            let info: Option<serde_json::Value> = serde_json::from_slice(&out.info()).ok();
            let failed: Vec<(usize, String)> =
                envs.iter().map(|&e| (e, message_of(&message, e))).collect();
            let report = serde_json::json!({ "failed": failed, "info": info }).to_string();
            batch_codec::encode_response(seq, status::ENV_FAILED, n, &out.rows, report.as_bytes())
        }
        // A call that failed while the session goes on (bad reset options, an env to reset
        // first): the slice failed this call only, as a local worker's refusal does.
        Err(e) if !vec.is_closed() => {
            batch_codec::encode_response(seq, status::ERROR, n, &[], e.to_string().as_bytes())
        }
        Err(e) => batch_codec::encode_error(seq, n, &e),
    }
}

/// Env `e`'s line of a failure message (`env 3: ...`), else the whole message.
fn message_of(message: &str, e: usize) -> String {
    let prefix = format!("env {e}: ");
    message
        .lines()
        .find_map(|l| l.strip_prefix(&prefix))
        .map_or_else(|| message.to_string(), str::to_string)
}

fn reset(
    vec: &mut VecEnv,
    request: &batch_codec::ParsedRequest<'_>,
    all: bool,
    layout: &BatchLayout,
    out: &mut Out,
) -> Result<(), HubError> {
    let options: envhub_core::ResetOptions = if request.options.is_empty() {
        Default::default()
    } else {
        serde_json::from_str(request.options).map_err(|e| HubError::InvalidConfig {
            what: "reset options",
            reason: e.to_string(),
        })?
    };
    let mask = (!all).then_some(&request.selected[..]);
    let batch = vec.reset_with(&request.seeds, mask, &options)?;
    out.absorb(layout, &batch);
    Ok(())
}

fn step(
    vec: &mut VecEnv,
    request: &batch_codec::ParsedRequest<'_>,
    all: bool,
    layout: &BatchLayout,
    out: &mut Out,
) -> Result<(), HubError> {
    if all {
        let batch = vec.step(request.actions)?;
        out.absorb(layout, &batch);
        return Ok(());
    }
    // Some envs: the local session steps them asynchronously, and every part is gathered
    // before the one answer goes back.
    let ab = vec.action_space().byte_len();
    let ids: Vec<usize> = (0..vec.num_envs())
        .filter(|&e| request.selected[e])
        .collect();
    let mut actions = Vec::with_capacity(ids.len() * ab);
    for &e in &ids {
        actions.extend_from_slice(&request.actions[e * ab..(e + 1) * ab]);
    }
    vec.send(&actions, &ids)?;
    let mut got = 0;
    while got < ids.len() {
        let batch = vec.recv()?;
        got += batch.env_ids.len();
        out.absorb(layout, &batch);
    }
    Ok(())
}

/// A response being made: the result block and the envs' infos.
struct Out {
    rows: Vec<u8>,
    infos: Vec<serde_json::Value>,
    any_info: bool,
}

impl Out {
    fn new(layout: &BatchLayout) -> Out {
        Out {
            rows: vec![0u8; layout.size()],
            infos: Vec::new(),
            any_info: false,
        }
    }

    /// Writes `batch`'s rows (and infos) where its envs go.
    fn absorb(&mut self, layout: &BatchLayout, batch: &Batch<'_>) {
        batch_codec::write_rows(
            layout,
            &mut self.rows,
            batch.env_ids,
            &RowsOut {
                obs: batch.obs,
                rewards: batch.rewards,
                terminated: batch.terminated,
                truncated: batch.truncated,
                final_mask: batch.final_blocks().0,
                final_obs: batch.final_blocks().1,
            },
        );
        if !batch.infos().is_empty() {
            if !self.any_info {
                self.infos = vec![serde_json::Value::Object(Default::default()); layout.num_envs];
                self.any_info = true;
            }
            for (k, &e) in batch.env_ids.iter().enumerate() {
                self.infos[e] = batch.infos()[k].clone();
            }
        }
    }

    /// The info section (empty when no env reported info).
    fn info(&self) -> Vec<u8> {
        if self.any_info {
            serde_json::to_vec(&self.infos).expect("infos serialize")
        } else {
            Vec::new()
        }
    }
}

/// Whose count a [`Cap`] bounds.
#[derive(Clone, Copy)]
enum Scope {
    /// The hub's, over every client (`--max-envs`, `--max-workers`).
    Hub,
    /// One client's share (`--max-envs-per-client`, `--max-workers-per-client`).
    Client,
}

/// One count limit of an admission: `asked` more `noun` on top of `held` may not pass `max`
/// (`None`: no limit). `flag` is the `envhub serve` option that sets it.
struct Cap {
    max: Option<usize>,
    held: usize,
    asked: usize,
    noun: &'static str,
    scope: Scope,
    flag: &'static str,
}

impl Cap {
    /// Why the admission is refused and what would fit, or nothing where it fits.
    fn check(&self) -> Result<(), (String, String)> {
        let Some(max) = self.max else {
            return Ok(());
        };
        if self.held.saturating_add(self.asked) <= max {
            return Ok(());
        }
        let (held, asked, noun, flag) = (self.held, self.asked, self.noun, self.flag);
        let (bound, holds, sets) = match self.scope {
            Scope::Hub => ("its limit", "runs", "limit"),
            Scope::Client => ("this client's share", "holds", "share"),
        };
        let instead = if noun == "workers" {
            "workers here (`workers=`), or place envs on other hubs"
        } else {
            "envs here, or place the rest on other hubs"
        };
        Err((
            format!("{asked} {noun} would exceed {bound} of {max} (it {holds} {held})"),
            format!(
                "ask for at most {} {instead}; its owner sets the {sets} with `envhub serve --{flag} N`",
                max.saturating_sub(held)
            ),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::client_share;
    use std::time::Instant;

    /// Opens racing each other, more of them than the limit: sessions moving from "starting"
    /// to "open" while another open counts them must be counted once, never zero times.
    #[test]
    fn concurrent_opens_never_pass_the_limit_together() {
        const MAX: usize = 3;
        let sessions = Sessions::default();
        let policy = ServePolicy {
            max_envs: Some(MAX),
            ..ServePolicy::unlimited()
        };
        let over = AtomicBool::new(false);
        let passed = std::sync::atomic::AtomicUsize::new(0);
        let deadline = Instant::now() + Duration::from_millis(1500);
        std::thread::scope(|s| {
            for t in 0..8 {
                let (sessions, policy, over, passed) = (&sessions, &policy, &over, &passed);
                s.spawn(move || {
                    let mut k = 0;
                    while Instant::now() < deadline && !over.load(Ordering::Relaxed) {
                        k += 1;
                        let Ok(reservation) = sessions.reserve("c", 1, 1, policy) else {
                            continue;
                        };
                        passed.fetch_add(1, Ordering::Relaxed);
                        // Registered as `start` does: the entry, then the reservation given back.
                        let id = format!("{t}-{k}");
                        sessions
                            .lock()
                            .insert(id.clone(), entry("", 1, 1, reservation.lent));
                        drop(reservation);
                        if sessions.totals().0 > MAX {
                            over.store(true, Ordering::Relaxed);
                        }
                        std::thread::yield_now();
                        sessions.lock().remove(&id);
                    }
                });
            }
        });
        assert!(passed.load(Ordering::Relaxed) > 0, "no open passed at all");
        assert!(
            !over.load(Ordering::Relaxed),
            "more than {MAX} envs were open at once"
        );
    }

    #[test]
    fn replays_are_not_queued_and_repeats_of_the_answer_are_spaced() {
        let mut gate = Gate::default();
        gate.admits(1, 0).expect("the first request");
        gate.passed(1, 0);
        assert!(gate.admits(1, 0).is_err(), "a copy of a queued request");
        // Answered: a repeat (the client heard nothing) once, then not again at once.
        gate.admits(1, 1).expect("a repeat of the answered request");
        gate.passed(1, 1);
        assert!(gate.admits(1, 1).is_err(), "a flood of repeats");
        assert!(gate.admits(0, 1).is_err(), "an older request");
        gate.admits(2, 1).expect("the next request");
        gate.passed(2, 1);
        std::thread::sleep(REPEAT_GAP);
        gate.admits(2, 2).expect("a repeat after the gap");
    }

    #[test]
    fn a_client_holds_at_most_its_sessions_and_others_are_not_counted() {
        let sessions = Sessions::default();
        let policy = ServePolicy {
            max_sessions_per_client: Some(2),
            ..ServePolicy::unlimited()
        };
        let a1 = sessions.reserve("a", 1, 1, &policy).expect("first");
        let _a2 = sessions.reserve("a", 1, 1, &policy).expect("second");
        let Refusal { reason, hint, .. } = sessions
            .reserve("a", 1, 1, &policy)
            .err()
            .expect("third refused");
        assert!(reason.contains("limit is 2"), "{reason}");
        assert!(hint.contains("--max-sessions-per-client"), "{hint}");
        let _b = sessions
            .reserve("b", 1, 1, &policy)
            .expect("another client is not counted");
        drop(a1);
        let _a3 = sessions
            .reserve("a", 1, 1, &policy)
            .expect("a reservation given back frees its place");
    }

    /// An entry as `start` registers it (no Zenoh, no workers).
    fn entry(identity: &str, envs: usize, workers: usize, lent: bool) -> Entry {
        Entry {
            client: String::new(),
            identity: identity.to_string(),
            envs,
            workers,
            requests: None,
            request_sizes: 0..=0,
            key: Arc::new(SessionKey::new(
                envhub_protocol::seal::Cipher::Aes256Gcm,
                &[0; envhub_protocol::seal::KEY_LEN],
            )),
            answered: Arc::default(),
            gate: Arc::default(),
            stop: Arc::new(AtomicBool::new(false)),
            lent,
            serial: SERIAL.fetch_add(1, Ordering::Relaxed),
            reclaimed: Arc::default(),
        }
    }

    /// Opens session `id` on reservation `r` as `start` does: its entry, then `r` given back.
    fn open(sessions: &Sessions, id: &str, r: Reservation<'_>) {
        let e = entry(&r.client, r.envs, r.workers, r.lent);
        sessions.lock().insert(id.to_string(), e);
    }

    /// The sessions being closed, by id; their threads end (they leave the entries).
    fn closing(sessions: &Sessions) -> Vec<String> {
        let mut entries = sessions.lock();
        let mut ids: Vec<String> = entries
            .iter()
            .filter(|(_, s)| s.stop.load(Ordering::Relaxed))
            .map(|(id, _)| id.clone())
            .collect();
        ids.sort();
        for id in &ids {
            assert!(entries[id].reclaimed.load(Ordering::Relaxed), "{id}");
            entries.remove(id);
        }
        ids
    }

    /// A key alone may take the whole hub; what it opens past its share is lent. Another key
    /// asking for room within its share gets the newest lent sessions closed for it (only as
    /// many as it needs, never one within the first key's share), and while it waits no key
    /// is lent more; past its own share it reclaims nothing.
    #[test]
    fn a_lone_client_borrows_past_its_share_and_gives_it_back_to_another() {
        let sessions = Sessions::default();
        let policy = ServePolicy {
            max_workers: Some(8),
            max_envs: Some(64),
            max_workers_per_client: client_share(Some(8)),
            max_envs_per_client: client_share(Some(64)),
            ..ServePolicy::unlimited()
        };
        for k in 0..8 {
            let r = sessions
                .reserve("first", 1, 1, &policy)
                .expect("a lone client may take the whole hub");
            assert_eq!(r.lent, k >= 4, "session {k}: lent only past the share of 4");
            open(&sessions, &format!("first-{k}"), r);
        }
        let full = sessions
            .reserve("first", 1, 1, &policy)
            .err()
            .expect("full");
        assert!(
            full.reason.contains("limit of 8") && !full.room_coming,
            "{full:?}"
        );
        // Another key within its share: the two newest lent sessions close for it.
        let wait = sessions
            .reserve("second", 2, 2, &policy)
            .err()
            .expect("waits");
        assert!(
            wait.room_coming && wait.reason.contains("closing to make room"),
            "{wait:?}"
        );
        let again = sessions
            .reserve("second", 2, 2, &policy)
            .err()
            .expect("waits");
        assert!(again.room_coming, "{again:?}");
        assert_eq!(
            closing(&sessions),
            ["first-6", "first-7"],
            "no more than it needs"
        );
        // While it waits, the first key is lent nothing, though there is room now.
        let share = sessions
            .reserve("first", 1, 1, &policy)
            .err()
            .expect("share");
        assert!(
            share.reason.contains("share of 4") && share.reason.contains("another client waits"),
            "{share:?}"
        );
        assert!(share.hint.contains("--max-workers-per-client"), "{share:?}");
        let r = sessions
            .reserve("second", 2, 2, &policy)
            .expect("the room given back");
        assert!(!r.lent);
        open(&sessions, "second-0", r);
        // Again, up to its share: the first key keeps exactly its share.
        let wait = sessions
            .reserve("second", 1, 2, &policy)
            .err()
            .expect("waits");
        assert!(wait.room_coming, "{wait:?}");
        assert_eq!(closing(&sessions), ["first-4", "first-5"]);
        open(
            &sessions,
            "second-1",
            sessions.reserve("second", 1, 2, &policy).unwrap(),
        );
        let past = sessions
            .reserve("second", 1, 1, &policy)
            .err()
            .expect("past");
        assert!(
            !past.room_coming && past.reason.contains("limit of 8"),
            "{past:?}"
        );
        assert!(
            closing(&sessions).is_empty(),
            "nothing within a share is closed"
        );
        // Nothing is lent now: a third key within its share waits with no room coming.
        let third = sessions
            .reserve("third", 1, 1, &policy)
            .err()
            .expect("full");
        assert!(
            !third.room_coming && third.reason.contains("limit of 8"),
            "{third:?}"
        );
    }

    #[test]
    fn the_default_policy_has_every_limit_on() {
        let p = ServePolicy::default();
        assert!(
            p.max_envs.is_some() && p.max_workers.is_some() && p.max_sessions_per_client.is_some()
        );
        assert!(p.max_envs_per_client < p.max_envs && p.max_workers_per_client < p.max_workers);
        assert!(p.idle_timeout.is_some() && p.max_step_timeout < Duration::MAX);
        assert!(!p.allow_remote_files && !p.allow_provision && !p.insecure_listen);
        let sessions = Sessions::default();
        let Refusal { reason, hint, .. } = sessions
            .reserve("c", 200_000, 1, &p)
            .err()
            .expect("200,000 envs refused by default");
        assert!(
            reason.contains("200000 envs") && hint.contains("--max-envs"),
            "{reason} / {hint}"
        );
    }
}
