//! Helpers for envhub's end-to-end tests: an isolated hub per test and the built binaries.

pub mod flood;
pub mod intruder;
pub mod remote;

use envhub_hub::{Hub, HubError, Registry, SessionOptions};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The folder holding the workspace's built binaries (`target/<profile>`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let deps = exe.parent().expect("deps folder");
    deps.parent().expect("profile folder").to_path_buf()
}

/// Path of a workspace binary; panics with the fix if it was not built.
pub fn binary(name: &str) -> PathBuf {
    let path = bin_dir().join(name);
    assert!(
        path.is_file(),
        "{} is missing: run `cargo build --workspace --bins` first (`make test` does)",
        path.display()
    );
    path
}

/// A hub in its own iceoryx2 namespace, so tests can run in parallel. Removes what the
/// namespace left in shared memory when dropped.
pub struct TestHub {
    /// The hub.
    pub hub: Hub,
    /// Its iceoryx2 namespace.
    pub namespace: String,
}

impl TestHub {
    /// A hub over the built-in registry with a short step timeout.
    pub fn new(name: &str) -> TestHub {
        Self::with(name, |_| {})
    }

    /// A hub whose session options `tweak` adjusts.
    pub fn with(name: &str, tweak: impl FnOnce(&mut SessionOptions)) -> TestHub {
        Self::over(name, Registry::builtin(), tweak)
    }

    /// A hub over `registry` whose session options `tweak` adjusts.
    pub fn over(
        name: &str,
        registry: Registry,
        tweak: impl FnOnce(&mut SessionOptions),
    ) -> TestHub {
        // The hub finds the worker next to the test binary's folder; fail early and clearly
        // if it was not built.
        binary("envhub-worker");
        let namespace = format!("e2e_{name}_{}_", std::process::id());
        let mut options = SessionOptions {
            namespace: namespace.clone(),
            // Far above a step or a start on a slow, busy machine: a test that reaches either
            // limit fails on what it says, never on a clock read in the test.
            step_timeout: Duration::from_secs(10),
            start_timeout: Duration::from_secs(60),
            ..SessionOptions::default()
        };
        tweak(&mut options);
        TestHub {
            hub: Hub::new(registry).with_options(options),
            namespace,
        }
    }
}

impl Drop for TestHub {
    fn drop(&mut self) {
        let _ = envhub_shm::remove_namespace(&self.namespace);
    }
}

/// Living child processes of `pid` (zombies not yet reaped count as gone).
pub fn living_children(pid: u32) -> usize {
    let me = pid.to_string();
    std::fs::read_dir("/proc")
        .map(|d| {
            d.filter_map(Result::ok)
                .filter_map(|e| std::fs::read_to_string(e.path().join("stat")).ok())
                .filter(|stat| {
                    // `pid (comm) state ppid ...`; comm may hold spaces, so read after `)`.
                    stat.rfind(')').is_some_and(|at| {
                        let mut fields = stat[at + 2..].split_whitespace();
                        fields.next() != Some("Z") && fields.next() == Some(me.as_str())
                    })
                })
                .count()
        })
        .unwrap_or(0)
}

/// Files in `/dev/shm` whose names contain `needle`.
pub fn shm_files(needle: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains(needle))
                .collect()
        })
        .unwrap_or_default()
}

/// Whether the Python worker can run: the interpreter the hub starts it with imports the
/// compiled `envhub._envhub`. If not, prints why and returns false so the test skips,
/// unless `ENVHUB_PY_REQUIRED` is set (as `make rust-test` does), when it panics: a missing
/// build must not pass by skipping.
pub fn python_worker_available(test: &str) -> bool {
    let python = envhub_hub::python_interpreter();
    let out = std::process::Command::new(&python)
        .args(["-c", "import envhub._envhub"])
        .output();
    let why = match out {
        Ok(out) if out.status.success() => return true,
        Ok(out) => String::from_utf8_lossy(&out.stderr)
            .lines()
            .last()
            .unwrap_or("")
            .to_string(),
        Err(e) => e.to_string(),
    };
    let reason = format!(
        "`{} -c 'import envhub._envhub'` failed: {why}; run `make py-install`, or set ENVHUB_PYTHON",
        python.display()
    );
    assert!(
        std::env::var_os(envhub_hub::env_vars::ENVHUB_PY_REQUIRED).is_none_or(|v| v.is_empty()),
        "{test}: the Python worker is required (ENVHUB_PY_REQUIRED) but {reason}"
    );
    eprintln!("skipped {test}: {reason}");
    false
}

