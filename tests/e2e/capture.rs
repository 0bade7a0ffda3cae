//! A capture of every byte of a session's link without TLS reads nothing: the client reaches
//! the hub through a TCP relay of the test that records both directions (what a capture on
//! the link sees: the open request and reply included), and a peer subscribed to every
//! session's messages keeps the sealed requests and answers. No 32 bytes of the capture, raw
//! or written as 64 hex digits, open any of them: the session key never travelled.

use envhub_e2e::remote::{RemoteHub, known_hubs};
use envhub_hub::{EnvConfig, Hub, NetConfig, Placement, Registry};
use envhub_protocol::seal::{Cipher, Direction, KEY_LEN, SessionKey};
use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// A relay on loopback to `target`, recording every byte both ways, until dropped.
struct Relay {
    port: u16,
    captured: Arc<Mutex<Vec<u8>>>,
    stop: Arc<AtomicBool>,
}

impl Relay {
    fn to(target: &str) -> Relay {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        listener.set_nonblocking(true).unwrap();
        let port = listener.local_addr().unwrap().port();
        let captured = Arc::new(Mutex::new(Vec::new()));
        let stop = Arc::new(AtomicBool::new(false));
        let (target, c, s) = (target.to_string(), captured.clone(), stop.clone());
        std::thread::spawn(move || {
            while !s.load(Ordering::Relaxed) {
                match listener.accept() {
                    Ok((client, _)) => {
                        client.set_nonblocking(false).unwrap();
                        let Ok(hub) = TcpStream::connect(&target) else {
                            continue;
                        };
                        for (from, to) in [
                            (client.try_clone().unwrap(), hub.try_clone().unwrap()),
                            (hub, client),
                        ] {
                            let (c, s) = (c.clone(), s.clone());
                            std::thread::spawn(move || copy(from, to, &c, &s));
                        }
                    }
                    Err(_) => std::thread::sleep(Duration::from_millis(10)),
                }
            }
        });
        Relay {
            port,
            captured,
            stop,
        }
    }
}

impl Drop for Relay {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Copies `from` to `to`, recording every byte, until either end closes or the relay stops.
fn copy(mut from: TcpStream, mut to: TcpStream, captured: &Mutex<Vec<u8>>, stop: &AtomicBool) {
    from.set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let mut buf = vec![0u8; 1 << 16];
    while !stop.load(Ordering::Relaxed) {
        match from.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                captured.lock().unwrap().extend_from_slice(&buf[..n]);
                if to.write_all(&buf[..n]).is_err() {
                    break;
                }
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => break,
        }
    }
    let _ = to.shutdown(std::net::Shutdown::Both);
}

/// The keys a capture could hold: every 32-byte window, and every 64-hex-digit window read
/// as bytes.
fn candidate_keys(capture: &[u8]) -> impl Iterator<Item = [u8; KEY_LEN]> + '_ {
    let raw = capture
        .windows(KEY_LEN)
        .map(|w| <[u8; KEY_LEN]>::try_from(w).unwrap());
    let hex = capture.windows(2 * KEY_LEN).filter_map(|w| {
        let text = std::str::from_utf8(w).ok()?;
        let mut key = [0u8; KEY_LEN];
        for (i, b) in key.iter_mut().enumerate() {
            *b = u8::from_str_radix(text.get(2 * i..2 * i + 2)?, 16).ok()?;
        }
        Some(key)
    });
    raw.chain(hex)
}

/// The first candidate key in `capture` that opens `sealed` (a message of `direction`), as a
/// key of either cipher.
fn key_in(capture: &[u8], sealed: &[u8], direction: Direction) -> Option<[u8; KEY_LEN]> {
    candidate_keys(capture).find(|k| {
        Cipher::ALL.into_iter().any(|cipher| {
            let mut m = sealed.to_vec();
            SessionKey::new(cipher, k).open(direction, &mut m).is_ok()
        })
    })
}

