//! Hubs on separate "machines": two network namespaces joined by a veth pair, every process in
//! its own mount and IPC namespace with fresh tmpfs on `/dev/shm` and `/tmp` (a network
//! namespace alone shares them, and iceoryx2 would join the two sides through shared memory).
//! Only Zenoh over the veth links them: multicast scouting, a cut link, a short flap.
//!
//! Needs root (network namespaces, mounts), `ip` and `unshare`; skipped with the reason
//! otherwise, unless `ENVHUB_NETNS_REQUIRED` is set (then a skip is a failure). CI runs as
//! root, so CI runs them. A failure of envhub itself always fails the test.

use envhub_e2e::binary;
use std::path::PathBuf;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// Set (non-empty) to turn a skip into a failure, where the tests must run.
const REQUIRED: &str = "ENVHUB_NETNS_REQUIRED";

/// Run inside each namespace: fresh `/dev/shm` and `/tmp`, then the command (`$@`). The
/// folders under `/tmp` named in `ENVHUB_NETNS_KEEP` (`:`-separated: a checkout or a venv that
/// lives there, as CI's may) stay visible at their paths: bound aside before the fresh `/tmp`
/// hides them, then moved back into it.
const ISOLATE: &str = r#"set -e
mount -t tmpfs tmpfs /dev/shm
IFS=:
i=0
for d in $ENVHUB_NETNS_KEEP; do mkdir -p /dev/shm/.keep$i; mount --bind "$d" /dev/shm/.keep$i; i=$((i+1)); done
mount -t tmpfs tmpfs /tmp
i=0
for d in $ENVHUB_NETNS_KEEP; do mkdir -p "$d"; mount --move /dev/shm/.keep$i "$d"; rmdir /dev/shm/.keep$i; i=$((i+1)); done
unset IFS ENVHUB_NETNS_KEEP
exec "$@""#;

/// The top folders under `/tmp` that hold the binaries or the Python interpreter the hubs use
/// (`/tmp/ci/checkout/...` → `/tmp/ci`), for `ENVHUB_NETNS_KEEP`.
fn kept_under_tmp() -> String {
    let mut keep: Vec<PathBuf> = Vec::new();
    for path in [envhub_e2e::bin_dir(), envhub_hub::python_interpreter()] {
        let mut parts = path.components();
        let top = match (parts.next(), parts.next(), parts.next()) {
            (Some(std::path::Component::RootDir), Some(tmp), Some(first))
                if tmp.as_os_str() == "tmp" =>
            {
                PathBuf::from("/tmp").join(first)
            }
            _ => continue,
        };
        if !keep.contains(&top) {
            keep.push(top);
        }
    }
    keep.iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(":")
}

/// Envhub settings from the caller's environment that would reach outside the namespaces or
/// change what runs.
const SCRUBBED: [&str; 6] = [
    envhub_hub::ENVHUB_CONNECT,
    envhub_hub::ENVHUB_MULTICAST,
    envhub_hub::env_vars::ENVHUB_HUB,
    envhub_hub::env_vars::ENVHUB_NAMESPACE,
    envhub_hub::env_vars::ENVHUB_CONFIG,
    envhub_hub::env_vars::ENVHUB_ADAPTERS,
];

/// Prints why `test` cannot run here and returns false (panics if `ENVHUB_NETNS_REQUIRED`).
fn skip(test: &str, why: &str) -> bool {
    assert!(
        std::env::var_os(REQUIRED).is_none_or(|v| v.is_empty()),
        "{test}: network namespace tests are required ({REQUIRED}) but {why}"
    );
    eprintln!("skipped {test}: {why}");
    false
}

/// Whether this machine can run the namespace tests (root, `ip`, `unshare`).
fn supported(test: &str) -> bool {
    // SAFETY: geteuid has no preconditions.
    if unsafe { libc::geteuid() } != 0 {
        return skip(
            test,
            "needs root (CAP_NET_ADMIN) to create network namespaces",
        );
    }
    for (tool, package) in [("ip", "iproute2"), ("unshare", "util-linux")] {
        let found = Command::new(tool)
            .arg("-V")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success());
        if !found {
            return skip(test, &format!("`{tool}` is missing (package {package})"));
        }
    }
    true
}

