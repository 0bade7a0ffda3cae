//! The engine alone: a session over real `envhub-worker` processes started by a launcher of
//! the test's own (the engine takes any [`Launch`]), with no hub, catalog or network.

use envhub_core::EnvConfig;
use envhub_protocol::{HubError, Route};
use envhub_session::{Launch, Process, SessionOptions, VecEnv};
use envhub_shm::{ReadySpec, WorkerJob, WorkerReply};
use std::io::BufRead;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// The release worker binary the workspace build put beside the tests.
fn worker_binary() -> Option<PathBuf> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../target/release/envhub-worker");
    path.exists().then_some(path)
}

/// Starts `envhub-worker serve` as a child and reads its ready line; counts its launches.
struct ChildLauncher {
    binary: PathBuf,
    launched: std::sync::atomic::AtomicUsize,
}

struct ChildProcess(Child);

impl Process for ChildProcess {
    fn pid(&self) -> u32 {
        self.0.id()
    }
    fn kill(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
    fn kill_now(&mut self) {
        self.kill();
    }
    fn exit_status(&mut self, timeout: Duration) -> Option<String> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Ok(Some(status)) = self.0.try_wait() {
                return Some(status.to_string());
            }
            if Instant::now() >= deadline {
                return None;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

impl Launch for ChildLauncher {
    fn launch(
        &self,
        job: &WorkerJob,
        _start_timeout: Duration,
    ) -> Result<(Box<dyn Process>, ReadySpec), HubError> {
        self.launched
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let mut child = Command::new(&self.binary)
            .arg("serve")
            .arg("--job")
            .arg(serde_json::to_string(job).unwrap())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .spawn()
            .map_err(|e| HubError::MakeFailed(e.to_string()))?;
        let mut line = String::new();
        std::io::BufReader::new(child.stdout.take().unwrap())
            .read_line(&mut line)
            .map_err(|e| HubError::MakeFailed(e.to_string()))?;
        match serde_json::from_str(&line).map_err(|e| HubError::MakeFailed(e.to_string()))? {
            WorkerReply::Ready(spec) => Ok((Box::new(ChildProcess(child)), spec)),
            WorkerReply::Error(message) => Err(HubError::MakeFailed(message)),
        }
    }
}

fn options() -> SessionOptions {
    SessionOptions {
        namespace: format!("envhub-engine-test-{}", std::process::id()),
        ..SessionOptions::default()
    }
}

fn cartpole(num_envs: usize, workers: usize) -> Route {
    let mut config = EnvConfig {
        num_envs,
        ..EnvConfig::default()
    };
    config.workers = Some(workers);
    config.max_episode_steps = Some(500);
    Route {
        adapter: "classic_control".into(),
        env_id: "CartPole-v1".into(),
        config,
        python: None,
    }
}

/// Steps `num_envs` CartPoles spread over `workers` processes and returns the observations
/// and rewards of every step.
fn rollout(
    launcher: &Arc<dyn Launch>,
    num_envs: usize,
    workers: usize,
) -> Vec<(Vec<f32>, Vec<f64>)> {
    let mut vec = VecEnv::start("cartpole", cartpole(num_envs, workers), options(), launcher)
        .expect("the session starts");
    assert_eq!(vec.num_workers(), workers);
    let mut out = Vec::new();
    let reset = vec.reset(Some(7)).expect("reset");
    out.push((reset.obs_f32().to_vec(), reset.rewards.to_vec()));
    for t in 0..200 {
        let actions: Vec<i64> = (0..num_envs).map(|e| ((t + e) % 2) as i64).collect();
        let batch = vec.step_i64(&actions).expect("step");
        out.push((batch.obs_f32().to_vec(), batch.rewards.to_vec()));
    }
    vec.close();
    out
}

#[test]
fn a_session_over_the_tests_own_launcher_is_the_same_whatever_the_workers() {
    let Some(binary) = worker_binary() else {
        if std::env::var_os("ENVHUB_MUJOCO_REQUIRED").is_some() {
            panic!("target/release/envhub-worker is missing; `make build` builds it");
        }
        eprintln!("skipped: target/release/envhub-worker is missing (`make build` builds it)");
        return;
    };
    let launcher = Arc::new(ChildLauncher {
        binary,
        launched: Default::default(),
    });
    let dyn_launcher: Arc<dyn Launch> = launcher.clone();
    let one = rollout(&dyn_launcher, 6, 1);
    let three = rollout(&dyn_launcher, 6, 3);
    assert_eq!(
        launcher.launched.load(std::sync::atomic::Ordering::Relaxed),
        4
    );
    assert_eq!(
        one, three,
        "1 worker and 3 workers step the same envs alike"
    );
    assert!(one.iter().any(|(_, r)| r.iter().all(|&r| r == 1.0)));
}
