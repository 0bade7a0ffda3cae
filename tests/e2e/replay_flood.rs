//! A peer that sees a session's traffic (a Zenoh client linked to the hub: the hub routes the
//! session's requests to it) puts the victim's latest sealed request again and again, with no
//! key needed: each copy is authentic. The hub drops copies by their sequence number before
//! any work (a repeat of the answered request is answered at most every 250 ms), so the
//! victim's step rate under the flood stays within 20 % of its rate without it (a ratio in
//! one run: medians of blocks before, during and after the flood, the flood's against the
//! lower of the others). Another client holds as many sessions of its own meanwhile as its
//! identity may.

use envhub_e2e::remote::{RemoteHub, net_to};
use envhub_hub::{EnvConfig, Hub, Placement, Registry};
use rand::SeedableRng;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// A message seen: its key and bytes.
type Message = (String, Vec<u8>);

/// Steps per measured block, and blocks per phase.
const BLOCK: usize = 300;
const BLOCKS: usize = 5;
/// Replays the attacker puts per second.
const FLOOD_PER_S: u64 = 2000;

/// Steps/s of `BLOCKS` blocks of `BLOCK` steps; their median.
fn rate(env: &mut envhub_hub::VecEnv, rng: &mut rand_chacha::ChaCha8Rng) -> f64 {
    let mut rates: Vec<f64> = (0..BLOCKS)
        .map(|_| {
            let t = Instant::now();
            for _ in 0..BLOCK {
                let actions = env.sample_actions(rng);
                env.step(&actions).expect("the victim's step");
            }
            BLOCK as f64 / t.elapsed().as_secs_f64()
        })
        .collect();
    rates.sort_by(f64::total_cmp);
    rates[BLOCKS / 2]
}

#[test]
fn a_replay_flood_and_a_squatting_peer_leave_another_client_s_rate_within_20_percent() {
    let a = RemoteHub::start("flooded", &[], &[]);
    let on_a = Placement::Hubs(vec![a.name.clone()]);
    let victim_hub = Hub::new(Registry::builtin()).with_network(net_to(&[&a]));
    let mut victim = victim_hub
        .make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &on_a)
        .unwrap();
    victim.reset(Some(0)).unwrap();
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    // The squatter: another client (its own network, so its own identity) holding sessions.
    let squatter_net = envhub_hub::NetConfig {
        lease_ms: Some(1500),
        ..net_to(&[&a])
    };
    let squatter = Hub::new(Registry::builtin()).with_network(squatter_net);
    let mut squatted = Vec::new();
    for _ in 0..20 {
        match squatter.make_vec_on("gym-cartpole", 1, &EnvConfig::default(), &on_a) {
            Ok(env) => squatted.push(env),
            Err(_) => break,
        }
    }
    let before = rate(&mut victim, &mut rng);
    // The flooder: a Zenoh client linked to the hub, re-putting the latest request it saw.
    let mut config = net_to(&[&a]).zenoh_config(false).unwrap();
    config.insert_json5("mode", "\"client\"").unwrap();
    let flooder = zenoh::open(config).wait().unwrap();
    let latest: Arc<Mutex<Option<Message>>> = Arc::default();
    let _spy = {
        let latest = latest.clone();
        flooder
            .declare_subscriber(format!("envhub/session/{}/*/req", a.name))
            .callback(move |s| {
                *latest.lock().unwrap() = Some((
                    s.key_expr().as_str().to_string(),
                    s.payload().to_bytes().into_owned(),
                ));
            })
            .wait()
            .unwrap()
    };
    let flooding = Arc::new(AtomicBool::new(true));
    let replayed = Arc::new(AtomicU64::new(0));
    let flood = {
        let (flooding, replayed, latest, flooder) = (
            flooding.clone(),
            replayed.clone(),
            latest.clone(),
            flooder.clone(),
        );
        std::thread::spawn(move || {
            let start = Instant::now();
            while flooding.load(Ordering::Relaxed) {
                let copy = latest.lock().unwrap().clone();
                if let Some((key, bytes)) = copy {
                    let _ = flooder.put(key, bytes).wait();
                    let n = replayed.fetch_add(1, Ordering::Relaxed) + 1;
                    // Paced, so the flood is the hub's load and not the test machine's.
                    let due = Duration::from_micros(n * 1_000_000 / FLOOD_PER_S);
                    if let Some(wait) = due.checked_sub(start.elapsed()) {
                        std::thread::sleep(wait);
                    }
                } else {
                    std::thread::sleep(Duration::from_millis(1));
                }
            }
        })
    };
    // The flood starts with the victim's next request.
    let replayed_before = replayed.load(Ordering::Relaxed);
    let during = rate(&mut victim, &mut rng);
    flooding.store(false, Ordering::Relaxed);
    flood.join().unwrap();
    let replays = replayed.load(Ordering::Relaxed) - replayed_before;
    let after = rate(&mut victim, &mut rng);
    victim.close();
    drop(squatted);
    // The machine's own drift over the run (other load on it) shows in `before` against
    // `after`: the flood is judged against the lower of the two.
    let baseline = before.min(after);
    eprintln!(
        "victim steps/s: {before:.0} before, {during:.0} under {replays} replays ({FLOOD_PER_S}/s) \
         and a squatter holding sessions, {after:.0} after; ratio {:.2}",
        during / baseline
    );
    assert!(
        replays > 100,
        "the flooder saw no request to replay ({replays} replays): the attack did not happen"
    );
    assert!(
        during >= 0.8 * baseline,
        "the victim's rate fell from {baseline:.0} to {during:.0} steps/s under the flood"
    );
}