/// An error of the set-up that says the kernel or the container refuses it, not a mistake.
fn refused(stderr: &str) -> bool {
    let s = stderr.to_lowercase();
    ["not permitted", "permission denied", "not supported"]
        .iter()
        .any(|n| s.contains(n))
}

/// Two "machines": namespaces `ns[0]` and `ns[1]`, joined by veth `veth[0]`–`veth[1]` with
/// addresses `addr[0]`, `addr[1]`. Dropping it kills every process in them and deletes them
/// (the veth pair and the tmpfs mounts go with them).
pub(crate) struct TwoHosts {
    pub(crate) ns: [String; 2],
    veth: [String; 2],
    pub(crate) addr: [String; 2],
    /// Logs of the processes, on the host.
    pub(crate) dir: PathBuf,
}

impl TwoHosts {
    /// Creates the namespaces; `None` (with the reason printed) where this machine cannot.
    pub(crate) fn new(test: &str) -> Option<TwoHosts> {
        if !supported(test) {
            return None;
        }
        // Unique per test process and per call, so parallel tests do not clash (a name over
        // 15 bytes is refused for an interface).
        static COUNT: AtomicU32 = AtomicU32::new(0);
        let pid = std::process::id();
        let k = COUNT.fetch_add(1, Ordering::Relaxed);
        let tag = format!("{}x{k}", pid % 10_000_000);
        let subnet = format!("10.250.{}", (pid + k) % 250 + 1);
        let hosts = TwoHosts {
            ns: [format!("ehnet{tag}a"), format!("ehnet{tag}b")],
            veth: [format!("ehv{tag}a"), format!("ehv{tag}b")],
            addr: [format!("{subnet}.1"), format!("{subnet}.2")],
            dir: std::env::temp_dir().join(format!("e2e-netns-{tag}")),
        };
        std::fs::create_dir_all(&hosts.dir).expect("temp dir");
        // Left over by an earlier process with this pid that was killed: ours by name.
        for ns in &hosts.ns {
            let _ = ip(&["netns", "del", ns]);
        }
        let [a, b] = &hosts.ns;
        let [va, vb] = &hosts.veth;
        let mut steps: Vec<Vec<&str>> = vec![
            vec!["netns", "add", a],
            vec!["netns", "add", b],
            vec![
                "link", "add", va, "netns", a, "type", "veth", "peer", "name", vb, "netns", b,
            ],
        ];
        let cidr = [
            format!("{}/24", hosts.addr[0]),
            format!("{}/24", hosts.addr[1]),
        ];
        for ((ns, veth), cidr) in hosts.ns.iter().zip(&hosts.veth).zip(&cidr) {
            steps.push(vec!["-n", ns, "addr", "add", cidr, "dev", veth]);
            steps.push(vec!["-n", ns, "link", "set", "lo", "up"]);
            steps.push(vec!["-n", ns, "link", "set", veth, "up"]);
        }
        for args in steps {
            if let Err(e) = ip(&args) {
                if refused(&e) {
                    skip(test, &format!("`ip {}` was refused: {e}", args.join(" ")));
                    return None;
                }
                panic!("`ip {}` failed: {e}", args.join(" "));
            }
        }
        // The kernel reports a new link running (carrier) up to a second after `up`; a Zenoh
        // session opened before that finds no multicast interface ("Will use [::]") and never
        // scouts over the veth.
        for (ns, veth) in hosts.ns.iter().zip(&hosts.veth) {
            hosts.wait_running(ns, veth);
        }
        // A mount namespace with its own tmpfs needs CAP_SYS_ADMIN, which some containers
        // withhold even from root.
        let probe = Command::new("ip")
            .args(["netns", "exec", a, "unshare", "--mount", "--ipc"])
            .args(["sh", "-c", ISOLATE, "isolate", "true"])
            .output()
            .expect("ip runs");
        if !probe.status.success() {
            let e = String::from_utf8_lossy(&probe.stderr).trim().to_string();
            if refused(&e) {
                skip(
                    test,
                    &format!("a private /dev/shm and /tmp was refused: {e}"),
                );
                return None;
            }
            panic!("a private /dev/shm and /tmp failed: {e}");
        }
        Some(hosts)
    }

