//! `envhub serve`: one hub daemon shared by several client processes.

use envhub_e2e::{PATIENCE, PyModule, binary, eventually, python_worker_available};
use envhub_hub::env_vars::{ENVHUB_ADAPTERS, ENVHUB_HUB, ENVHUB_NAMESPACE, ENVHUB_REGISTRY};
use envhub_hub::{EnvConfig, Host, Hub, HubError, Registry, SessionOptions};
use rand::SeedableRng;
use std::ffi::OsString;
use std::io::BufRead;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

struct Daemon {
    child: Child,
    socket: PathBuf,
    namespace: String,
}

impl Daemon {
    fn start(name: &str) -> Daemon {
        Daemon::start_with(name, &[])
    }

    /// A daemon with `vars` set, and without the user adapters of this process.
    fn start_with(name: &str, vars: &[(&str, OsString)]) -> Daemon {
        let dir = std::env::temp_dir().join(format!("e2e-daemon-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let socket = dir.join("hub.sock");
        let namespace = format!("e2e_daemon_{name}_{}_", std::process::id());
        let mut child = Command::new(binary("envhub"))
            .args([
                "serve",
                "--local-only",
                "--socket",
                socket.to_str().unwrap(),
            ])
            .env("ENVHUB_NAMESPACE", &namespace)
            .envs(vars.iter().cloned())
            .env_remove(ENVHUB_ADAPTERS)
            .stdout(Stdio::piped())
            .spawn()
            .unwrap();
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .unwrap();
        assert!(line.contains("listening on"), "daemon said {line:?}");
        Daemon {
            child,
            socket,
            namespace,
        }
    }

    fn hub(&self) -> Hub {
        Hub::connect(&self.socket, Registry::builtin())
            .unwrap()
            .with_options(SessionOptions {
                namespace: self.namespace.clone(),
                ..SessionOptions::default()
            })
    }

    fn alive(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }
}

impl Drop for Daemon {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = envhub_shm::remove_namespace(&self.namespace);
    }
}

fn parent_of(pid: u32) -> u32 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap();
    let after = &stat[stat.rfind(')').unwrap() + 2..];
    after.split_whitespace().nth(1).unwrap().parse().unwrap()
}

#[test]
fn several_clients_share_one_daemon() {
    let mut d = Daemon::start("share");
    let clients: Vec<Child> = (0..3)
        .map(|k| {
            Command::new(binary("envhub"))
                .args([
                    "run",
                    "gym-cartpole",
                    "--num-envs",
                    "4",
                    "--workers",
                    "1",
                    "--steps",
                    "20000",
                    "--json",
                    "--seed",
                    &k.to_string(),
                ])
                .env("ENVHUB_HUB", &d.socket)
                .env("ENVHUB_NAMESPACE", &d.namespace)
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        })
        .collect();
    for c in clients {
        let out = c.wait_with_output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v["steps"], 20000);
    }
    assert!(d.alive());

    // Workers are the daemon's children, and the data plane still goes direct.
    let hub = d.hub();
    let mut env = hub
        .make_vec(
            "gym-pendulum",
            2,
            &EnvConfig {
                workers: Some(2),
                ..EnvConfig::default()
            },
        )
        .unwrap();
    for pid in env.worker_pids() {
        assert_eq!(parent_of(pid), d.child.id());
    }
    env.reset(Some(0)).unwrap();
    env.step_f32(&[0.5, -0.5]).unwrap();
    env.step_f32(&[5.0, -5.0]).unwrap(); // beyond the bounds: the env clips, as in Gymnasium
    assert_eq!(hub.daemon().unwrap().worker_count().unwrap(), 2);
    env.close();
    eventually("closed workers are forgotten", || {
        hub.daemon().unwrap().worker_count().unwrap() == 0
    });

    // `strict_actions` travels through the daemon's routing.
    let mut strict = hub
        .make_vec(
            "gym-pendulum",
            1,
            &EnvConfig {
                strict_actions: true,
                ..EnvConfig::default()
            },
        )
        .unwrap();
    strict.reset(Some(0)).unwrap();
    let err = strict.step_f32(&[5.0]).unwrap_err().to_string();
    assert!(err.contains("valid range [-2, 2]"), "{err}");
    strict.close();

    // Errors travel back with their hints.
    let err = hub
        .make("gym-cartpol", &EnvConfig::default())
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("did you mean `gym-cartpole`"), "{err}");
}