#[test]
fn a_capture_of_every_byte_of_a_link_without_tls_cannot_decrypt_the_session() {
    // The search finds a key that travels, as the open reply's `key` field once did.
    let shown = [7u8; KEY_LEN];
    let mut sealed_by_shown = 1u64.to_le_bytes().to_vec();
    sealed_by_shown.extend_from_slice(b"an observation");
    SessionKey::new(Cipher::fastest_here(), &shown).seal(Direction::Response, &mut sealed_by_shown);
    let leaky = format!(r#"{{"key":"{}"}}"#, "07".repeat(KEY_LEN));
    assert_eq!(
        key_in(leaky.as_bytes(), &sealed_by_shown, Direction::Response),
        Some(shown),
        "the search does not find a key in hex"
    );

    let a = RemoteHub::start("captured", &[], &[]);
    let address = a.endpoint.trim_start_matches("tcp/").to_string();
    let relay = Relay::to(&address);
    // A peer that sees the session's messages (directly on the hub, not through the relay).
    let observer = zenoh::open(
        envhub_e2e::remote::net_to(&[&a])
            .zenoh_config(false)
            .unwrap(),
    )
    .wait()
    .unwrap();
    type Seen = Arc<Mutex<Vec<(String, Vec<u8>)>>>;
    let seen: Seen = Arc::default();
    let _spy = {
        let seen = seen.clone();
        observer
            .declare_subscriber("envhub/session/**")
            .callback(move |s| {
                seen.lock().unwrap().push((
                    s.key_expr().as_str().to_string(),
                    s.payload().to_bytes().into_owned(),
                ));
            })
            .wait()
            .unwrap()
    };
    std::thread::sleep(Duration::from_millis(500));
    let client = Hub::new(Registry::builtin()).with_network(NetConfig {
        connect: vec![format!("tcp/127.0.0.1:{}", relay.port)],
        multicast: Some(false),
        known_hubs: Some(known_hubs()),
        ..NetConfig::default()
    });
    let mut env = client
        .make_vec_on(
            "gym-cartpole",
            2,
            &EnvConfig::default(),
            &Placement::Hubs(vec![a.name.clone()]),
        )
        .expect("a session through the relay");
    let rollout = envhub_e2e::rollout_bytes(&mut env, 0, 1, 50);
    env.close();
    assert!(!rollout.is_empty());
    // The answers seen are in the capture too (what the relay recorded is the session's link).
    let deadline = Instant::now() + Duration::from_secs(10);
    while seen.lock().unwrap().len() < 40 && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    let capture = relay.captured.lock().unwrap().clone();
    drop(relay);
    let seen = seen.lock().unwrap().clone();
    let answers: Vec<&Vec<u8>> = seen
        .iter()
        .filter(|(k, _)| k.ends_with("/rep"))
        .map(|(_, b)| b)
        .collect();
    let requests: Vec<&Vec<u8>> = seen
        .iter()
        .filter(|(k, _)| k.ends_with("/req"))
        .map(|(_, b)| b)
        .collect();
    eprintln!(
        "captured {} bytes through the relay; the observer saw {} requests and {} answers",
        capture.len(),
        requests.len(),
        answers.len()
    );
    // The observer links to the hub alone: it sees the hub's answers (a peer does not route
    // the client's requests to other peers).
    assert!(!answers.is_empty(), "the observer saw no answers");
    let in_capture = |m: &[u8]| capture.windows(m.len()).any(|w| w == m);
    assert!(
        answers.iter().chain(&requests).all(|m| in_capture(m)),
        "a session message the observer saw is not in the capture: the relay missed traffic"
    );
    assert!(
        in_capture(b"\"exchange\"") && in_capture(b"\"hello\""),
        "the open request and reply are not in the capture"
    );
    // The hub took the client's offer's first cipher (both ends run on this CPU).
    let picked = format!("\"cipher\":\"{}\"", Cipher::fastest_here().name());
    assert!(
        in_capture(picked.as_bytes()),
        "the open reply does not pick {picked}"
    );
    // Every candidate key of the capture against the first answer and the first request.
    let mut sealed = vec![(answers[0], Direction::Response)];
    sealed.extend(requests.first().map(|r| (*r, Direction::Request)));
    for (sealed, direction) in sealed {
        assert_eq!(
            key_in(&capture, sealed, direction),
            None,
            "bytes of the capture open the session's {direction:?}: its key travelled"
        );
    }
}