    /// Starts `envhub ARGS` on host `side`, in its own `/dev/shm` and `/tmp`; `tag` names its
    /// logs.
    pub(crate) fn envhub(&self, side: usize, tag: &str, args: &[&str]) -> Proc {
        self.envhub_with(side, tag, args, &[])
    }

    /// [`TwoHosts::envhub`] with `vars` added to its environment (one with an empty value is
    /// removed from it instead).
    pub(crate) fn envhub_with(
        &self,
        side: usize,
        tag: &str,
        args: &[&str],
        vars: &[(&str, &str)],
    ) -> Proc {
        let out = self.dir.join(format!("{tag}.out"));
        let err = self.dir.join(format!("{tag}.err"));
        let mut cmd = Command::new("ip");
        cmd.args([
            "netns",
            "exec",
            &self.ns[side],
            "unshare",
            "--mount",
            "--ipc",
        ])
        .args(["sh", "-c", ISOLATE, "isolate"])
        .arg(binary("envhub"))
        .env("ENVHUB_NETNS_KEEP", kept_under_tmp())
        .args(args)
        .stdin(Stdio::null())
        .stdout(std::fs::File::create(&out).expect("log file"))
        .stderr(std::fs::File::create(&err).expect("log file"));
        for var in SCRUBBED {
            cmd.env_remove(var);
        }
        if side == 1 {
            // The clients' host finds hub `a` across the veth by multicast: a client scouts
            // the LAN only when told to (it trusts this one).
            cmd.env(envhub_hub::ENVHUB_MULTICAST, "1");
        }
        for (var, value) in vars {
            if value.is_empty() {
                cmd.env_remove(var);
            } else {
                cmd.env(var, value);
            }
        }
        // `ip netns exec`, `unshare` and `sh` each exec the next: the child is envhub itself
        // (its workers are its children, its namespaces are the hub's).
        let child = cmd.spawn().expect("ip netns exec starts");
        Proc {
            child,
            out,
            err,
            what: format!("`envhub {}` on {}", args.join(" "), self.ns[side]),
        }
    }

    /// Starts hub `a` on host 0 with multicast scouting on, listening on the veth; returns
    /// once it says it is on the network. No multicast route is needed: Zenoh scouts on the
    /// interface it picks, the veth (the only other one is loopback).
    fn hub_a(&self) -> Proc {
        let listen = format!("tcp/{}:7447", self.addr[0]);
        // Beyond loopback without credentials: allowed by the flag, with a warning; scouting
        // by a flag of its own.
        let mut hub = self.envhub(
            0,
            "hub-a",
            &[
                "serve",
                "--name",
                "a",
                "--listen",
                &listen,
                "--insecure-listen",
                "--multicast-scouting",
            ],
        );
        hub.wait_for_line("on the network as hub `a`", Duration::from_secs(15));
        assert!(
            hub.stderr().contains("without credentials")
                && hub.stderr().contains("--insecure-listen"),
            "the hub open to the network without credentials printed no warning; {}",
            hub.said()
        );
        // The isolation holds: the hub sees other network and mount namespaces than ours.
        let ns_of = |pid: &str, kind: &str| std::fs::read_link(format!("/proc/{pid}/ns/{kind}"));
        for kind in ["net", "mnt", "ipc"] {
            let pid = hub.child.id().to_string();
            assert_ne!(
                ns_of(&pid, kind).unwrap(),
                ns_of("self", kind).unwrap(),
                "the hub shares this test's {kind} namespace"
            );
        }
        hub
    }

    /// Starts `envhub serve --name NAME ARGS` on host 0 and waits (at most 15 s) until it
    /// says it is on the network.
    fn hub_on_a(&self, name: &str, args: &[&str]) -> Proc {
        let mut all = vec!["serve", "--name", name];
        all.extend_from_slice(args);
        let mut hub = self.envhub(0, &format!("hub-{name}"), &all);
        hub.wait_for_line(
            &format!("on the network as hub `{name}`"),
            Duration::from_secs(15),
        );
        hub
    }