#[test]
fn killed_worker_and_killed_client_leave_the_daemon_running() {
    let mut d = Daemon::start("kill");
    let hub = d.hub();
    let mut env = hub
        .make_vec(
            "gym-cartpole",
            2,
            &EnvConfig {
                workers: Some(1),
                ..EnvConfig::default()
            },
        )
        .unwrap();
    env.reset(Some(0)).unwrap();
    let pid = env.worker_pids()[0];
    Command::new("kill")
        .args(["-9", &pid.to_string()])
        .status()
        .unwrap();
    // Noticed as the process's exit (its status), not at the step timeout.
    let err = env.step_i64(&[0, 1]).unwrap_err();
    match err {
        HubError::WorkerDied { why, .. } => {
            assert!(
                why.starts_with("died (") && why.contains("signal: 9"),
                "{why}"
            )
        }
        other => panic!("expected WorkerDied, got {other}"),
    }
    assert!(d.alive());

    // A client killed mid-run: the daemon stops its workers and carries on.
    let mut client = Command::new(binary("envhub"))
        .args([
            "run",
            "gym-cartpole",
            "--num-envs",
            "2",
            "--workers",
            "2",
            "--steps",
            "100000000",
        ])
        .env("ENVHUB_HUB", &d.socket)
        .env("ENVHUB_NAMESPACE", &d.namespace)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    eventually("the client's workers start", || {
        hub.daemon().unwrap().worker_count().unwrap() >= 2
    });
    client.kill().unwrap();
    client.wait().unwrap();
    eventually("the dead client's workers are stopped", || {
        hub.daemon().unwrap().worker_count().unwrap() == 0
    });
    assert!(d.alive());
    let mut env = hub
        .make_vec("gym-cartpole", 1, &EnvConfig::default())
        .unwrap();
    env.reset(Some(0)).unwrap();
    env.step_i64(&[1]).unwrap();
}

/// A user adapter whose `make` wraps Gymnasium's CartPole.
const WRAPPED_ADAPTER: &str = r#"
import gymnasium as gym

import envhub


class WrappedCartPole(envhub.EnvAdapter):
    name = "e2e_wrapped"
    frameworks = ["e2e_wrapped"]
    requires = ["gymnasium"]
    description = "Gymnasium's CartPole behind a user adapter"

    def make(self, env_id, config):
        return gym.make("CartPole-v1")
"#;

const WRAPPED_REGISTRY: &str = "
environments:
  - id: wrapped-cartpole
    name: CartPole through a user adapter
    framework: e2e_wrapped
    env_id: WrappedCartPole-v0
    robot_type: custom
    env_type: floor
";

#[test]
fn user_adapters_of_a_client_reach_the_daemon() {
    if !python_worker_available("daemon::user_adapters_of_a_client_reach_the_daemon") {
        return;
    }
    let module = PyModule::write("daemon-user", "e2e_wrapped_adapter", WRAPPED_ADAPTER);
    let registry = module.dir.join("registry.yaml");
    std::fs::write(&registry, WRAPPED_REGISTRY).unwrap();
    let mut registries = OsString::from("@default:");
    registries.push(&registry);
    let mut d = Daemon::start_with("user", &[(ENVHUB_REGISTRY, registries)]);

    // A client without the adapter: the daemon's own catalog has no such framework.
    let out = Command::new(binary("envhub"))
        .args([
            "run",
            "wrapped-cartpole",
            "--num-envs",
            "1",
            "--steps",
            "10",
        ])
        .env(ENVHUB_HUB, &d.socket)
        .env(ENVHUB_NAMESPACE, &d.namespace)
        .env_remove(ENVHUB_ADAPTERS)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("unknown framework `e2e_wrapped`"),
        "{stderr}"
    );

    // This process registers it as `AdapterRegistry().register` does: in its own
    // environment, which the daemon never sees (nextest runs each test in its own process).
    unsafe {
        std::env::set_var(ENVHUB_ADAPTERS, "e2e_wrapped_adapter:WrappedCartPole");
        std::env::set_var("PYTHONPATH", module.pythonpath());
    }
    let hub = d.hub();
    let listed = hub.adapters().unwrap();
    let wrapped_info = listed.iter().find(|a| a.name == "e2e_wrapped");
    assert!(
        wrapped_info.is_some_and(|a| a.availability.is_available() && a.host == Host::Python),
        "{listed:?}"
    );
    let config = EnvConfig {
        workers: Some(2),
        ..EnvConfig::default()
    };
    let mut wrapped = hub.make_vec("wrapped-cartpole", 2, &config).unwrap();
    assert_eq!(wrapped.route().adapter, "e2e_wrapped");
    for pid in wrapped.worker_pids() {
        assert_eq!(parent_of(pid), d.child.id(), "the daemon started it");
    }
    // It is Gymnasium's CartPole: it steps like the native one.
    let mut native = hub.make_vec("gym-cartpole", 2, &config).unwrap();
    let first = native.reset(Some(3)).unwrap().obs.to_vec();
    assert_eq!(wrapped.reset(Some(3)).unwrap().obs, first);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    for step in 0..100 {
        let actions = native.sample_actions(&mut rng);
        let a = native.step(&actions).unwrap();
        let b = wrapped.step(&actions).unwrap();
        assert_eq!((a.obs, a.rewards), (b.obs, b.rewards), "step {step}");
        assert_eq!(a.terminated, b.terminated, "step {step}");
    }
    wrapped.close();
    native.close();

    // An import path that fails: the reason names it, as with the embedded hub.
    unsafe { std::env::set_var(ENVHUB_ADAPTERS, "e2e_no_such_module_xyz:Nope") };
    let err = hub
        .make_vec("wrapped-cartpole", 1, &EnvConfig::default())
        .err()
        .expect("the adapter cannot be imported")
        .to_string();
    assert!(
        err.contains("cannot import `e2e_no_such_module_xyz:Nope`")
            && err.contains("ModuleNotFoundError"),
        "{err}"
    );
    assert!(d.alive());
}

