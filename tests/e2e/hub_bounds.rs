//! A live hub under a hostile peer on its network, measured: 100,000 client-token flaps,
//! oversized requests on a session's key and a subscriber that never reads its samples. The
//! hub's thread count and resident memory stay bounded (figures printed, for
//! `docs/security.md`) and another client's session keeps stepping, bit for bit as it would.

use envhub::{EnvConfig, Hub, Placement};
use envhub_e2e::remote::{RemoteHub, net_to};
use rand::SeedableRng;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};
use zenoh::Wait;

const FLAPS: usize = 100_000;

/// `Threads` and `VmRSS` (KiB) of process `pid`, from `/proc/<pid>/status`; `None` once it
/// is gone.
fn threads_and_rss(pid: u32) -> Option<(u64, u64)> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let field = |name: &str| {
        status
            .lines()
            .find(|l| l.starts_with(name))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    };
    Some((field("Threads:"), field("VmRSS:")))
}

/// A peer in a process of its own that subscribes to every session's key on the hub at
/// `endpoint` and never returns from its callback, until the test ends (it is killed then, or
/// exits when its stdin closes). A process of its own, as a real peer is: in the test's
/// process, its blocked callbacks would hold Zenoh's RX threads, which every session of a
/// process shares, and stall the victim's own session (seen in CI: a step unanswered for 60 s).
struct StalledPeer(std::process::Child);

