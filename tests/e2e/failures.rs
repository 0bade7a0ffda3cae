//! Workers that die, hang or fail: the client gets an error, never a hang, and the hub and
//! other sessions keep working. A death is noticed by the hub's watch on the process, a hang
//! by the step timeout; the tests tell them apart by what the error says, not by a clock.

use envhub_e2e::{TestHub, eventually, kill_worker_expect_died, shm_files, sigkill};
use envhub_hub::{EnvConfig, HubError};
use std::time::{Duration, Instant};

fn null_config(extra: &[(&str, u64)], workers: usize) -> EnvConfig {
    let mut config = EnvConfig {
        workers: Some(workers),
        ..EnvConfig::default()
    };
    for (k, v) in extra {
        config.extra.insert(k.to_string(), (*v).into());
    }
    config
}

#[test]
fn kill_9_mid_rollout_is_worker_died_and_hub_lives_on() {
    let t = TestHub::new("kill9");
    let mut env = t
        .hub
        .make_vec(
            "gym-cartpole",
            4,
            &EnvConfig {
                workers: Some(2),
                ..EnvConfig::default()
            },
        )
        .unwrap();
    // A second session that must not notice.
    let mut other = t
        .hub
        .make_vec("gym-pendulum", 2, &EnvConfig::default())
        .unwrap();
    other.reset(Some(0)).unwrap();
    env.reset(Some(0)).unwrap();
    let actions = vec![0u8; 4 * 8];
    for _ in 0..50 {
        env.step(&actions).unwrap();
    }
    let victim = env.worker_pids()[1];
    let (err, why) = kill_worker_expect_died(1, victim, || env.step(&actions).map(drop));
    assert!(why.contains("signal 9") || why.contains("SIGKILL"), "{why}");
    assert!(err.to_string().contains("hint:"));
    // The session is closed for good; the other one and new ones work.
    assert!(matches!(env.step(&actions), Err(HubError::Closed { .. })));
    let action = vec![0u8; 2 * 4];
    other.step(&action).unwrap();
    let mut fresh = t
        .hub
        .make_vec("gym-cartpole", 2, &EnvConfig::default())
        .unwrap();
    fresh.reset(Some(1)).unwrap();
    fresh.step(&[0u8; 16]).unwrap();
}

#[test]
fn hung_worker_is_killed_after_the_step_timeout() {
    let timeout = Duration::from_millis(300);
    let t = TestHub::with("hang", |o| o.step_timeout = timeout);
    // A step that would sleep ten minutes: only the timeout can end it within the test.
    let mut env = t
        .hub
        .make_vec_direct("null", "Null-v0", &null_config(&[("sleep_ms", 600_000)], 1))
        .unwrap();
    env.reset(None).unwrap();
    let pid = env.worker_pids()[0];
    let start = Instant::now();
    let err = env.step(&[0u8; 8]).unwrap_err();
    let took = start.elapsed();
    // Not before the timeout; after it, however late a loaded machine lets the hub look.
    assert!(took >= timeout, "{took:?}");
    assert!(
        matches!(&err, HubError::WorkerDied { why, .. }
            if why.contains("did not answer within 300ms (step timeout) and was killed")),
        "{err}"
    );
    assert!(
        !std::path::Path::new(&format!("/proc/{pid}")).exists() || is_zombie_free(pid),
        "the hung worker was killed"
    );
}

fn is_zombie_free(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).map_or(true, |s| s.contains(") Z"))
}

#[test]
fn restart_on_crash_truncates_the_affected_envs() {
    let t = TestHub::with("restart", |o| o.restart_on_crash = true);
    let mut env = t
        .hub
        .make_vec(
            "gym-cartpole",
            4,
            &EnvConfig {
                workers: Some(2),
                ..EnvConfig::default()
            },
        )
        .unwrap();
    env.reset(Some(0)).unwrap();
    let actions = vec![0u8; 4 * 8];
    env.step(&actions).unwrap();
    let old = env.worker_pids();
    sigkill(old[0]);
    // The next step notices, restarts worker 0 and reports its envs truncated.
    let b = env.step(&actions).unwrap();
    assert_eq!(b.truncated[..2], [true, true]);
    assert_eq!(b.info(0)["worker_restarted"], true);
    assert_eq!(b.info(0)["worker_restarts"], 1);
    assert!(!b.info(2).get("worker_restarted").is_some_and(|v| v == true));
    let new = env.worker_pids();
    assert_ne!(new[0], old[0]);
    assert_eq!(new[1], old[1]);
    for _ in 0..20 {
        let b = env.step(&actions).unwrap();
        assert!(!b.has_info());
    }
}