/// The error of `make(id, config)` on `hub`, as the variant and message a caller sees.
fn make_error(hub: &Hub, id: &str, config: &EnvConfig) -> HubError {
    match hub.make(id, config) {
        Ok(_) => panic!("`{id}` made"),
        Err(e) => e,
    }
}

#[test]
fn errors_through_the_daemon_are_the_embedded_hubs() {
    let d = Daemon::start("errors");
    let (remote, local) = (d.hub(), Hub::new(Registry::builtin()));
    let mut bad_option = EnvConfig::default();
    bad_option.extra.insert("gravty".into(), 9.8.into());
    let cases = [
        ("mujoco-antt", EnvConfig::default()),
        ("isaac-franka-lift", EnvConfig::default()),
        ("gym-pendulum", bad_option),
    ];
    for (id, config) in &cases {
        let (through, here) = (
            make_error(&remote, id, config),
            make_error(&local, id, config),
        );
        assert_eq!(
            std::mem::discriminant(&through),
            std::mem::discriminant(&here),
            "`{id}`: through the daemon {through:?}, embedded {here:?}"
        );
        assert_eq!(through.to_string(), here.to_string(), "`{id}`");
    }
    match make_error(&remote, "mujoco-antt", &EnvConfig::default()) {
        HubError::Registry(envhub_hub::RegistryError::UnknownId { id, closest }) => {
            assert_eq!(id, "mujoco-antt");
            assert!(closest.iter().any(|c| c == "mujoco-ant"), "{closest:?}");
        }
        other => panic!("expected UnknownId, got {other:?}"),
    }
    let unavailable = make_error(&remote, "isaac-franka-lift", &EnvConfig::default());
    assert!(
        matches!(unavailable, HubError::Unavailable { ref adapter, .. } if adapter == "isaac_lab"),
        "{unavailable:?}"
    );
    let bad = make_error(&remote, "gym-pendulum", &cases[2].1);
    assert!(matches!(bad, HubError::MakeFailed(_)), "{bad:?}");
}