impl StalledPeer {
    fn start(endpoint: &str) -> StalledPeer {
        let mut child = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", "hub_bounds::stalled_peer_process", "--nocapture"])
            .env("E2E_STALLED_PEER_OF", endpoint)
            .stdin(std::process::Stdio::piped())
            .stdout(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        let said = envhub_e2e::lines_until_ready(&mut std::io::BufReader::new(
            child.stdout.take().unwrap(),
        ));
        assert!(said.contains("ready"), "the stalled peer said {said:?}");
        StalledPeer(child)
    }
}

impl Drop for StalledPeer {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// The stalled peer of the test above; does nothing in a normal run.
#[test]
fn stalled_peer_process() {
    let Ok(endpoint) = std::env::var("E2E_STALLED_PEER_OF") else {
        return;
    };
    let net = envhub::NetConfig {
        connect: vec![endpoint],
        multicast: Some(false),
        ..envhub::NetConfig::default()
    };
    let peer = zenoh::open(net.zenoh_config(false).unwrap())
        .wait()
        .unwrap();
    let _stalled = peer
        .declare_subscriber("envhub/session/**")
        .callback(|_| {
            loop {
                std::thread::sleep(Duration::from_secs(1));
            }
        })
        .wait()
        .unwrap();
    println!("ready");
    // Until the test closes its end (or it is killed).
    let _ = std::io::Read::read_to_end(&mut std::io::stdin(), &mut Vec::new());
    std::process::exit(0);
}

fn rollout(env: &mut envhub::VecEnv, steps: usize) -> Vec<Vec<u8>> {
    envhub_e2e::rollout_bytes(env, 3, 5, steps)
}

#[test]
fn flaps_oversized_requests_and_a_stalled_subscriber_leave_a_live_hub_bounded() {
    let a = RemoteHub::start("bounds", &[], &[]);
    let on_a = Placement::Hubs(vec![a.name.clone()]);
    let hub = Hub::new(envhub::Registry::builtin()).with_network(net_to(&[&a]));
    let mut quiet = hub
        .make_vec_on("gym-cartpole", 2, &EnvConfig::default(), &on_a)
        .unwrap();
    let expected = rollout(&mut quiet, 200);
    quiet.close();
    let mut victim = hub
        .make_vec_on("gym-cartpole", 2, &EnvConfig::default(), &on_a)
        .unwrap();
    victim.reset(Some(0)).unwrap();
    std::thread::sleep(Duration::from_millis(500));
    let before = threads_and_rss(a.pid()).expect("the hub runs");

    // The attacker: peers on the hub's network. One (`StalledPeer`, below) subscribes to every
    // session's answers and never returns from its callback (it never reads another sample);
    // the other flaps client tokens and sends oversized requests.
    let attacker_endpoint = format!("tcp/127.0.0.1:{}", envhub_e2e::remote::free_port());
    let attacker = {
        let mut net = net_to(&[&a]);
        net.listen = vec![attacker_endpoint.clone()];
        zenoh::open(net.zenoh_config(false).unwrap())
            .wait()
            .unwrap()
    };
    // A witness linked to the attacker alone counts the flaps' deletions the attacker sent
    // (it sends each declaration to every link: the hub gets the same ones).
    let witness = {
        let mut net = net_to(&[]);
        net.connect = vec![attacker_endpoint];
        zenoh::open(net.zenoh_config(false).unwrap())
            .wait()
            .unwrap()
    };
    let carried = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let _witness = {
        let carried = carried.clone();
        witness
            .liveliness()
            .declare_subscriber("envhub/client/*")
            .callback(move |sample| {
                if sample.kind() == zenoh::sample::SampleKind::Delete {
                    carried.fetch_add(1, Ordering::Relaxed);
                }
            })
            .wait()
            .unwrap()
    };
    // The flaps count only once the witness's subscription has reached the attacker (a fixed
    // sleep was too short on a loaded machine: the witness then saw 858 of 100,000): a probe
    // token flaps until the witness sees its deletion, within a bounded time.
    let ready_by = Instant::now() + Duration::from_secs(20);
    while carried.load(Ordering::Relaxed) == 0 {
        assert!(
            Instant::now() < ready_by,
            "the witness saw no token of the attacker's within 20 s"
        );
        let probe = attacker
            .liveliness()
            .declare_token("envhub/client/probe")
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(100));
        drop(probe);
        std::thread::sleep(Duration::from_millis(100));
    }
    carried.store(0, Ordering::Relaxed);
    let stalled = StalledPeer::start(&a.endpoint);
    let peak = Arc::new(std::sync::Mutex::new(before));
    let sampling = Arc::new(AtomicBool::new(true));
    let sampler = {
        let (peak, sampling, pid) = (peak.clone(), sampling.clone(), a.pid());
        std::thread::spawn(move || {
            while sampling.load(Ordering::Relaxed) {
                let Some((t, r)) = threads_and_rss(pid) else {
                    break;
                };
                let mut p = peak.lock().unwrap();
                *p = (p.0.max(t), p.1.max(r));
                drop(p);
                std::thread::sleep(Duration::from_millis(20));
            }
        })
    };
    // The victim steps throughout, in its own thread.
    let stepping = Arc::new(AtomicBool::new(true));
    let steps = {
        let stepping = stepping.clone();
        std::thread::spawn(move || {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
            let mut n = 0u64;
            while stepping.load(Ordering::Relaxed) {
                let actions = victim.sample_actions(&mut rng);
                victim.step(&actions).expect("the victim's step");
                n += 1;
            }
            (victim, n)
        })
    };
    let start = Instant::now();
    for i in 0..FLAPS {
        // A thousand distinct keys, each flapping a hundred times.
        let token = attacker
            .liveliness()
            .declare_token(format!("envhub/client/flap-{}", i % 1000))
            .wait()
            .unwrap();
        drop(token);
    }
    let flap_seconds = start.elapsed().as_secs_f64();
    let deadline = Instant::now() + Duration::from_secs(30);
    while carried.load(Ordering::Relaxed) < FLAPS && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(100));
    }
    let carried = carried.load(Ordering::Relaxed);
    let oversized = vec![0u8; 80 << 20];
    for k in 0..4 {
        attacker
            .put(
                format!("envhub/session/{}/x{k}/req", a.name),
                oversized.clone(),
            )
            .wait()
            .unwrap();
    }
    std::thread::sleep(Duration::from_secs(3));
    stepping.store(false, Ordering::Relaxed);
    let (mut victim, victim_steps) = steps.join().unwrap();
    let after = threads_and_rss(a.pid()).expect("the hub runs");
    sampling.store(false, Ordering::Relaxed);
    sampler.join().unwrap();
    let peak = *peak.lock().unwrap();
    drop(stalled);
    // The victim's session is still right: a rollout from a reset is the quiet one's.
    assert_eq!(rollout(&mut victim, 200), expected);
    victim.close();
    eprintln!(
        "hub under attack: {FLAPS} token flaps in {flap_seconds:.1} s ({carried} deletions \
         carried), 4 requests of 80 MiB, a stalled subscriber; threads {} -> peak {} -> {}; RSS {} -> peak {} -> {} MiB; the \
         victim stepped {victim_steps} times meanwhile",
        before.0,
        peak.0,
        after.0,
        before.1 / 1024,
        peak.1 / 1024,
        after.1 / 1024
    );
    assert!(
        victim_steps > 100,
        "the victim stepped {victim_steps} times"
    );
    assert!(
        carried >= FLAPS * 9 / 10,
        "only {carried} of {FLAPS} flaps left the attacker: the attack did not happen"
    );
    assert!(
        peak.0 <= before.0 + 8,
        "the hub's threads grew from {} to {}",
        before.0,
        peak.0
    );
    assert!(
        peak.1 <= before.1 + 256 * 1024,
        "the hub's memory grew from {} to {} KiB",
        before.1,
        peak.1
    );
}
