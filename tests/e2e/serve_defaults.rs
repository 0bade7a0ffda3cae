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

/// A hub started with no `--listen` and no credentials listens on a Unix socket in this
/// user's folder of local hubs and on no TCP port: there is nothing another user of the
/// machine can flood (4,200 connections held on a loopback TCP port slowed the owner's client
/// to 18 s, `hub_bounds`). Another user's 4,200 tries on the socket are all refused by the
/// folder's mode; the owner's `envhub hubs` finds the hub through it.
#[test]
fn a_default_hub_listens_on_a_unix_socket_no_other_user_reaches_and_on_no_tcp_port() {
    use std::os::unix::process::CommandExt;
    let dir = std::env::temp_dir().join(format!("e2e-loopback-{}", std::process::id()));
    let local = dir.join("hubs");
    std::fs::create_dir_all(&dir).unwrap();
    let hub = Command::new(binary("envhub"))
        .args(["serve", "--name", "quiet", "--socket"])
        .arg(dir.join("hub.sock"))
        .env(envhub_hub::ENVHUB_MULTICAST, "0")
        .env(envhub_hub::local::ENVHUB_LOCAL_HUBS, &local)
        .env(
            "ENVHUB_NAMESPACE",
            format!("e2e_loopback_{}_", std::process::id()),
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    struct Killed(Option<std::process::Child>);
    impl Drop for Killed {
        fn drop(&mut self) {
            if let Some(mut child) = self.0.take() {
                let _ = child.kill();
                let _ = child.wait();
            }
        }
    }
    let mut hub = Killed(Some(hub));
    let pid = hub.0.as_ref().unwrap().id();
    let deadline = Instant::now() + Duration::from_secs(20);
    let endpoint = loop {
        let entry = std::fs::read_dir(&local).ok().and_then(|d| {
            d.filter_map(Result::ok)
                .find(|e| e.file_name().to_string_lossy().ends_with(".json"))
        });
        if let Some(v) = entry
            .and_then(|e| std::fs::read(e.path()).ok())
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        {
            break v["endpoints"][0].as_str().unwrap().to_string();
        }
        assert!(Instant::now() < deadline, "the hub wrote no entry in 20 s");
        std::thread::sleep(Duration::from_millis(50));
    };
    let socket = local.join(format!("{pid}.sock"));
    assert_eq!(endpoint, format!("unixsock-stream/{}", socket.display()));
    assert!(
        listening_addresses(pid).is_empty(),
        "the hub listens on TCP: {:?}",
        listening_addresses(pid)
    );
    // The owner finds it.
    let listed = envhub_e2e::envhub_hubs_listing(&local, "\"quiet\"");
    assert!(
        listed.contains("\"quiet\""),
        "the owner's `envhub hubs`: {listed}"
    );
    // Another user: every connection refused by the file system.
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } == 0 {
        let script = "import socket,sys\nok=denied=0\nheld=[]\nfor _ in range(4200):\n    s=socket.socket(socket.AF_UNIX)\n    try:\n        s.connect(sys.argv[1]); ok+=1; held.append(s)\n    except PermissionError:\n        denied+=1; s.close()\nprint(ok, denied)\n";
        let out = Command::new("python3")
            .args(["-c", script])
            .arg(&socket)
            .uid(65534)
            .gid(65534)
            .current_dir("/")
            .output()
            .expect("python3 runs");
        let said = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "{said} {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            said.trim(),
            "0 4200",
            "another user's connections (connected, refused)"
        );
    } else {
        assert!(
            std::env::var_os("ENVHUB_OTHER_USER_REQUIRED").is_none_or(|v| v.is_empty()),
            "the other user's flood: required (ENVHUB_OTHER_USER_REQUIRED) but not root"
        );
        eprintln!("skipped the other user's flood: needs root to run as uid 65534");
    }
    let mut child = hub.0.take().unwrap();
    let _ = child.kill();
    let out = child.wait_with_output().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("loopback only") && said.contains("--insecure-listen"),
        "the hub did not say how to open it up: {said}"
    );
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