/// The daemon's socket is its user's alone (mode 0600), and a connection from another user
/// that gets through anyway (the socket opened up by hand) is refused: the daemon asks the
/// kernel who connected (`SO_PEERCRED`). The second user is uid 65534 (`nobody`), which
/// needs root to become; skipped otherwise, unless `ENVHUB_NETNS_REQUIRED` (the root tier).
#[test]
fn another_user_cannot_use_the_daemon() {
    use std::os::unix::fs::PermissionsExt;
    use std::os::unix::process::CommandExt;
    let daemon = Daemon::start("peer");
    let mode = std::fs::metadata(&daemon.socket)
        .unwrap()
        .permissions()
        .mode();
    assert_eq!(mode & 0o777, 0o600, "socket mode {:o}", mode & 0o777);
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        assert!(
            std::env::var_os("ENVHUB_NETNS_REQUIRED").is_none_or(|v| v.is_empty()),
            "another_user_cannot_use_the_daemon: required (ENVHUB_NETNS_REQUIRED) but not root"
        );
        eprintln!("skipped the second user: needs root to run as uid 65534");
        return;
    }
    let dir = daemon.socket.parent().unwrap();
    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o755)).unwrap();
    std::fs::set_permissions(&daemon.socket, std::fs::Permissions::from_mode(0o666)).unwrap();
    // Connects as `nobody`, sends a ping, prints what comes back (nothing: refused).
    // (The daemon may drop the connection before the ping is even written: a broken pipe.)
    let script = "import socket,sys\ns=socket.socket(socket.AF_UNIX)\ns.settimeout(5)\ntry:\n    s.connect(sys.argv[1])\n    s.sendall(b'{\"op\": \"ping\"}\\n')\n    print(repr(s.recv(100)))\nexcept OSError as e:\n    print('error', e)\n";
    let out = Command::new("python3")
        .args(["-c", script])
        .arg(&daemon.socket)
        .uid(65534)
        .gid(65534)
        .output()
        .expect("python3 runs");
    let said = String::from_utf8_lossy(&out.stdout);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{said} {err}");
    assert!(!said.contains("pong"), "another user was served: {said}");
    // It reached the socket (the refusal is the daemon's, not the file mode's).
    assert!(!said.contains("Permission denied"), "{said}");
    // The daemon's own user still is.
    let mut own = std::os::unix::net::UnixStream::connect(&daemon.socket).unwrap();
    std::io::Write::write_all(&mut own, b"{\"op\": \"ping\"}\n").unwrap();
    let mut line = String::new();
    std::io::BufReader::new(own).read_line(&mut line).unwrap();
    assert!(line.contains("pong"), "{line}");
}

