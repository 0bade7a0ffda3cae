//! EnvPool's asynchronous contract over remote hubs (two hubs on loopback): every env's
//! trajectory under `async_reset`/`send`/`recv` equals the lock-step run's, bit for bit,
//! whatever order the envs come back in — with one session per hub, and with each hub's
//! slice opened as two lanes that take requests of their own (`remote_lanes`).

use crate::env_pool::{assert_same_per_env, env_pool, lock_step};
use envhub_e2e::TestHub;
use envhub_e2e::remote::{RemoteHub, client, net_to};
use envhub_hub::{EnvConfig, Hub, NetConfig, Placement, RESENT, SessionOptions};
use std::sync::atomic::Ordering;

fn with_lanes(hub: Hub, lanes: usize) -> Hub {
    let options = SessionOptions {
        remote_lanes: lanes,
        ..hub.options().clone()
    };
    hub.with_options(options)
}

#[test]
fn remote_trajectories_per_env_under_send_recv_equal_the_lock_step_run() {
    let a = RemoteHub::start("poola", &[], &[]);
    let b = RemoteHub::start("poolb", &[], &[]);
    let on_both = Placement::Hubs(vec![a.name.clone(), b.name.clone()]);
    // Two workers per machine: with two lanes, each hub runs two sessions of one worker.
    let config = EnvConfig {
        workers: Some(2),
        ..EnvConfig::default()
    };
    let (n, steps, seed) = (8, 150, 7);
    let local = TestHub::new("pool_remote_local");
    let mut here = local.hub.make_vec("gym-cartpole", n, &config).unwrap();
    let reference = lock_step(&mut here, seed, steps);
    here.close();
    for lanes in [1, 2] {
        let hub = with_lanes(client(&format!("pool{lanes}"), &[&a, &b]), lanes);
        let mut remote = hub
            .make_vec_on("gym-cartpole", n, &config, &on_both)
            .unwrap();
        assert_eq!(
            remote.placement(),
            vec![(a.name.clone(), 0..4), (b.name.clone(), 4..8)],
            "lanes of one hub are one range"
        );
        assert_eq!(remote.num_workers(), 2 * lanes, "links: lanes per hub");
        let sync = lock_step(&mut remote, seed, steps);
        assert_same_per_env("remote lock step", &reference, &sync, steps);
        remote.close();
        // M = 3 is no multiple of the envs per link (4 with one lane, 2 with two): envs of
        // one answer are handed out over two `recv`s, and sends to a busy link wait.
        let mut remote = hub
            .make_vec_on("gym-cartpole", n, &config, &on_both)
            .unwrap();
        let pool = env_pool(&mut remote, 3, seed, steps);
        assert_same_per_env(
            &format!("remote EnvPool, {lanes} lanes"),
            &reference,
            &pool,
            steps,
        );
    }
}

/// A client whose Zenoh drops answers of `hub` that come within `1 / freq` s of the last one
/// it let in (Zenoh's own downsampling on the client's ingress): a link that loses messages,
/// as one that dropped and came back under load does.
fn lossy_client(name: &str, hub: &RemoteHub, freq: f64) -> (Hub, TempFile) {
    let path = std::env::temp_dir().join(format!("e2e-{name}-{}.json5", std::process::id()));
    let config = format!(
        r#"{{
  mode: "peer",
  downsampling: [{{
    flows: ["ingress"],
    messages: ["put"],
    rules: [{{ key_expr: "envhub/session/{}/*/rep", freq: {freq} }}],
  }}],
}}"#,
        hub.name
    );
    std::fs::write(&path, config).unwrap();
    let net = NetConfig {
        config: Some(path.clone()),
        ..net_to(&[hub])
    };
    let hub = client(name, &[hub]).with_network(net);
    (hub, TempFile(path))
}

/// A file removed when dropped.
struct TempFile(std::path::PathBuf);

impl Drop for TempFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// The EnvPool mode over a link that loses answers: a request whose answer does not come is
/// sent again (the hub answers it from its last answer, without stepping twice), as in lock
/// step, and every env's trajectory still equals the lock-step run's. Waiting instead would
/// fail the session with "did not answer within the step timeout" at the first lost answer.
#[test]
fn remote_send_recv_over_a_link_that_loses_answers_sends_again_and_loses_no_step() {
    let a = RemoteHub::start("lossy", &[], &[]);
    let config = EnvConfig {
        workers: Some(2),
        ..EnvConfig::default()
    };
    let (n, steps, seed) = (2, 5, 11);
    let local = TestHub::new("pool_lossy_local");
    let mut here = local.hub.make_vec("gym-cartpole", n, &config).unwrap();
    let reference = lock_step(&mut here, seed, steps);
    here.close();
    // At most 4 answers a second pass: an answer that follows the last one closer is lost.
    // One lane: two links would share that rate, and one's resends could keep losing to
    // the other's answers.
    let (hub, _config_file) = lossy_client("pool_lossy", &a, 4.0);
    let on_a = Placement::Hubs(vec![a.name.clone()]);
    let mut remote = hub.make_vec_on("gym-cartpole", n, &config, &on_a).unwrap();
    let resent_before = RESENT.load(Ordering::Relaxed);
    let pool = env_pool(&mut remote, 1, seed, steps);
    let resent = RESENT.load(Ordering::Relaxed) - resent_before;
    assert_same_per_env("EnvPool over a lossy link", &reference, &pool, steps);
    assert!(
        resent > 0,
        "no request was sent again: the link lost no answer, so this test tested nothing"
    );
    eprintln!("{resent} requests sent again over the lossy link");
}