/// Whether `hub`'s MuJoCo adapter can run here (a worker built with its `mujoco` feature, which
/// finds libmujoco). If not, prints why and returns false so the test skips, unless
/// `ENVHUB_MUJOCO_REQUIRED` is set (as `make rust-test` does, so in CI), when it panics: a
/// worker built without MuJoCo must not pass the MuJoCo tests by skipping them.
pub fn mujoco_available(hub: &envhub_hub::Hub, test: &str) -> bool {
    let adapters = hub.adapters().expect("the adapter catalog");
    let availability = adapters
        .iter()
        .find(|a| a.name == "mujoco")
        .map(|a| a.availability.clone());
    let why = match availability {
        Some(a) if a.is_available() => return true,
        Some(envhub_core::Availability::Unavailable { reason, .. }) => reason,
        _ => "the worker lists no `mujoco` adapter".into(),
    };
    assert!(
        std::env::var_os(envhub_hub::env_vars::ENVHUB_MUJOCO_REQUIRED).is_none_or(|v| v.is_empty()),
        "{test}: MuJoCo is required (ENVHUB_MUJOCO_REQUIRED) but unavailable: {why}\nhint: `make build` builds the worker with the `mujoco` feature and libmujoco"
    );
    eprintln!("skipped {test}: MuJoCo is unavailable: {why}");
    false
}

/// A temp folder holding one Python module (a user adapter for the Python worker), removed
/// when dropped.
pub struct PyModule {
    /// The folder, to put on `PYTHONPATH`.
    pub dir: PathBuf,
}