/// A socket that accepts and never answers (a stuck or stopped daemon, or not a daemon at
/// all): connecting fails at the ping's time limit instead of hanging.
#[test]
fn a_daemon_that_never_answers_is_an_error_at_the_pings_time_limit() {
    let dir = std::env::temp_dir().join(format!("e2e-silent-daemon-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let socket = dir.join("hub.sock");
    let _ = std::fs::remove_file(&socket);
    let listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
    let silent = std::thread::spawn(move || {
        // Holds the connection open without a word until the client gives up.
        let (mut stream, _) = listener.accept().unwrap();
        let mut sink = Vec::new();
        let _ = std::io::Read::read_to_end(&mut stream, &mut sink);
    });
    let (tx, connected) = std::sync::mpsc::channel();
    let client = socket.clone();
    std::thread::spawn(move || {
        let _ = tx.send(Hub::connect(&client, Registry::builtin()).map(drop));
    });
    // The silent socket would hold it forever: only the ping's own 5 s limit ends it.
    let Ok(connected) = connected.recv_timeout(Duration::from_secs(5) + PATIENCE) else {
        panic!("connecting to a silent socket hangs");
    };
    let Err(e) = connected else {
        panic!("a silent socket passed for a daemon");
    };
    assert!(
        e.to_string().contains("no reply to `ping` within 5s"),
        "{e}"
    );
    silent.join().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
}

/// A socket in front of a real daemon that passes every request on and hands its replies
/// back through `rewrite` (a daemon that lies).
fn lying_proxy(
    daemon: &Daemon,
    name: &str,
    rewrite: impl Fn(&str, serde_json::Value) -> serde_json::Value + Send + 'static,
) -> (PathBuf, std::thread::JoinHandle<()>) {
    use std::io::Write;
    let dir = std::env::temp_dir().join(format!("e2e-lying-daemon-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let socket = dir.join("hub.sock");
    let _ = std::fs::remove_file(&socket);
    let listener = std::os::unix::net::UnixListener::bind(&socket).unwrap();
    let real = daemon.socket.clone();
    let proxy = std::thread::spawn(move || {
        let (client, _) = listener.accept().unwrap();
        let upstream = std::os::unix::net::UnixStream::connect(&real).unwrap();
        let mut from_client = std::io::BufReader::new(client.try_clone().unwrap());
        let mut from_daemon = std::io::BufReader::new(upstream.try_clone().unwrap());
        let (mut to_client, mut to_daemon) = (client, upstream);
        let mut line = String::new();
        while from_client.read_line(&mut line).unwrap_or(0) > 0 {
            let op = serde_json::from_str::<serde_json::Value>(&line).unwrap()["op"]
                .as_str()
                .unwrap_or_default()
                .to_string();
            to_daemon.write_all(line.as_bytes()).unwrap();
            line.clear();
            from_daemon.read_line(&mut line).unwrap();
            let reply = rewrite(&op, serde_json::from_str(&line).unwrap());
            to_client
                .write_all(format!("{reply}\n").as_bytes())
                .unwrap();
            line.clear();
        }
    });
    (socket, proxy)
}

#[test]
fn a_daemon_that_reports_a_foreign_pid_or_a_foreign_error_kind_is_not_believed() {
    let daemon = Daemon::start("lying");
    // A process that is not the daemon's child (nor this process's, which plays the daemon
    // here): a shell's child, the worker the lying daemon reports.
    let mut shell = Command::new("sh")
        .args(["-c", "sleep 30 & echo $!; wait"])
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    let mut said = String::new();
    std::io::BufReader::new(shell.stdout.take().unwrap())
        .read_line(&mut said)
        .unwrap();
    let foreign_pid: u32 = said.trim().parse().unwrap();
    assert_eq!(parent_of(foreign_pid), shell.id());
    let (socket, proxy) = lying_proxy(&daemon, "pid", move |op, mut reply| {
        if op == "launch" {
            reply["ok"]["pid"] = serde_json::json!(foreign_pid);
        }
        reply
    });
    let hub = Hub::connect(&socket, Registry::builtin())
        .unwrap()
        .with_options(SessionOptions {
            namespace: daemon.namespace.clone(),
            ..SessionOptions::default()
        });
    let err = hub
        .make_vec("gym-cartpole", 1, &EnvConfig::default())
        .err()
        .expect("a session with a worker the daemon did not start");
    assert!(
        err.to_string().contains(&format!("pid {foreign_pid}"))
            && err.to_string().contains("not the daemon"),
        "{err}"
    );
    drop(hub);
    assert_eq!(
        parent_of(foreign_pid),
        shell.id(),
        "the foreign process was killed"
    );
    envhub_shm::kill(foreign_pid);
    let _ = shell.wait();
    proxy.join().unwrap();

    // An error kind that describes the client itself (Interrupted: Python's
    // KeyboardInterrupt) comes back as the daemon's error, not as that kind.
    let (socket, proxy) = lying_proxy(&daemon, "kind", |op, reply| {
        if op == "route" {
            serde_json::json!({
                "err": "interrupted",
                "error": serde_json::to_value(HubError::Interrupted).unwrap(),
            })
        } else {
            reply
        }
    });
    let hub = Hub::connect(&socket, Registry::builtin()).unwrap();
    match hub.make_vec("gym-cartpole", 1, &EnvConfig::default()) {
        Err(HubError::Daemon { reason, .. }) => assert!(reason.contains("nterrupted"), "{reason}"),
        Err(e) => panic!("expected the daemon's error, got {e:?}"),
        Ok(_) => panic!("a session from a refused route"),
    }
    drop(hub);
    proxy.join().unwrap();
}

#[test]
fn an_overlong_request_line_ends_that_connection_only() {
    use std::io::Write;
    let daemon = Daemon::start("overlong");
    let mut stream = std::os::unix::net::UnixStream::connect(&daemon.socket).unwrap();
    // Bounded so that a daemon that never answers fails here, far above a loaded machine's
    // answer.
    stream.set_read_timeout(Some(PATIENCE)).unwrap();
    // 17 MiB without a newline: past the 16 MiB bound.
    let chunk = vec![b'x'; 1 << 20];
    for _ in 0..17 {
        if stream.write_all(&chunk).is_err() {
            break; // the daemon closed the connection mid-way
        }
    }
    let mut reply = String::new();
    let _ = std::io::BufReader::new(&stream).read_line(&mut reply);
    assert!(
        reply.contains("longer than"),
        "the daemon answered {reply:?}"
    );
    // The daemon still serves others.
    let hub = daemon.hub();
    let mut env = hub
        .make_vec("gym-cartpole", 1, &EnvConfig::default())
        .unwrap();
    env.reset(Some(0)).unwrap();
}