    /// Waits (at most 5 s, else fails) until `veth` in `ns` is up and running.
    fn wait_running(&self, ns: &str, veth: &str) {
        let deadline = Instant::now() + Duration::from_secs(5);
        loop {
            let out = Command::new("ip")
                .args(["-n", ns, "-o", "link", "show", "dev", veth])
                .output()
                .expect("ip runs");
            let line = String::from_utf8_lossy(&out.stdout).to_string();
            if line.contains("LOWER_UP") && line.contains("state UP") {
                return;
            }
            assert!(
                Instant::now() < deadline,
                "{veth} in {ns} not running after 5 s: {line}"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Takes the veth down (`up` false) or up again, from host 0's side.
    fn link(&self, up: bool) {
        let state = if up { "up" } else { "down" };
        ip(&["-n", &self.ns[0], "link", "set", &self.veth[0], state])
            .unwrap_or_else(|e| panic!("cannot set the link {state}: {e}"));
    }

    /// `envhub hubs --json` on host 1 (multicast turned on, no endpoint): the names it lists, and
    /// what it said on stderr.
    fn hubs_seen_from_b(&self, tag: &str) -> (Vec<String>, String) {
        let (_, out, err) = self.envhub(1, tag, &["hubs", "--json"]).finish(20);
        // No hub found is an empty listing and a non-zero exit: both mean "not yet".
        let listed: Vec<serde_json::Value> = serde_json::from_str(&out).unwrap_or_default();
        let names = listed
            .iter()
            .filter_map(|h| h["name"].as_str().map(String::from))
            .collect();
        (names, err)
    }

    /// Polls `envhub hubs` on host 1 until it lists `a`; the time from `since`, or a
    /// failure after `limit`.
    fn wait_for_a(&self, since: Instant, limit: Duration, tag: &str) -> Duration {
        let mut tries = 0;
        loop {
            tries += 1;
            let (seen, err) = self.hubs_seen_from_b(&format!("{tag}-{tries}"));
            let took = since.elapsed();
            if seen.iter().any(|n| n == "a") {
                return took;
            }
            assert!(
                took < limit,
                "hub `a` not listed from the other host after {took:?} ({tries} tries, the last \
                 saw {seen:?} and said {err:?})"
            );
        }
    }
}

impl Drop for TwoHosts {
    fn drop(&mut self) {
        // Processes keep a deleted namespace alive: kill everything in ours first (only ours:
        // the namespaces were made by this test).
        for ns in &self.ns {
            if let Ok(out) = Command::new("ip").args(["netns", "pids", ns]).output() {
                for pid in String::from_utf8_lossy(&out.stdout).split_whitespace() {
                    if let Ok(pid) = pid.parse::<i32>() {
                        // SAFETY: kill with a pid and a signal number has no memory effects.
                        unsafe { libc::kill(pid, libc::SIGKILL) };
                    }
                }
            }
        }
        for ns in &self.ns {
            let _ = ip(&["netns", "del", ns]);
        }
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Runs `ip ARGS`; its stderr on failure.
fn ip(args: &[&str]) -> Result<(), String> {
    let out = Command::new("ip")
        .args(args)
        .output()
        .map_err(|e| e.to_string())?;
    if out.status.success() {
        Ok(())
    } else {
        Err(String::from_utf8_lossy(&out.stderr).trim().to_string())
    }
}

/// A process in a namespace, its output in files (nothing blocks on a full pipe). Killed
/// when dropped.
pub(crate) struct Proc {
    child: Child,
    out: PathBuf,
    err: PathBuf,
    what: String,
}

impl Proc {
    pub(crate) fn stdout(&self) -> String {
        std::fs::read_to_string(&self.out).unwrap_or_default()
    }

    pub(crate) fn stderr(&self) -> String {
        std::fs::read_to_string(&self.err).unwrap_or_default()
    }

    pub(crate) fn said(&self) -> String {
        format!("{} said:\n{}{}", self.what, self.stdout(), self.stderr())
    }

    /// Waits (at most `limit`) until it prints `line` on stdout; fails at once if it ends.
    pub(crate) fn wait_for_line(&mut self, line: &str, limit: Duration) {
        let deadline = Instant::now() + limit;
        while !self.stdout().contains(line) {
            assert!(self.ended().is_none(), "{}", self.said());
            assert!(
                Instant::now() < deadline,
                "no `{line}` after {limit:?}; {}",
                self.said()
            );
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Its exit status if it has ended.
    pub(crate) fn ended(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().expect("try_wait")
    }

    /// Waits (at most `limit_s` seconds, else fails) for it to end: status, stdout, stderr.
    pub(crate) fn finish(mut self, limit_s: u64) -> (ExitStatus, String, String) {
        let deadline = Instant::now() + Duration::from_secs(limit_s);
        loop {
            if let Some(status) = self.ended() {
                return (status, self.stdout(), self.stderr());
            }
            assert!(
                Instant::now() < deadline,
                "{} still running after {limit_s} s; {}",
                self.what,
                self.said()
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// Child processes (a hub's workers).
    fn children(&self) -> usize {
        envhub_e2e::living_children(self.child.id())
    }

    /// Waits (at most 30 s) until hub `self` runs workers: a client's session has started.
    fn wait_for_workers(&self, client: &mut Proc) {
        let deadline = Instant::now() + Duration::from_secs(30);
        while self.children() == 0 {
            assert!(client.ended().is_none(), "{}", client.said());
            assert!(
                Instant::now() < deadline,
                "no session on hub `a` after 30 s; {}",
                client.said()
            );
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        // A failing test shows what every process of it said (the hub's log included).
        if std::thread::panicking() {
            let said = self.said();
            let tail = said.len().saturating_sub(4000);
            let tail = (tail..said.len())
                .find(|i| said.is_char_boundary(*i))
                .unwrap_or(0);
            eprintln!("--- {}", &said[tail..]);
        }
    }
}

/// The JSON line of `envhub run --json`.
pub(crate) fn run_summary(
    status: ExitStatus,
    out: &str,
    err: &str,
    what: &str,
) -> serde_json::Value {
    assert!(status.success(), "{what} failed ({status}):\n{out}{err}");
    serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{what} printed {out:?}: {e}"))
}

#[test]
fn netns_a_hub_is_found_by_multicast_across_the_veth() {
    let Some(hosts) = TwoHosts::new("netns_a_hub_is_found_by_multicast_across_the_veth") else {
        return;
    };
    let _hub = hosts.hub_a();
    let started = Instant::now();
    let took = hosts.wait_for_a(started, Duration::from_secs(5), "hubs");
    eprintln!("hub `a` found by multicast from the other namespace in {took:?}");
}

#[test]
fn netns_a_cut_link_loses_the_hub_within_two_seconds_and_it_comes_back() {
    let test = "netns_a_cut_link_loses_the_hub_within_two_seconds_and_it_comes_back";
    let Some(hosts) = TwoHosts::new(test) else {
        return;
    };
    let hub = hosts.hub_a();
    let mut client = hosts.envhub(
        1,
        "run-forever",
        &[
            "run",
            "gym-cartpole",
            "--hub",
            "a",
            "--num-envs",
            "4",
            "--steps",
            "1000000000000",
        ],
    );
    hub.wait_for_workers(&mut client);
    std::thread::sleep(Duration::from_millis(300));
    assert!(client.ended().is_none(), "{}", client.said());

    let cut = Instant::now();
    hosts.link(false);
    let status = loop {
        if let Some(status) = client.ended() {
            break status;
        }
        assert!(
            cut.elapsed() < Duration::from_secs(10),
            "the client still runs 10 s after the link was cut"
        );
        std::thread::sleep(Duration::from_millis(2));
    };
    let lost_after = cut.elapsed();
    let err = client.stderr();
    assert!(
        !status.success(),
        "the client ended well: {}",
        client.said()
    );
    assert!(
        err.contains("hub `a` (envs 0..4) was lost"),
        "expected HubLost naming hub `a`; {}",
        client.said()
    );
    assert!(
        lost_after < Duration::from_secs(2),
        "hub `a` reported lost {lost_after:?} after the cut"
    );
    eprintln!("link cut: hub `a` reported lost after {lost_after:?}");
    // Its side too: the client's token expires there, and the hub ends the session.
    while hub.children() > 0 {
        assert!(
            cut.elapsed() < Duration::from_secs(5),
            "hub `a` still runs the cut-off client's workers 5 s after the cut"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
    eprintln!(
        "link cut: hub `a` ended the client's session after {:?}",
        cut.elapsed()
    );

    let restored = Instant::now();
    hosts.link(true);
    // A process started before the kernel reports the link running again would find no
    // multicast interface (see `TwoHosts::new`): wait for it, then ask.
    for (ns, veth) in hosts.ns.iter().zip(&hosts.veth) {
        hosts.wait_running(ns, veth);
    }
    let running_after = restored.elapsed();
    let back_after = hosts.wait_for_a(restored, Duration::from_secs(5), "hubs-back");
    eprintln!(
        "link restored: running again after {running_after:?}, hub `a` listed again after {back_after:?}"
    );
    let (status, out, err) = hosts
        .envhub(
            1,
            "run-after",
            &[
                "run",
                "gym-cartpole",
                "--hub",
                "a",
                "--num-envs",
                "4",
                "--steps",
                "2000",
                "--json",
            ],
        )
        .finish(30);
    let summary = run_summary(
        status,
        &out,
        &err,
        "a run on hub `a` after the link came back",
    );
    assert_eq!(summary["steps"], 2000);
}

/// How long a long rollout may take before it counts as hung (not a speed bound).
const PATIENT_SECS: u64 = 240;

#[test]
fn netns_a_link_flap_shorter_than_the_lease_loses_no_step() {
    let test = "netns_a_link_flap_shorter_than_the_lease_loses_no_step";
    let Some(hosts) = TwoHosts::new(test) else {
        return;
    };
    let hub = hosts.hub_a();
    // Long enough (a few seconds over the veth) that the flap falls in the middle.
    fn rollout(hub: &str) -> Vec<&str> {
        vec![
            "run",
            "gym-cartpole",
            "--hub",
            hub,
            "--num-envs",
            "4",
            "--seed",
            "3",
            "--steps",
            "100000",
            "--json",
        ]
    }
    // Debug logs of the remote link: they show whether the client had to resend a request.
    let mut client = hosts.envhub_with(
        1,
        "run-flap",
        &rollout("a"),
        &[(
            envhub_hub::env_vars::ENVHUB_LOG,
            "warn,envhub_hub::remote=debug",
        )],
    );
    hub.wait_for_workers(&mut client);
    std::thread::sleep(Duration::from_millis(300));
    assert!(client.ended().is_none(), "{}", client.said());
    hosts.link(false);
    let down = Instant::now();
    std::thread::sleep(Duration::from_millis(300));
    hosts.link(true);
    let flap = down.elapsed();
    assert!(
        client.ended().is_none(),
        "the rollout ended before the link came back: {}",
        client.said()
    );
    // Well under the lease (1000 ms), or the test would be about expiry, not a flap.
    assert!(
        flap < Duration::from_millis(700),
        "the flap lasted {flap:?}"
    );
    // Bounds against a hang only: two CPU burners beside the suite stretch this rollout
    // from ~3 s to over a minute (25,000 round trips, each waiting for a core).
    let (status, out, log) = client.finish(PATIENT_SECS);
    let remote = run_summary(status, &out, &log, "the rollout over the flapping link");
    let (status, out, err) = hosts
        .envhub(1, "run-local", &rollout("local"))
        .finish(PATIENT_SECS);
    let local = run_summary(status, &out, &err, "the same rollout on one machine");
    for key in ["steps", "episodes", "mean_return"] {
        assert_eq!(
            remote[key], local[key],
            "{key}: over the flapping link {remote}, locally {local}"
        );
    }
    // The TCP link rides out the flap (retransmits): no lease expiry, and at most a resend.
    let resends = log.matches("sending again").count();
    eprintln!(
        "link down for {flap:?} mid-rollout: completed in {:.2} s with {resends} resent requests, same as locally ({} episodes, mean return {})",
        remote["seconds"], local["episodes"], local["mean_return"]
    );
}

/// A peer on host 1's LAN, as an attacker runs one (a default Zenoh peer: scouting, gossip and
/// autoconnect on, no credentials, listening on the veth), never reaches a hub on host 0 that
/// `--insecure-listen` opened without `--multicast-scouting`: neither by its scouts nor by the
/// hub's (a hub never connects to what scouting names). With the flag, the same peer finds the
/// hub: the probe can see a hub that is reachable.
#[test]
fn netns_a_lan_peer_never_reaches_an_insecure_listen_hub_unless_it_scouts() {
    let test = "netns_a_lan_peer_never_reaches_an_insecure_listen_hub_unless_it_scouts";
    let Some(hosts) = TwoHosts::new(test) else {
        return;
    };
    let listen_lan = format!("tcp/{}:7447", hosts.addr[0]);
    let (peer_addr, lure) = (
        hosts.addr[1].clone(),
        format!("envhub/hub/lure-{}", std::process::id()),
    );
    // The attacker lives on its own thread in host 1's namespace (this thread stays here).
    let (to_peer, jobs) = std::sync::mpsc::channel::<(String, bool)>();
    let (to_test, seen) = std::sync::mpsc::channel();
    let enter = hosts.ns[1].clone();
    let attacker = std::thread::spawn(move || {
        let hosts_ns = format!("/var/run/netns/{enter}");
        let file = std::fs::File::open(&hosts_ns).expect("namespace file");
        use std::os::fd::AsRawFd;
        // SAFETY: setns with an open namespace file and its type: it changes this thread's
        // network namespace only (the Zenoh runtime threads it starts later inherit it).
        assert_eq!(
            unsafe { libc::setns(file.as_raw_fd(), libc::CLONE_NEWNET) },
            0
        );
        for (hub, reachable) in jobs {
            // A fresh peer per hub, as one that joins the LAN after the hub started.
            let mut config = zenoh::Config::default();
            config
                .insert_json5("listen/endpoints", &format!("[\"tcp/{peer_addr}:0\"]"))
                .unwrap();
            let peer = zenoh::open(config)
                .wait()
                .expect("the attacker's peer opens");
            let _lure = peer.liveliness().declare_token(&lure).wait().unwrap();
            // Scouting runs for seconds: a hub that scouts or answers scouts has time to be
            // found (a reachable one is waited for, up to 20 s).
            let deadline = Instant::now() + Duration::from_secs(if reachable { 20 } else { 5 });
            let mut got = envhub_e2e::intruder::probe(&peer, &hub);
            while Instant::now() < deadline && (!reachable || got.peers.is_empty()) {
                std::thread::sleep(Duration::from_millis(250));
                got = envhub_e2e::intruder::probe(&peer, &hub);
            }
            let tokens: Vec<String> = got.tokens.into_iter().filter(|t| *t != lure).collect();
            to_test.send((got.peers, tokens, got.open_answers)).unwrap();
        }
    });
    let cases: [(&str, Vec<&str>, bool); 4] = [
        ("plain", vec!["--insecure-listen"], false),
        (
            "loopback",
            vec!["--insecure-listen", "--listen", "tcp/127.0.0.1:7448"],
            false,
        ),
        (
            "lan",
            vec!["--insecure-listen", "--listen", &listen_lan],
            false,
        ),
        (
            "scouting",
            vec![
                "--insecure-listen",
                "--listen",
                &listen_lan,
                "--multicast-scouting",
            ],
            true,
        ),
    ];
    for (name, args, reachable) in cases {
        let hub = hosts.hub_on_a(name, &args);
        let said = hub.stderr();
        if !reachable {
            assert!(
                said.contains("loopback only") || said.contains("neither sends nor answers"),
                "hub `{name}` did not say it keeps off scouting; {}",
                hub.said()
            );
        }
        to_peer.send((name.to_string(), reachable)).unwrap();
        let (peers, tokens, opens) = seen.recv().expect("the attacker answers");
        eprintln!(
            "hub `{name}`: the LAN peer got links {peers:?}, tokens {tokens:?}, {opens} open answers"
        );
        if reachable {
            assert!(
                !peers.is_empty() && tokens.iter().any(|t| t == &format!("envhub/hub/{name}")),
                "the control failed: a hub told to scout was not found by the LAN peer; {}",
                hub.said()
            );
        } else {
            assert!(
                peers.is_empty() && tokens.is_empty() && opens == 0,
                "hub `{name}` ({args:?}) was reached by a LAN peer: links {peers:?}, tokens \
                 {tokens:?}, {opens} open answers; {}",
                hub.said()
            );
        }
        drop(hub);
    }
    drop(to_peer);
    attacker.join().expect("the attacker thread");
}
