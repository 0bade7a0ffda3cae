//! A peer on this machine's LAN address, as an attacker would run one: a Zenoh peer without
//! credentials listening on the first global-scope address, scouting by multicast, holding a
//! hub's token to lure clients. A default `envhub serve` (no credentials, nothing configured)
//! must never connect to it, show it its token, or answer its `open`; a default client must
//! neither connect to it nor believe its token, and still find the local hub.
//!
//! Needs an interface with a global-scope IPv4 address; skipped with the reason otherwise,
//! unless `ENVHUB_LAN_REQUIRED` is set (then a skip is a failure).

use envhub_e2e::binary;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// The first global-scope IPv4 address of this machine (`ip -4 -o addr show scope global`).
fn lan_address() -> Option<String> {
    let out = Command::new("ip")
        .args(["-4", "-o", "addr", "show", "scope", "global"])
        .output()
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let line = text.lines().next()?;
    let mut words = line.split_whitespace();
    words.find(|w| *w == "inet")?;
    Some(words.next()?.split('/').next()?.to_string())
}

/// The attacker: a default Zenoh peer (multicast scouting and gossip on, autoconnect on, no
/// credentials) listening on `address`.
fn attacker(address: &str) -> zenoh::Session {
    let mut config = zenoh::Config::default();
    let listen = format!("[\"tcp/{address}:0\"]");
    config.insert_json5("listen/endpoints", &listen).unwrap();
    config.insert_json5("mode", "\"peer\"").unwrap();
    zenoh::open(config)
        .wait()
        .expect("the attacker's peer opens")
}

#[test]
fn a_peer_on_the_lan_never_reaches_a_default_hub_and_a_default_client_ignores_it() {
    let Some(address) = lan_address() else {
        assert!(
            std::env::var_os("ENVHUB_LAN_REQUIRED").is_none_or(|v| v.is_empty()),
            "ENVHUB_LAN_REQUIRED is set but this machine has no global-scope IPv4 address"
        );
        eprintln!("skipped: no global-scope IPv4 address on this machine");
        return;
    };
    let pid = std::process::id();
    let name = format!("lan-victim-{pid}");
    let dir = std::env::temp_dir().join(format!("e2e-lan-{pid}"));
    let local = dir.join("hubs");
    std::fs::create_dir_all(&dir).unwrap();
    let peer = attacker(&address);
    let rogue = format!("lan-rogue-{pid}");
    let _lure = peer
        .liveliness()
        .declare_token(format!("envhub/hub/{rogue}"))
        .wait()
        .unwrap();
    // A default hub: no credentials, no endpoint, multicast left as it is by default.
    let mut hub = Command::new(binary("envhub"))
        .args(["serve", "--name", &name, "--socket"])
        .arg(dir.join("hub.sock"))
        .env("ENVHUB_NAMESPACE", format!("e2e_lan_{pid}_"))
        .env(envhub_hub::local::ENVHUB_LOCAL_HUBS, &local)
        .env_remove(envhub_hub::ENVHUB_MULTICAST)
        .env_remove(envhub_hub::ENVHUB_CONNECT)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // A hang bound: the entry appears once the hub answers.
    let deadline = Instant::now() + Duration::from_secs(120);
    while !local.exists() || std::fs::read_dir(&local).map_or(0, |d| d.count()) == 0 {
        assert!(
            Instant::now() < deadline,
            "the hub did not start within 120 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    // A default client on this machine: it finds the local hub, and not the lure.
    let listed = envhub_e2e::envhub_hubs_listing(&local, &name);
    // Scouting runs for seconds: give a hub that scouts (or answers scouts) time to do it.
    std::thread::sleep(Duration::from_secs(4));
    let envhub_e2e::intruder::Seen {
        peers,
        tokens,
        open_answers: open_replies,
    } = envhub_e2e::intruder::probe(&peer, &name);
    let _ = hub.kill();
    let _ = hub.wait();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(
        listed.contains(&name),
        "a default client on this machine did not find the local hub: {listed}"
    );
    assert!(
        !listed.contains(&rogue),
        "a default client believed the LAN peer's token: {listed}"
    );
    assert!(
        peers.is_empty(),
        "the LAN peer got links to {peers:?} (hub or client)"
    );
    assert!(
        tokens.iter().all(|t| t == &format!("envhub/hub/{rogue}")),
        "the LAN peer saw tokens {tokens:?}"
    );
    assert_eq!(open_replies, 0, "the LAN peer's open was answered");
}
