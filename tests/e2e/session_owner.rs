//! Another peer on the same Zenoh network tries to end a session it did not open by forging
//! its owner's liveliness token (declaring the owner's key and dropping it): the hub ends a
//! client's sessions only when no token of that key is left, so the session goes on. (Zenoh
//! 1.10 itself reports no deletion while another token of the key lives, in this topology;
//! the hub's own check keeps it so where routers aggregate differently.)

use envhub_e2e::remote::{RemoteHub, free_port, net_to};
use envhub_hub::EnvConfig;
use std::time::{Duration, Instant};
use zenoh::Wait;

#[test]
fn a_forged_client_token_does_not_end_another_client_s_session() {
    let hub_proc = RemoteHub::start("own", &[], &[]);
    // The attacker: a peer both the hub and the client are linked to.
    let spy_endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut spy_net = net_to(&[&hub_proc]);
    spy_net.listen = vec![spy_endpoint.clone()];
    let spy = zenoh::open(spy_net.zenoh_config(false).unwrap())
        .wait()
        .unwrap();
    let mut net = net_to(&[&hub_proc]);
    net.connect.push(spy_endpoint);
    let hub = envhub_hub::Hub::new(envhub_hub::Registry::builtin())
        .with_options(envhub_hub::SessionOptions {
            namespace: format!("e2e_owner_{}_", std::process::id()),
            step_timeout: Duration::from_secs(10),
            start_timeout: Duration::from_secs(30),
            ..envhub_hub::SessionOptions::default()
        })
        .with_network(net);
    let placement: envhub_hub::Placement = "own".parse().unwrap();
    let start = Instant::now();
    let mut env = loop {
        match hub.make_vec_on("gym-cartpole", 2, &EnvConfig::default(), &placement) {
            Ok(env) => break env,
            Err(e) if start.elapsed() < Duration::from_secs(10) => {
                eprintln!("not yet: {e}");
                std::thread::sleep(Duration::from_millis(100));
            }
            Err(e) => panic!("{e}"),
        }
    };
    env.reset(Some(3)).unwrap();
    env.step(&[0u8; 16]).unwrap();

    // The owner's token, as any peer sees it; declared by the spy, then dropped.
    let tokens: Vec<String> = spy
        .liveliness()
        .get("envhub/client/*")
        .timeout(Duration::from_secs(1))
        .wait()
        .unwrap()
        .iter()
        .filter_map(|r| r.result().ok().map(|s| s.key_expr().as_str().to_string()))
        .collect();
    assert!(!tokens.is_empty(), "the spy sees no client token");
    for key in &tokens {
        let forged = spy.liveliness().declare_token(key.clone()).wait().unwrap();
        std::thread::sleep(Duration::from_millis(100));
        drop(forged);
    }
    // A deletion that reached the hub used to end the owner's sessions within ~50 ms.
    std::thread::sleep(Duration::from_millis(1000));
    for _ in 0..20 {
        env.step(&[0u8; 16])
            .unwrap_or_else(|e| panic!("the owner's session was ended by a forged token: {e}"));
    }
    assert!(
        hub_proc.worker_count() > 0,
        "the session's workers still run"
    );
}
