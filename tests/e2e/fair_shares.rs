//! A hub shared among client keys, attacked by a client in a process of its own (this test
//! binary run again): alone on the hub, it takes all of it (its share holds only while
//! another key waits, so what it opens past half is lent), opens a session under the victim's
//! token with its own key, and re-puts the victim's latest sealed request as fast as it can
//! (no key needed: each copy is authentic). The victim's open succeeds (the session lent to
//! the attacker closes for it, and tells the attacker why) and its steps go on; the hub
//! answers the flood with at most a repeat per 250 ms; when the attacker is killed its
//! sessions end with it, and its share is another key's again. Outcomes and counts are
//! asserted, never the clock.

use envhub_e2e::remote::{RemoteHub, known_hubs, net_to};
use envhub_hub::{EnvConfig, Hub, NetConfig, Placement, Registry};
use envhub_protocol::OpenMessage;
use envhub_protocol::handshake::{Identity, client_hello};
use envhub_protocol::seal::Cipher;
use rand::SeedableRng;
use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdout, Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

const ATTACKER_OF: &str = "E2E_ATTACKER_OF";
const ATTACKER_HUB: &str = "E2E_ATTACKER_HUB";
const VICTIM_ID: &str = "E2E_VICTIM_ID";
/// Replays the attacker puts per second (paced, so the flood is the hub's load).
const FLOOD_PER_S: u64 = 2000;
/// A message seen: its key and bytes.
type Message = (String, Vec<u8>);
/// The victim's steps under the flood.
const STEPS: u64 = 400;

/// The attacking client, a process of its own.
struct Attacker {
    child: Child,
    out: BufReader<ChildStdout>,
}

impl Attacker {
    fn start(hub: &RemoteHub, victim_id: &str) -> (Attacker, String) {
        let mut child = Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "fair_shares::attacker_process", "--nocapture"])
            .env(ATTACKER_OF, &hub.endpoint)
            .env(ATTACKER_HUB, &hub.name)
            .env(VICTIM_ID, victim_id)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut out = BufReader::new(child.stdout.take().unwrap());
        let said = envhub_e2e::lines_until_ready(&mut out);
        (Attacker { child, out }, said)
    }

    /// Tells it to stop flooding; what it counted, and what its lent session said.
    fn stop_flood(&mut self) -> (String, String) {
        writeln!(self.child.stdin.as_mut().unwrap(), "stop").unwrap();
        let (mut counted, mut lent) = (String::new(), String::new());
        self.out.read_line(&mut counted).unwrap();
        self.out.read_line(&mut lent).unwrap();
        (counted, lent)
    }
}

impl Drop for Attacker {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// `name=<number>` in `line`.
fn count(line: &str, name: &str) -> f64 {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{name}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no `{name}=` in {line:?}"))
}

#[test]
fn a_lone_key_borrows_the_hub_and_a_flooding_or_vanished_client_starves_no_one() {
    // Two workers: each key's share is one.
    let a = RemoteHub::start("fair", &["--max-workers", "2"], &[]);
    let on_a = Placement::Hubs(vec![a.name.clone()]);
    let net = net_to(&[&a]);
    let victim_id = envhub_hub::Network::get(&net)
        .unwrap()
        .client_id()
        .to_string();
    let victim_hub = Hub::new(Registry::builtin()).with_network(net);
    let (mut attacker, said) = Attacker::start(&a, &victim_id);
    assert!(said.contains("ready"), "the attacker said {said:?}");
    assert!(
        said.contains("held 2 ") && said.contains("limit of 2"),
        "a key alone takes the whole hub, past its share of 1: {said:?}"
    );
    assert!(
        said.contains("forged open refused") && said.contains("not named by the identity"),
        "an open under the victim's token with another key: {said:?}"
    );
    let mut victim = victim_hub
        .make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &on_a)
        .expect("the victim's open succeeds: the session lent to the attacker closes for it");
    victim.reset(Some(0)).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    for _ in 0..STEPS {
        let actions = victim.sample_actions(&mut rng);
        victim
            .step(&actions)
            .expect("the victim's step under the flood");
    }
    let (counted, lent) = attacker.stop_flood();
    eprintln!("victim: reset and {STEPS} steps; attacker: {counted}; {lent}");
    assert!(
        lent.contains("lent past this client's share") && lent.contains("another client asked"),
        "the attacker's lent session was given back, and it is told why: {lent:?}"
    );
    let (replays, answers, secs) = (
        count(&counted, "replays"),
        count(&counted, "answers"),
        count(&counted, "secs"),
    );
    assert!(
        replays >= 100.0,
        "the attacker replayed {replays} requests: the attack did not happen"
    );
    // One answer per request of the victim (its reset and steps), and repeats of the last one
    // at most every 250 ms of the flood: not one per replay.
    let most = (STEPS + 1) as f64 + 4.0 * secs + 2.0;
    assert!(
        answers <= most,
        "the hub published {answers} answers for {} requests and {replays} replays in {secs} s",
        STEPS + 1
    );
    // The attacker vanishes (SIGKILL: no goodbye): its session ends with it.
    envhub_e2e::sigkill(attacker.child.id());
    envhub_e2e::eventually("the vanished attacker's worker ends", || {
        a.worker_count() == 1
    });
    let actions = victim.sample_actions(&mut rng);
    victim.step(&actions).unwrap();
    // Its share is another key's again (a client with its own identity).
    let third = Hub::new(Registry::builtin()).with_network(NetConfig {
        lease_ms: Some(1500),
        ..net_to(&[&a])
    });
    let mut other = third
        .make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &on_a)
        .expect("the share the attacker held is free again");
    other.reset(Some(1)).unwrap();
    other.close();
    victim.close();
}

