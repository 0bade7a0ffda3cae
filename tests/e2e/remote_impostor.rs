//! An impostor: a Zenoh peer the client reaches that declares a queryable under a live hub's
//! name (`envhub/hub/<name>/open`) and answers every open at once, before the real hub can,
//! then again a few seconds later (the last answer is what a client that waits for the
//! query's end would keep). The client takes answers only from the Zenoh id the hub's
//! identity token names: its session is the real hub's, and steps bit for bit as a local one.

use crate::remote_hubs::assert_same_rollout;
use envhub_e2e::TestHub;
use envhub_e2e::remote::{RemoteHub, client, free_port};
use envhub_hub::{EnvConfig, NetConfig, Placement};
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// What the impostor saw: opens it answered, requests sent to its made-up session.
#[derive(Default)]
struct Caught {
    answered: AtomicUsize,
    requests: AtomicUsize,
}

/// The impostor's open answer: a well-formed session of its own on CartPole.
fn lure(observation_space: &serde_json::Value) -> String {
    // A made-up half of a key exchange (the client never gets as far as checking it).
    let hello = serde_json::json!({
        "exchange": "cd".repeat(32), "identity": "ef".repeat(32), "proof": "ab".repeat(64)
    });
    envhub_e2e::intruder::cartpole_open_reply("rogue-1", observation_space.clone(), hello)
        .to_string()
}

#[test]
fn an_impostor_answering_a_live_hub_s_opens_first_does_not_get_the_session() {
    let hub_a = RemoteHub::start("real", &[], &[]);
    let local = TestHub::new("remote_impostor");
    let config = EnvConfig::default();
    let mut here = local.hub.make_vec("gym-cartpole", 4, &config).unwrap();
    let obs_space = serde_json::to_value(here.observation_space()).unwrap();

    let rogue_endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let rogue = zenoh::open(
        NetConfig {
            listen: vec![rogue_endpoint.clone()],
            multicast: Some(false),
            ..NetConfig::default()
        }
        .zenoh_config(false)
        .unwrap(),
    )
    .wait()
    .unwrap();
    let caught = Arc::new(Caught::default());
    let _open = {
        let (caught, answer) = (caught.clone(), lure(&obs_space));
        rogue
            .declare_queryable(format!("envhub/hub/{}/open", hub_a.name))
            .callback(move |query| {
                if query
                    .reply(query.key_expr().clone(), answer.clone())
                    .wait()
                    .is_ok()
                {
                    caught.answered.fetch_add(1, Ordering::Relaxed);
                }
                // Again once the real hub has answered: the query ends with this one.
                let answer = answer.clone();
                std::thread::spawn(move || {
                    std::thread::sleep(Duration::from_secs(3));
                    let _ = query.reply(query.key_expr().clone(), answer).wait();
                });
            })
            .wait()
            .unwrap()
    };
    let _requests = {
        let caught = caught.clone();
        rogue
            .declare_subscriber(format!("envhub/session/{}/rogue-1/req", hub_a.name))
            .callback(move |_| {
                caught.requests.fetch_add(1, Ordering::Relaxed);
            })
            .wait()
            .unwrap()
    };
    // A name token too, as an impostor would hold to look live (harmless: a name).
    let _token = rogue
        .liveliness()
        .declare_token(envhub_protocol::keys::hub_token(&hub_a.name))
        .wait()
        .unwrap();

    // The client reaches both the real hub and the impostor.
    let hub = client("impostor", &[&hub_a]).with_network(NetConfig {
        connect: vec![hub_a.endpoint.clone(), rogue_endpoint],
        multicast: Some(false),
        ..NetConfig::default()
    });
    let on = Placement::Hubs(vec![hub_a.name.clone()]);
    let mut remote = hub.make_vec_on("gym-cartpole", 4, &config, &on).unwrap();
    // The impostor's queryable may not have reached the client before that open: open again
    // (each open is one the impostor is asked) until it has answered one.
    let asked = Instant::now();
    while caught.answered.load(Ordering::Relaxed) == 0 {
        assert!(
            asked.elapsed() < Duration::from_secs(10),
            "the impostor was never asked to open (the test proves nothing)"
        );
        remote.close();
        std::thread::sleep(Duration::from_millis(200));
        remote = hub.make_vec_on("gym-cartpole", 4, &config, &on).unwrap();
    }
    assert_eq!(
        remote.placement(),
        vec![(hub_a.name.clone(), 0..4)],
        "the session is placed on the real hub"
    );
    assert_same_rollout(&mut remote, &mut here, 300);
    remote.close();
    here.close();
    assert_eq!(
        caught.requests.load(Ordering::Relaxed),
        0,
        "the client sent requests to the impostor's session"
    );
}
