//! A hub that lies: a Zenoh peer that holds a hub's token and answers like one, with hostile
//! replies. The client must come out of each with an error that names the hub — never a
//! panic, a write out of bounds, or an error kind that means something else here (a hub's
//! `Interrupted` would be raised as Python's `KeyboardInterrupt`) — and a session that can
//! go on where its other envs can.

use envhub_hub::{EnvConfig, Hub, HubError, NetConfig, Registry, SessionOptions};
use envhub_protocol::handshake::{self, Identity};
use envhub_protocol::seal::{Direction, SessionKey};
use envhub_shm::BatchLayout;
use serde_json::json;
use std::sync::{Arc, Mutex};
use std::time::Duration;
use zenoh::Wait;

/// What the fake hub answers next.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Lie {
    /// Opens fine, answers steps and resets honestly.
    None,
    /// An open answered with the error kind `interrupted`.
    InterruptedOpen,
    /// An open whose observation space takes 2^40 bytes.
    HugeSpace,
    /// A step answered with a failure report naming env 999.
    FailedEnvOutOfRange,
    /// A step answered with result rows of the wrong size.
    ShortRows,
    /// A step answered with the session's end, as the error kind `interrupted`.
    InterruptedStep,
}

const OBS: usize = 16; // CartPole: four float32

/// The liar's answer to an open (`request`: its bytes): CartPole with `observation_space`,
/// and the session's key, agreed with the client as a hub does (a hub that lies still seals:
/// it is the session's hub).
fn cartpole_reply(
    identity: &Identity,
    request: &[u8],
    observation_space: serde_json::Value,
) -> (serde_json::Value, SessionKey) {
    let message = envhub_protocol::untrusted::read_open_request(request).unwrap();
    let (exchange, cipher) =
        handshake::check_client_hello("liar", &message.hello, now_ms()).unwrap();
    let (hello, key) =
        handshake::hub_answer(identity, "liar", "s1-1", request, &exchange, cipher).unwrap();
    let reply = envhub_e2e::intruder::cartpole_open_reply(
        "s1-1",
        observation_space,
        serde_json::to_value(hello).unwrap(),
    );
    (reply, key)
}

fn now_ms() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as u64
}

fn response(seq: u64, status: u32, n: u32, rows: &[u8], info: &[u8]) -> Vec<u8> {
    let mut out = Vec::new();
    out.extend_from_slice(&seq.to_le_bytes());
    out.extend_from_slice(&status.to_le_bytes());
    out.extend_from_slice(&n.to_le_bytes());
    out.extend_from_slice(&(info.len() as u32).to_le_bytes());
    out.extend_from_slice(&(rows.len() as u32).to_le_bytes());
    out.extend_from_slice(rows);
    out.extend_from_slice(info);
    out
}

/// A fake hub: what it holds (dropped: it leaves).
struct Liar {
    _session: zenoh::Session,
    _token: zenoh::liveliness::LivelinessToken,
    _id_token: zenoh::liveliness::LivelinessToken,
    _open: zenoh::query::Queryable<()>,
    _requests: zenoh::pubsub::Subscriber<()>,
}

