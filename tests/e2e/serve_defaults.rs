//! `envhub serve`'s safe defaults, with real hub processes: loopback only without
//! credentials, limits on, silent sessions closed.

use envhub_e2e::binary;
use envhub_e2e::remote::{RemoteHub, net_to};
use envhub_hub::{EnvConfig, Hub, HubError, Placement, Registry, SessionOptions};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// A client that reaches `hub` and asks for `step_timeout`.
fn client(name: &str, hub: &RemoteHub, step_timeout: Duration) -> Hub {
    Hub::new(Registry::builtin())
        .with_options(SessionOptions {
            namespace: format!("e2e_defaults_{name}_{}_", std::process::id()),
            step_timeout,
            start_timeout: Duration::from_secs(30),
            ..SessionOptions::default()
        })
        .with_network(net_to(&[hub]))
}

fn refusal(result: Result<envhub_hub::VecEnv, HubError>) -> String {
    match result {
        Err(e @ HubError::Refused { .. }) => e.to_string(),
        Err(e) => panic!("expected a refusal, got {e}"),
        Ok(_) => panic!("expected a refusal, got a session"),
    }
}

#[test]
fn a_hub_without_credentials_refuses_to_listen_beyond_loopback() {
    let dir = std::env::temp_dir().join(format!("e2e-exposure-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = Command::new(binary("envhub"))
        .args(["serve", "--name", "exposed", "--socket"])
        .arg(dir.join("hub.sock"))
        .args(["--listen", "tcp/0.0.0.0:0"])
        .env(envhub_hub::ENVHUB_MULTICAST, "0")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "the hub started: {err}");
    assert!(
        err.contains("tcp/0.0.0.0:0")
            && err.contains("--insecure-listen")
            && err.contains("usrpwd"),
        "the refusal names the endpoint, the flag and the credentials: {err}"
    );
}

/// The TCP sockets a process listens on, from /proc (its socket inodes matched against the
/// kernel's tables): (address, port) in the kernel's hex.
fn listening_addresses(pid: u32) -> Vec<String> {
    let inodes: Vec<String> = std::fs::read_dir(format!("/proc/{pid}/fd"))
        .unwrap()
        .filter_map(|e| std::fs::read_link(e.ok()?.path()).ok())
        .filter_map(|l| {
            let l = l.to_string_lossy().into_owned();
            Some(l.strip_prefix("socket:[")?.strip_suffix(']')?.to_string())
        })
        .collect();
    let mut found = Vec::new();
    for table in ["/proc/net/tcp", "/proc/net/tcp6"] {
        for line in std::fs::read_to_string(table)
            .unwrap_or_default()
            .lines()
            .skip(1)
        {
            let f: Vec<&str> = line.split_whitespace().collect();
            // local_address, state (0A: LISTEN), inode
            if f.len() > 9 && f[3] == "0A" && inodes.iter().any(|i| i == f[9]) {
                found.push(f[1].to_string());
            }
        }
    }
    found
}

#[test]
fn a_hub_started_without_listen_or_credentials_listens_on_loopback_only() {
    let dir = std::env::temp_dir().join(format!("e2e-loopback-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let mut hub = Command::new(binary("envhub"))
        .args(["serve", "--name", "quiet", "--socket"])
        .arg(dir.join("hub.sock"))
        .env(envhub_hub::ENVHUB_MULTICAST, "0")
        .env(
            "ENVHUB_NAMESPACE",
            format!("e2e_loopback_{}_", std::process::id()),
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(15);
    let mut addresses = Vec::new();
    while addresses.is_empty() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
        addresses = listening_addresses(hub.id());
    }
    let _ = hub.kill();
    let out = hub.wait_with_output().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("loopback only") && said.contains("--insecure-listen"),
        "the hub did not say how to open it up: {said}"
    );
    assert!(
        !addresses.is_empty(),
        "the hub listened on no TCP socket within 15 s"
    );
    // IPv4 loopback is 0100007F:port in /proc/net/tcp (little-endian 127.0.0.1).
    for a in &addresses {
        assert!(
            a.starts_with("0100007F:"),
            "the hub listens on {a}, not on loopback"
        );
    }
}

#[test]
fn limits_are_named_with_their_flags_and_silent_sessions_close() {
    let a = RemoteHub::start(
        "lim",
        &[
            "--max-step-timeout",
            "5",
            "--max-sessions-per-client",
            "1",
            "--idle-timeout",
            "1",
        ],
        &[],
    );
    let on_a = Placement::Hubs(vec![a.name.clone()]);
    let config = EnvConfig::default();
    let greedy = client("greedy", &a, Duration::from_secs(60));
    let err = refusal(greedy.make_vec_on("gym-cartpole", 1, &config, &on_a));
    assert!(
        err.contains("--max-step-timeout") && err.contains("limit of 5s"),
        "{err}"
    );
    assert_eq!(a.worker_count(), 0, "a refused request started workers");

    let hub = client("modest", &a, Duration::from_secs(2));
    let mut first = hub.make_vec_on("gym-cartpole", 1, &config, &on_a).unwrap();
    first.reset(Some(0)).unwrap();
    let err = refusal(hub.make_vec_on("gym-cartpole", 1, &config, &on_a));
    assert!(err.contains("--max-sessions-per-client"), "{err}");

    // Silent past the idle timeout (1 s, looked at every 100 ms): the hub closes the session
    // and frees its workers.
    let silent = Instant::now();
    while a.worker_count() > 0 {
        assert!(
            silent.elapsed() < Duration::from_secs(10),
            "the silent session still runs {} workers after 10 s",
            a.worker_count()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let action = vec![0u8; first.action_space().byte_len()];
    let err = first.step(&action).expect_err("a closed session steps");
    assert!(err.to_string().contains("no open session"), "{err}");
    // Its place is free again.
    hub.make_vec_on("gym-cartpole", 1, &config, &on_a).unwrap();
}
