//! A peer that sees a session's traffic (a Zenoh client linked to the hub: the hub routes the
//! session's requests to it) puts the victim's latest sealed request again and again, with no
//! key needed: each copy is authentic. The hub drops copies by their sequence number before
//! any work (a repeat of the answered request is answered at most every 250 ms), so the
//! victim keeps at least half its step rate under the flood (a ratio in one run: blocks of
//! steps with the flood on and off in turn, the median of the blocks under the flood against
//! the median of the others, so the machine's own drift falls on both). On two cores the
//! flooder's and the hub's own CPU for 2,000 puts a second cost the victim 7-20 %; a hub that
//! did each replay's work took it from ~2,000 to 1-7 steps/s. Another client holds as many
//! sessions of its own meanwhile as its identity may.

use envhub_e2e::remote::{RemoteHub, net_to};
use envhub_hub::{EnvConfig, Hub, Placement, Registry};
use rand::SeedableRng;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// A message seen: its key and bytes.
type Message = (String, Vec<u8>);

/// Steps per measured block, and blocks with the flood on (as many with it off).
const BLOCK: usize = 300;
const BLOCKS: usize = 7;
/// Replays the attacker puts per second while it floods.
const FLOOD_PER_S: u64 = 2000;

/// Steps/s of one block of `BLOCK` steps.
fn block_rate(env: &mut envhub_hub::VecEnv, rng: &mut rand_chacha::ChaCha8Rng) -> f64 {
    let t = Instant::now();
    for _ in 0..BLOCK {
        let actions = env.sample_actions(rng);
        env.step(&actions).expect("the victim's step");
    }
    BLOCK as f64 / t.elapsed().as_secs_f64()
}

fn median(mut rates: Vec<f64>) -> f64 {
    rates.sort_by(f64::total_cmp);
    rates[rates.len() / 2]
}

#[test]
fn a_replay_flood_and_a_squatting_peer_leave_another_client_at_least_half_its_rate() {
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
    let running = Arc::new(AtomicBool::new(true));
    let flooding = Arc::new(AtomicBool::new(false));
    let replayed = Arc::new(AtomicU64::new(0));
    let flood = {
        let (running, flooding, replayed, latest, flooder) = (
            running.clone(),
            flooding.clone(),
            replayed.clone(),
            latest.clone(),
            flooder.clone(),
        );
        std::thread::spawn(move || {
            // Paced from the start of each stretch of flooding, so the flood is the hub's
            // load and not the test machine's.
            let mut stretch: Option<(Instant, u64)> = None;
            while running.load(Ordering::Relaxed) {
                let copy = latest.lock().unwrap().clone();
                match copy {
                    Some((key, bytes)) if flooding.load(Ordering::Relaxed) => {
                        let (start, sent) = *stretch.get_or_insert((Instant::now(), 0));
                        let _ = flooder.put(key, bytes).wait();
                        replayed.fetch_add(1, Ordering::Relaxed);
                        stretch = Some((start, sent + 1));
                        let due = Duration::from_micros((sent + 1) * 1_000_000 / FLOOD_PER_S);
                        if let Some(wait) = due.checked_sub(start.elapsed()) {
                            std::thread::sleep(wait);
                        }
                    }
                    _ => {
                        stretch = None;
                        std::thread::sleep(Duration::from_millis(1));
                    }
                }
            }
        })
    };
    // The spy sees the victim's requests from here on in both kinds of block; only the
    // replays differ. A first block warms the path.
    block_rate(&mut victim, &mut rng);
    let (mut quiet, mut flooded) = (Vec::new(), Vec::new());
    for k in 0..2 * BLOCKS {
        let on = k % 2 == 1;
        flooding.store(on, Ordering::Relaxed);
        let rate = block_rate(&mut victim, &mut rng);
        if on { &mut flooded } else { &mut quiet }.push(rate);
    }
    flooding.store(false, Ordering::Relaxed);
    running.store(false, Ordering::Relaxed);
    flood.join().unwrap();
    let replays = replayed.load(Ordering::Relaxed);
    victim.close();
    drop(squatted);
    let (baseline, during) = (median(quiet), median(flooded));
    eprintln!(
        "victim steps/s: {baseline:.0} without the flood, {during:.0} under it ({replays} replays \
         at {FLOOD_PER_S}/s in {BLOCKS} blocks) with a squatter holding sessions; ratio {:.2}",
        during / baseline
    );
    assert!(
        replays > 100,
        "the flooder saw no request to replay ({replays} replays): the attack did not happen"
    );
    assert!(
        during >= 0.5 * baseline,
        "the victim's rate fell from {baseline:.0} to {during:.0} steps/s under the flood"
    );
}
