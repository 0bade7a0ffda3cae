//! Hub processes on loopback for the remote-hub tests: each with its own iceoryx2 namespace,
//! multicast off and explicit endpoints, so nothing can shortcut through local shared memory
//! or reach beyond 127.0.0.1. They stand for hubs on other machines, which no local
//! credential reaches: each is shared with `--insecure-listen` (a hub given a loopback
//! listener otherwise admits only its user's processes that present the local credential,
//! as `other_user` tests; the tests' raw Zenoh peers present none).

use crate::binary;
use envhub_hub::{Hub, NetConfig, Registry, SessionOptions};
use std::io::BufRead;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// A free TCP port on loopback (bound and released: another process could take it first,
/// which the hub then reports).
pub fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// An `envhub serve` process on the network.
pub struct RemoteHub {
    /// The process.
    pub child: Child,
    /// Its name on the network.
    pub name: String,
    /// Its Zenoh endpoint (`tcp/127.0.0.1:PORT`).
    pub endpoint: String,
    /// Its iceoryx2 namespace.
    pub namespace: String,
    dir: std::path::PathBuf,
}

impl RemoteHub {
    /// Starts hub `name` listening on a free loopback port, with `args` added to `serve`
    /// and `vars` to its environment; returns once it is on the network.
    pub fn start(name: &str, args: &[&str], vars: &[(&str, &str)]) -> RemoteHub {
        let endpoint = format!("tcp/127.0.0.1:{}", free_port());
        RemoteHub::start_at(name, &endpoint, args, vars)
    }

    /// [`RemoteHub::start`] on a given endpoint (a hub that comes back where it was).
    pub fn start_at(name: &str, endpoint: &str, args: &[&str], vars: &[(&str, &str)]) -> RemoteHub {
        RemoteHub::launch(name, endpoint, args, vars, false)
    }

    /// [`RemoteHub::start_at`] with the hub's log (its stderr) written to a file that
    /// [`RemoteHub::log`] reads, instead of the test's stderr.
    pub fn start_logged(
        name: &str,
        endpoint: &str,
        args: &[&str],
        vars: &[(&str, &str)],
    ) -> RemoteHub {
        RemoteHub::launch(name, endpoint, args, vars, true)
    }

    /// What a hub of [`RemoteHub::start_logged`] has logged so far.
    pub fn log(&self) -> String {
        std::fs::read_to_string(self.dir.join("hub.log")).unwrap_or_default()
    }

    fn launch(
        name: &str,
        endpoint: &str,
        args: &[&str],
        vars: &[(&str, &str)],
        logged: bool,
    ) -> RemoteHub {
        let tag = format!("{name}-{}-{}", std::process::id(), free_port());
        let dir = std::env::temp_dir().join(format!("e2e-hub-{tag}"));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let endpoint = endpoint.to_string();
        let namespace = format!("e2e_hub_{}_", tag.replace('-', "_"));
        let mut child = Command::new(binary("envhub"))
            .args(["serve", "--socket"])
            .arg(dir.join("hub.sock"))
            .args([
                "--name",
                name,
                "--listen",
                endpoint.as_str(),
                "--insecure-listen",
            ])
            .args(args)
            .env("ENVHUB_NAMESPACE", &namespace)
            .env(envhub_hub::ENVHUB_MULTICAST, "0")
            .env_remove(envhub_hub::ENVHUB_CONNECT)
            .env_remove(envhub_hub::env_vars::ENVHUB_ADAPTERS)
            .envs(vars.iter().copied())
            .stdout(Stdio::piped())
            .stderr(if logged {
                std::fs::File::create(dir.join("hub.log"))
                    .expect("the hub's log file")
                    .into()
            } else {
                Stdio::inherit()
            })
            .spawn()
            .expect("envhub serve starts");
        let mut out = std::io::BufReader::new(child.stdout.take().expect("piped"));
        let mut said = String::new();
        for _ in 0..4 {
            let mut line = String::new();
            if out.read_line(&mut line).unwrap_or(0) == 0 {
                break;
            }
            said.push_str(&line);
            if line.contains("on the network") {
                return RemoteHub {
                    child,
                    name: name.to_string(),
                    endpoint,
                    namespace,
                    dir,
                };
            }
        }
        let _ = child.kill();
        let _ = child.wait();
        panic!("hub `{name}` did not join the network; it said {said:?}");
    }

    /// The hub's pid.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// Worker processes of this hub (its living children: zombies not yet reaped count as
    /// gone).
    pub fn worker_count(&self) -> usize {
        crate::living_children(self.pid())
    }
}

impl Drop for RemoteHub {
    fn drop(&mut self) {
        let _ = Command::new("kill")
            .args(["-CONT", &self.pid().to_string()])
            .status();
        let _ = self.child.kill();
        let _ = self.child.wait();
        let _ = envhub_shm::remove_namespace(&self.namespace);
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The network settings of a client that reaches `hubs` by their endpoints, multicast off,
/// pinning hub identities in a file of this test process ([`known_hubs`]).
pub fn net_to(hubs: &[&RemoteHub]) -> NetConfig {
    NetConfig {
        connect: hubs.iter().map(|h| h.endpoint.clone()).collect(),
        multicast: Some(false),
        known_hubs: Some(known_hubs()),
        ..NetConfig::default()
    }
}

/// The `known_hubs` file of this test process: in the config folder the test binary made
/// for it (`XDG_CONFIG_HOME`, removed when it exits), never the user's (fake hubs have new
/// identities in every run).
pub fn known_hubs() -> std::path::PathBuf {
    let home = std::env::var_os("XDG_CONFIG_HOME")
        .filter(|_| std::env::var_os("ENVHUB_E2E_CONFIG_HOME").is_some())
        .expect("the e2e binary gives each of its processes a config folder of its own");
    std::path::PathBuf::from(home)
        .join("envhub")
        .join("known_hubs")
}

/// A client hub (own namespace, short timeouts) that reaches `hubs`.
pub fn client(name: &str, hubs: &[&RemoteHub]) -> Hub {
    Hub::new(Registry::builtin())
        .with_options(SessionOptions {
            namespace: format!("e2e_client_{name}_{}_", std::process::id()),
            step_timeout: Duration::from_secs(10),
            start_timeout: Duration::from_secs(30),
            ..SessionOptions::default()
        })
        .with_network(net_to(hubs))
}