/// The attacker of the test above; does nothing in a normal run.
#[test]
fn attacker_process() {
    let (Ok(endpoint), Ok(hub), Ok(victim_id)) = (
        std::env::var(ATTACKER_OF),
        std::env::var(ATTACKER_HUB),
        std::env::var(VICTIM_ID),
    ) else {
        return;
    };
    let net = NetConfig {
        connect: vec![endpoint],
        multicast: Some(false),
        known_hubs: Some(known_hubs()),
        ..NetConfig::default()
    };
    let on = Placement::Hubs(vec![hub.clone()]);
    let client = Hub::new(Registry::builtin()).with_network(net.clone());
    // As many sessions as its key may hold.
    let mut held = Vec::new();
    let refused = loop {
        match client.make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &on) {
            Ok(env) if held.len() < 8 => held.push(env),
            Ok(_) => break "never refused".to_string(),
            Err(e) => break e.to_string().replace('\n', " "),
        }
    };
    println!("held {} sessions; then: {refused}", held.len());
    // A Zenoh client: the hub routes the session's traffic to it.
    let mut config = net.zenoh_config(false).unwrap();
    config.insert_json5("mode", "\"client\"").unwrap();
    let zenoh = zenoh::open(config).wait().unwrap();
    // An open under the victim's token, signed with a key of its own.
    let request = serde_json::json!({
        "id": "gym-cartpole", "config": {"num_envs": 1}, "client": victim_id,
        "restart_on_crash": false, "step_timeout_ms": 10_000
    });
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_millis() as u64;
    let (hello, _pending) =
        client_hello(&Identity::generate().unwrap(), &hub, now, &Cipher::ALL).unwrap();
    let message = OpenMessage {
        request: serde_json::from_value(request).unwrap(),
        hello,
    };
    let answers: Vec<String> = zenoh
        .get(format!("envhub/hub/{hub}/open"))
        .payload(serde_json::to_string(&message).unwrap())
        .timeout(Duration::from_secs(30))
        .wait()
        .unwrap()
        .iter()
        .filter_map(|r| {
            r.result()
                .ok()
                .map(|s| s.payload().try_to_string().unwrap().to_string())
        })
        .collect();
    let forged = answers.join(" | ");
    if forged.contains("\"err\"") {
        println!("forged open refused: {forged}");
    } else {
        println!("forged open answered: {forged}");
    }
    // The flood: the latest request seen, put again and again; the answers counted.
    let latest: Arc<Mutex<Option<Message>>> = Arc::default();
    let _spy = {
        let latest = latest.clone();
        zenoh
            .declare_subscriber(format!("envhub/session/{hub}/*/req"))
            .callback(move |s| {
                *latest.lock().unwrap() = Some((
                    s.key_expr().as_str().to_string(),
                    s.payload().to_bytes().into_owned(),
                ));
            })
            .wait()
            .unwrap()
    };
    let answers = Arc::new(AtomicU64::new(0));
    let _answers = {
        let answers = answers.clone();
        zenoh
            .declare_subscriber(format!("envhub/session/{hub}/*/rep"))
            .callback(move |_| {
                answers.fetch_add(1, Ordering::Relaxed);
            })
            .wait()
            .unwrap()
    };
    let flooding = Arc::new(AtomicBool::new(true));
    let replays = Arc::new(AtomicU64::new(0));
    let start = Instant::now();
    let flood = {
        let (flooding, replays, latest, zenoh) = (
            flooding.clone(),
            replays.clone(),
            latest.clone(),
            zenoh.clone(),
        );
        std::thread::spawn(move || {
            while flooding.load(Ordering::Relaxed) {
                let copy = latest.lock().unwrap().clone();
                let Some((key, bytes)) = copy else {
                    std::thread::sleep(Duration::from_millis(1));
                    continue;
                };
                let _ = zenoh.put(key, bytes).wait();
                let n = replays.fetch_add(1, Ordering::Relaxed) + 1;
                let due = Duration::from_micros(n * 1_000_000 / FLOOD_PER_S);
                if let Some(wait) = due.checked_sub(start.elapsed()) {
                    std::thread::sleep(wait);
                }
            }
        })
    };
    println!("ready");
    let mut stdin = std::io::stdin().lock();
    let mut line = String::new();
    let _ = stdin.read_line(&mut line);
    flooding.store(false, Ordering::Relaxed);
    flood.join().unwrap();
    let secs = start.elapsed().as_secs_f64();
    // The last answers of the flood arrive within a moment; counted after it.
    std::thread::sleep(Duration::from_millis(300));
    println!(
        "replays={} answers={} secs={secs:.2}",
        replays.load(Ordering::Relaxed),
        answers.load(Ordering::Relaxed)
    );
    // Its newest session was lent past its share: closed for the victim, and it says so.
    let lent = match held.last_mut().map(|env| env.reset(Some(0))) {
        Some(Err(e)) => e.to_string().replace('\n', " "),
        Some(Ok(_)) => "the lent session still runs".to_string(),
        None => "no session".to_string(),
    };
    println!("lent session: {lent}");
    // Holds its sessions until it is killed (or its stdin closes).
    let _ = stdin.read_line(&mut line);
    drop(held);
}
