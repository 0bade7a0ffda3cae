//! EnvPool's asynchronous contract over remote hubs (two hubs on loopback): every env's
//! trajectory under `async_reset`/`send`/`recv` equals the lock-step run's, bit for bit,
//! whatever order the envs come back in — with one session per hub, and with each hub's
//! slice opened as two lanes that take requests of their own (`remote_lanes`).

use crate::env_pool::{assert_same_per_env, env_pool, lock_step};
use envhub_e2e::TestHub;
use envhub_e2e::remote::{RemoteHub, client};
use envhub_hub::{EnvConfig, Hub, Placement, SessionOptions};

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
