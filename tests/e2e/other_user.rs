//! A hub without credentials on loopback (by default, or on a loopback `--listen` it was given)
//! against the other users of its machine, as one of them would try it: loopback is open to
//! every uid, so the hub checks every link into it against this user's local credential,
//! which only this user can read.
//!
//! - A Zenoh peer that reaches the hub's loopback port without the credential (as any
//!   process of another user can, the port being in `/proc/net/tcp`) gets no link, no token
//!   and no answer to `open`.
//! - `envhub hubs` run as another uid (`nobody`), pointed at the hub's endpoint, lists nothing;
//!   it cannot read the credential either. Needs root to run a process as another uid; without
//!   it that part is skipped with the reason (CI runs as root).
//! - This user's default client finds the hub (through the folder of local hubs) and one
//!   given the endpoint reaches it: both present the credential.

use envhub_e2e::{binary, envhub_hubs};
use std::os::unix::fs::PermissionsExt;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};
use zenoh::Wait;

const NOBODY: u32 = 65534;

struct LoopbackHub {
    child: Child,
    name: String,
    endpoint: String,
    local: PathBuf,
    dir: PathBuf,
}

impl Drop for LoopbackHub {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Starts hub `uid-<tag>-<pid>`, with `args` added to `serve`.
fn start(tag: &str, args: &[&str]) -> LoopbackHub {
    let pid = std::process::id();
    let name = format!("uid-{tag}-{pid}");
    let dir = std::env::temp_dir().join(format!("e2e-uid-{tag}-{pid}"));
    let local = dir.join("hubs");
    std::fs::create_dir_all(&dir).unwrap();
    let child = Command::new(binary("envhub"))
        .args(["serve", "--name", &name, "--socket"])
        .arg(dir.join("hub.sock"))
        .args(args)
        .env("ENVHUB_NAMESPACE", format!("e2e_uid_{tag}_{pid}_"))
        .env(envhub_hub::local::ENVHUB_LOCAL_HUBS, &local)
        .env(envhub_hub::ENVHUB_MULTICAST, "0")
        .env_remove(envhub_hub::ENVHUB_CONNECT)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    let deadline = Instant::now() + Duration::from_secs(20);
    let endpoint = loop {
        let entry = std::fs::read_dir(&local).ok().and_then(|d| {
            d.filter_map(Result::ok)
                .find(|e| e.file_name().to_string_lossy().ends_with(".json"))
        });
        if let Some(entry) = entry {
            let v: serde_json::Value =
                serde_json::from_slice(&std::fs::read(entry.path()).unwrap()).unwrap();
            break v["endpoints"][0].as_str().unwrap().to_string();
        }
        assert!(
            Instant::now() < deadline,
            "the hub did not start within 20 s"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    LoopbackHub {
        child,
        name,
        endpoint,
        local,
        dir,
    }
}

#[test]
fn another_user_on_this_machine_never_reaches_a_default_hub() {
    never_reached_by_another_user(start("default", &[]));
}

#[test]
fn another_user_never_reaches_a_hub_given_a_loopback_listener() {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let hub = start("listen", &["--listen", &format!("tcp/127.0.0.1:{port}")]);
    assert_eq!(hub.endpoint, format!("tcp/127.0.0.1:{port}"));
    never_reached_by_another_user(hub);
}

fn never_reached_by_another_user(hub: LoopbackHub) {
    // A peer without the credential, on the hub's own loopback endpoint.
    let mut config = zenoh::Config::default();
    config
        .insert_json5("connect/endpoints", &format!("[\"{}\"]", hub.endpoint))
        .unwrap();
    config
        .insert_json5("scouting/multicast/enabled", "false")
        .unwrap();
    let intruder = zenoh::open(config)
        .wait()
        .expect("the intruder's peer opens");
    std::thread::sleep(Duration::from_secs(2));
    let envhub_e2e::intruder::Seen {
        peers,
        tokens,
        open_answers: answers,
    } = envhub_e2e::intruder::probe(&intruder, &hub.name);
    drop(intruder);
    assert!(
        peers.is_empty(),
        "a peer without the credential got a link to {peers:?}"
    );
    assert!(
        tokens.is_empty(),
        "a peer without the credential saw tokens {tokens:?}"
    );
    assert_eq!(
        answers, 0,
        "a peer without the credential got an open answer"
    );

    // This user's clients: found through the folder, and reached through the endpoint.
    let found = envhub_hubs(&binary("envhub"), &hub.local, &[], None);
    assert!(
        found.contains(&hub.name),
        "this user's default client did not find the hub: {found}"
    );
    let reached = envhub_hubs(
        &binary("envhub"),
        &hub.local,
        &["--connect", &hub.endpoint],
        None,
    );
    assert!(
        reached.contains(&hub.name),
        "this user's client given the endpoint did not reach the hub: {reached}"
    );

    // Another uid, as a process of another user runs: no credential to read, no hub.
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        eprintln!("skipped the other-uid part: running a process as another uid needs root");
        return;
    }
    let theirs = hub.dir.join("nobody");
    std::fs::create_dir_all(theirs.join("bin")).unwrap();
    std::fs::set_permissions(&hub.dir, std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::set_permissions(&theirs, std::fs::Permissions::from_mode(0o755)).unwrap();
    std::os::unix::fs::chown(&theirs, Some(NOBODY), Some(NOBODY)).unwrap();
    let their_binary = theirs.join("bin").join("envhub");
    std::fs::copy(binary("envhub"), &their_binary).unwrap();
    std::fs::set_permissions(&their_binary, std::fs::Permissions::from_mode(0o755)).unwrap();
    let their_local = theirs.join("hubs");
    let credential = hub.local.join("credential");
    let read = Command::new("cat")
        .arg(&credential)
        .uid(NOBODY)
        .gid(NOBODY)
        .output()
        .unwrap();
    assert!(
        !read.status.success() && read.stdout.is_empty(),
        "another uid read the credential"
    );
    let listed = envhub_hubs(
        &their_binary,
        &their_local,
        &["--connect", &hub.endpoint],
        Some(NOBODY),
    );
    assert!(
        !listed.contains(&hub.name),
        "another uid reached the default hub: {listed}"
    );
    // The same binary, run by this user with the endpoint, does reach it (the test can fail).
    let control = envhub_hubs(
        &their_binary,
        &hub.local,
        &["--connect", &hub.endpoint],
        None,
    );
    assert!(control.contains(&hub.name), "{control}");
}