#[test]
fn crash_inside_the_simulator_is_an_error_not_a_hang() {
    let t = TestHub::new("abort");
    let mut env = t
        .hub
        .make_vec_direct("null", "Null-v0", &null_config(&[("exit_after", 3)], 1))
        .unwrap();
    env.reset(None).unwrap();
    env.step(&[0u8; 8]).unwrap();
    env.step(&[0u8; 8]).unwrap();
    // The abort is noticed as the process's exit (its status), not at the step timeout.
    let err = env.step(&[0u8; 8]).unwrap_err();
    assert!(
        matches!(&err, HubError::WorkerDied { why, .. }
            if why.starts_with("died (") && why.contains("SIGABRT")),
        "{err}"
    );
}

#[test]
fn env_errors_reach_the_client_and_the_worker_survives() {
    let t = TestHub::new("enverror");
    let mut env = t
        .hub
        .make_vec_direct("null", "Null-v0", &null_config(&[("error_after", 2)], 1))
        .unwrap();
    env.reset(None).unwrap();
    env.step(&[0u8; 8]).unwrap();
    let err = env.step(&[0u8; 8]).unwrap_err();
    assert!(
        matches!(&err, HubError::EnvFailed { envs, .. } if envs == &[0]),
        "{err}"
    );
    assert!(
        err.to_string().contains("failed on purpose at step 2"),
        "{err}"
    );
    // Its state is unknown: it must be reset before it steps again, and then it does.
    let refused = env.step(&[0u8; 8]).unwrap_err().to_string();
    assert!(refused.contains("must be reset first"), "{refused}");
    env.reset(None).unwrap();
    env.step(&[0u8; 8]).unwrap();
}

#[test]
fn dead_clients_leave_nothing_behind() {
    let t = TestHub::new("stale");
    let ns = t.namespace.clone();
    let mut client = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "failures::child_that_gets_killed", "--nocapture"])
        .env("E2E_CHILD_NAMESPACE", &ns)
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = client.id();
    // Wait until the child's session is up (it prints its worker's pid), then kill it hard.
    let said =
        envhub_e2e::lines_until_ready(&mut std::io::BufReader::new(client.stdout.take().unwrap()));
    let worker: u32 = said
        .lines()
        .find_map(|l| l.strip_prefix("ready "))
        .and_then(|p| p.trim().parse().ok())
        .unwrap_or_else(|| panic!("child said {said:?}"));
    let left_by_the_child = shm_files(&ns);
    assert!(
        left_by_the_child.len() > 1,
        "the child's session lives in /dev/shm: {left_by_the_child:?}"
    );
    sigkill(pid);
    client.wait().unwrap();
    // Its worker goes with it (parent-death signal, or its owner watch)...
    eventually(&format!("worker {worker} exits with its client"), || {
        !std::fs::read_to_string(format!("/proc/{worker}/stat"))
            .is_ok_and(|stat| !stat.contains(") Z"))
    });
    // ...and the next session in the namespace removes what the dead ones left (iceoryx2
    // cleans up dead nodes when a node is created): nothing here cleans up by hand.
    let mut env = t
        .hub
        .make_vec("gym-cartpole", 1, &EnvConfig::default())
        .unwrap();
    env.reset(Some(0)).unwrap();
    env.close();
    drop(env);
    // The namespace's own management file stays until the namespace is removed.
    let left: Vec<String> = shm_files(&ns)
        .into_iter()
        .filter(|f| !f.ends_with(".global_mgmt"))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
}

/// Helper process for `dead_clients_leave_nothing_behind`; does nothing in a normal run.
#[test]
fn child_that_gets_killed() {
    let Ok(ns) = std::env::var("E2E_CHILD_NAMESPACE") else {
        return;
    };
    let hub = envhub_hub::Hub::new(envhub_hub::Registry::builtin()).with_options(
        envhub_hub::SessionOptions {
            namespace: ns,
            ..envhub_hub::SessionOptions::default()
        },
    );
    let mut env = hub
        .make_vec("gym-cartpole", 2, &EnvConfig::default())
        .unwrap();
    env.reset(Some(0)).unwrap();
    println!("ready {}", env.worker_pids()[0]);
    std::thread::sleep(Duration::from_secs(30));
}