/// A fake hub `name` on `endpoint` hosting CartPole with observation space `obs_space`.
fn liar(name: &str, endpoint: &str, obs_space: serde_json::Value, lie: Arc<Mutex<Lie>>) -> Liar {
    let net = NetConfig {
        listen: vec![endpoint.to_string()],
        multicast: Some(false),
        ..NetConfig::default()
    };
    let session = zenoh::open(net.zenoh_config(false).unwrap())
        .wait()
        .unwrap();
    let key: Arc<Mutex<Option<SessionKey>>> = Arc::default();
    let identity = Identity::generate().unwrap();
    let open = {
        let (lie, key) = (lie.clone(), key.clone());
        session
            .declare_queryable(format!("envhub/hub/{name}/open"))
            .callback(move |query| {
                let request = query.payload().map(|p| p.to_bytes().into_owned()).unwrap();
                let reply = match *lie.lock().unwrap() {
                    Lie::InterruptedOpen => json!({"error": {"kind": "interrupted"}}),
                    Lie::HugeSpace => {
                        cartpole_reply(
                            &identity,
                            &request,
                            json!({"type": "multi_binary", "shape": [1u64 << 40]}),
                        )
                        .0
                    }
                    _ => {
                        let (reply, session_key) =
                            cartpole_reply(&identity, &request, obs_space.clone());
                        *key.lock().unwrap() = Some(session_key);
                        reply
                    }
                };
                let _ = query
                    .reply(query.key_expr().clone(), reply.to_string())
                    .wait();
            })
            .wait()
            .unwrap()
    };
    let requests = {
        let (z, name) = (session.clone(), name.to_string());
        session
            .declare_subscriber(format!("envhub/session/{name}/*/req"))
            .callback(move |sample| {
                let mut req = sample.payload().to_bytes().into_owned();
                let key = key.lock().unwrap();
                let Some(seal) = key.as_ref() else {
                    return;
                };
                if seal.open(Direction::Request, &mut req).is_err() {
                    return;
                }
                let seq = u64::from_le_bytes(req[..8].try_into().unwrap());
                let n = u32::from_le_bytes(req[12..16].try_into().unwrap());
                let command = u32::from_le_bytes(req[8..12].try_into().unwrap());
                let layout = BatchLayout::new(n as usize, OBS, false);
                let rows = vec![0u8; layout.size()];
                let lie = *lie.lock().unwrap();
                let answer = match (command, lie) {
                    (3, _) => response(seq, 2, n, &[], &[]), // close
                    (2, Lie::FailedEnvOutOfRange) => {
                        let report = json!({"failed": [[999, "made up"]], "info": null});
                        response(seq, 3, n, &rows, report.to_string().as_bytes())
                    }
                    (2, Lie::ShortRows) => response(seq, 0, n, &rows[..rows.len() / 2], b""),
                    (2, Lie::InterruptedStep) => {
                        response(seq, 16, n, &[], br#"{"kind":"interrupted"}"#)
                    }
                    _ => response(seq, 0, n, &rows, b""),
                };
                let key = sample.key_expr().as_str().replace("/req", "/rep");
                let mut answer = answer;
                seal.seal(Direction::Response, &mut answer);
                let _ = z.put(key, answer).wait();
            })
            .wait()
            .unwrap()
    };
    // A liar is still the hub of its name: its answers come from the id it announces.
    let id_token = session
        .liveliness()
        .declare_token(envhub_protocol::keys::hub_id_token(
            name,
            &session.zid().to_string(),
        ))
        .wait()
        .unwrap();
    let token = session
        .liveliness()
        .declare_token(format!("envhub/hub/{name}"))
        .wait()
        .unwrap();
    Liar {
        _session: session,
        _token: token,
        _id_token: id_token,
        _open: open,
        _requests: requests,
    }
}

fn client(endpoint: &str) -> Hub {
    envhub_e2e::binary("envhub-worker");
    Hub::new(Registry::builtin())
        .with_options(SessionOptions {
            namespace: format!("e2e_liar_{}_", std::process::id()),
            step_timeout: Duration::from_secs(5),
            start_timeout: Duration::from_secs(20),
            ..SessionOptions::default()
        })
        .with_network(NetConfig {
            connect: vec![endpoint.to_string()],
            multicast: Some(false),
            // The liar's identity is new in every run: pinned in a file of this run's.
            known_hubs: Some(envhub_e2e::remote::known_hubs()),
            ..NetConfig::default()
        })
}

fn names_the_hub(e: &HubError) {
    assert!(!matches!(e, HubError::Interrupted), "{e:?}");
    assert!(
        e.to_string().contains("`liar`"),
        "the hub is not named: {e}"
    );
}

#[test]
fn a_lying_hub_gets_errors_that_name_it_and_the_session_goes_on() {
    let endpoint = format!("tcp/127.0.0.1:{}", envhub_e2e::remote::free_port());
    let lie = Arc::new(Mutex::new(Lie::None));
    let hub = client(&endpoint);
    // The liar's spaces are this machine's, so that a session may mix the two.
    let mut local = hub
        .make_vec("gym-cartpole", 1, &EnvConfig::default())
        .unwrap();
    let obs_space = serde_json::to_value(local.observation_space()).unwrap();
    local.close();
    let _liar = liar("liar", &endpoint, obs_space, lie.clone());
    let config = EnvConfig::default();
    let on = |p: &str| p.parse::<envhub_hub::Placement>().unwrap();
    // Until the liar's token has arrived, it is an unknown hub.
    *lie.lock().unwrap() = Lie::InterruptedOpen;
    let live = std::time::Instant::now();
    while matches!(
        hub.make_vec_on("gym-cartpole", 2, &config, &on("liar")),
        Err(HubError::UnknownHub { .. })
    ) && live.elapsed() < Duration::from_secs(5)
    {
        std::thread::sleep(Duration::from_millis(50));
    }

    for open_lie in [Lie::InterruptedOpen, Lie::HugeSpace] {
        *lie.lock().unwrap() = open_lie;
        let Err(e) = hub.make_vec_on("gym-cartpole", 2, &config, &on("liar")) else {
            panic!("{open_lie:?}: a lying open succeeded");
        };
        names_the_hub(&e);
    }

    // The lying hub hosts env 0, this machine env 1: the liar's slice answers first.
    *lie.lock().unwrap() = Lie::None;
    let mut env = hub
        .make_vec_on("gym-cartpole", 2, &config, &on("liar:1,local:1"))
        .expect("an honest open");
    env.reset(Some(0)).unwrap();
    let actions = [0u8; 16];
    for step_lie in [Lie::FailedEnvOutOfRange, Lie::ShortRows] {
        *lie.lock().unwrap() = step_lie;
        let e = env.step(&actions).expect_err("a lying step fails");
        names_the_hub(&e);
        // The local worker's answer was taken with it: the session steps on.
        *lie.lock().unwrap() = Lie::None;
        env.step(&actions)
            .unwrap_or_else(|e| panic!("after {step_lie:?}: {e}"));
    }
    *lie.lock().unwrap() = Lie::InterruptedStep;
    let e = env.step(&actions).expect_err("a hub's end of the session");
    names_the_hub(&e);
}