impl PyModule {
    /// Writes `<module>.py` with `source` into a folder named after `test` and this process.
    pub fn write(test: &str, module: &str, source: &str) -> PyModule {
        let dir = std::env::temp_dir().join(format!("e2e-{test}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        std::fs::write(dir.join(format!("{module}.py")), source).expect("module file");
        PyModule { dir }
    }

    /// This process's `PYTHONPATH` with the folder first.
    pub fn pythonpath(&self) -> std::ffi::OsString {
        let rest = std::env::var_os("PYTHONPATH").unwrap_or_default();
        let paths = std::iter::once(self.dir.clone()).chain(std::env::split_paths(&rest));
        std::env::join_paths(paths).expect("temp dir names hold no `:`")
    }
}

impl Drop for PyModule {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// The lines a helper child (this test binary run again) prints on `out`, up to and with the
/// first that contains `ready`, at most 20 lines (bounded: a child that never says it reads
/// as end of output, and the caller's assertion names what it said instead).
pub fn lines_until_ready(out: &mut impl std::io::BufRead) -> String {
    let mut said = String::new();
    for _ in 0..20 {
        let mut line = String::new();
        let read = out.read_line(&mut line).unwrap();
        said.push_str(&line);
        if read == 0 || line.contains("ready") {
            break;
        }
    }
    said
}

/// How long a test waits for what happens on its own (a process exits, a daemon forgets a
/// worker): far above what it takes on a slow, busy machine, so running out means it never
/// happened. Below nextest's limit (`.config/nextest.toml`), so the failure names what.
pub const PATIENCE: Duration = Duration::from_secs(60);

/// Polls `done` until it holds; panics naming `what` if it still does not after [`PATIENCE`].
pub fn eventually(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + PATIENCE;
    while !done() {
        assert!(Instant::now() < deadline, "{what}: not after {PATIENCE:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Sends SIGKILL to `pid`.
pub fn sigkill(pid: u32) {
    let status = std::process::Command::new("kill")
        .args(["-9", &pid.to_string()])
        .status()
        .unwrap();
    assert!(status.success());
}

/// Kills worker `worker` (process `victim`) with SIGKILL, then calls `step` until it fails:
/// the failure must be `WorkerDied` for that worker and pid, noticed by the hub's watch on the
/// process (its `why` is the exit status), not by the step timeout running out. Returns the
/// error and its `why` for the caller's own checks.
///
/// No clock is read: the watch sees the exit however loaded the machine is, and a hub that
/// noticed only at the step timeout says `step timeout` instead, which fails here.
pub fn kill_worker_expect_died(
    worker: usize,
    victim: u32,
    mut step: impl FnMut() -> Result<(), HubError>,
) -> (HubError, String) {
    sigkill(victim);
    // The worker was idle between steps, so the next step fails; a few tries, not a clock,
    // bound the wait.
    let err = (0..3)
        .find_map(|_| step().err())
        .expect("steps kept succeeding after their worker was killed");
    let why = match &err {
        HubError::WorkerDied {
            worker: w,
            pid,
            why,
            ..
        } => {
            assert_eq!((*w, *pid), (worker, victim));
            why.clone()
        }
        other => panic!("expected WorkerDied, got {other}"),
    };
    assert!(
        why.starts_with("died (") && !why.contains("step timeout"),
        "the death was not noticed by the process watch: {why}"
    );
    (err, why)
}

/// A rollout of `env` as bytes, one row per step (the reset's observations first, then each
/// step's observations, rewards and done flags): reset with `reset_seed`, actions sampled
/// from `action_seed`. Two runs compare bit for bit.
pub fn rollout_bytes(
    env: &mut envhub_hub::VecEnv,
    reset_seed: u64,
    action_seed: u64,
    steps: usize,
) -> Vec<Vec<u8>> {
    use rand::SeedableRng;
    let mut out = vec![env.reset(Some(reset_seed)).unwrap().obs.to_vec()];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(action_seed);
    for _ in 0..steps {
        out.push(step_bytes(env, &mut rng));
    }
    out
}

/// One step with actions drawn from `rng`, as the bytes `rollout_bytes` keeps of it
/// (observations, rewards, done flags).
pub fn step_bytes(env: &mut envhub_hub::VecEnv, rng: &mut rand_chacha::ChaCha8Rng) -> Vec<u8> {
    let actions = env.sample_actions(rng);
    let b = env.step(&actions).unwrap();
    let mut row = b.obs.to_vec();
    row.extend(b.rewards.iter().flat_map(|r| r.to_le_bytes()));
    row.extend(b.terminated.iter().chain(b.truncated).map(|&d| d as u8));
    row
}

/// `envhub hubs --json` run by `binary` with `args`, with `local` as the folder of local hubs
/// and no multicast, endpoints or daemon from the environment, as this user (`uid`: as that
/// one, from `/`); its stdout.
pub fn envhub_hubs(
    binary: &std::path::Path,
    local: &std::path::Path,
    args: &[&str],
    uid: Option<u32>,
) -> String {
    use std::os::unix::process::CommandExt;
    let mut cmd = std::process::Command::new(binary);
    cmd.args(["hubs", "--json"])
        .args(args)
        .env(envhub_hub::local::ENVHUB_LOCAL_HUBS, local)
        .env_remove(envhub_hub::ENVHUB_MULTICAST)
        .env_remove(envhub_hub::ENVHUB_CONNECT)
        .env_remove(envhub_hub::env_vars::ENVHUB_HUB)
        .stdin(std::process::Stdio::null());
    if let Some(uid) = uid {
        cmd.uid(uid).gid(uid).current_dir("/");
    }
    let out = cmd.output().unwrap();
    String::from_utf8_lossy(&out.stdout).to_string()
}

/// A default client's `envhub hubs --json` (this user, the folder of local hubs `local`) until
/// it lists `name`, asked at most 3 times: it waits 2 s for discovery, and a busy machine can
/// take longer to link (a bound of tries, not of time; a client that never finds the hub still
/// fails). The last listing.
pub fn envhub_hubs_listing(local: &std::path::Path, name: &str) -> String {
    let mut listed = String::new();
    for _ in 0..3 {
        listed = envhub_hubs(&binary("envhub"), local, &[], None);
        if listed.contains(name) {
            break;
        }
    }
    listed
}
