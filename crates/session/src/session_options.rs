//! How a session behaves, beyond what `EnvConfig` says about the envs.

use envhub_shm::WaitPolicy;
use std::time::Duration;

/// A wait this long (on average) pays for a wake-up (tens of µs on a VM) many times over.
pub(crate) const BLOCK_BEYOND: Duration = Duration::from_micros(200);

/// CPU cores of this machine (1 if unknown).
pub fn cores() -> usize {
    std::thread::available_parallelism().map_or(1, |n| n.get())
}

/// Worker processes for `num_envs` envs here: the config's, else one per core, at most one
/// per env. (A hub applies the same rule to the envs placed on it.)
pub fn workers_for(config: &envhub_core::EnvConfig, num_envs: usize) -> usize {
    config.workers.unwrap_or_else(|| cores().min(num_envs))
}

/// Options of a session (timeouts, restarts, waiting, shared memory).
#[derive(Clone, Debug, PartialEq)]
pub struct SessionOptions {
    /// A worker that takes longer than this for one request is treated as hung and killed.
    pub step_timeout: Duration,
    /// Time allowed for a worker to create its envs and report ready.
    pub start_timeout: Duration,
    /// Restart a worker that died; its envs come back truncated, with `worker_restarted`
    /// in their info.
    pub restart_on_crash: bool,
    /// Spin at least this long on a response before blocking (0: always block at once).
    pub spin: Duration,
    /// Spin at most this long: the spin adapts to the usual wait up to this bound, so a
    /// step of a millisecond is caught without a wake-up (tens of µs on a VM).
    pub max_spin: Duration,
    /// iceoryx2 namespace (file prefix) of the session's channels and batch slots.
    pub namespace: String,
    /// Shared memory the session's batch slots may take in all. Results that arrays still
    /// view keep their slot; past this cap new results are copied rather than waiting.
    pub pool_bytes: usize,
    /// Bytes per env of typed info columns in the batch slots (0: none). Only a client that
    /// reads them sets it (the Python drop-in); Python workers then write infos that fit
    /// their learned schema there, and the rest as JSON (see `envhub_protocol::info_columns`).
    pub info_row_bytes: usize,
    /// Sessions each remote hub's slice is opened as ("lanes", at most one per env and, when
    /// `EnvConfig.workers` is set, one per worker, which they share). Each lane takes its own
    /// requests, so with `send`/`recv` one lane steps while another's results travel: a
    /// remote session is then bound by its link's bandwidth rather than its round trip.
    /// 1: one session per hub.
    pub remote_lanes: usize,
}

/// A duration in seconds from the environment variable `name`, else `default`; a value that
/// is not a positive number of seconds is ignored with a warning that says so.
pub fn seconds_from_env(name: &str, default: Duration) -> Duration {
    let Ok(text) = std::env::var(name) else {
        return default;
    };
    match text.trim().parse::<f64>() {
        Ok(secs) if secs.is_finite() && secs > 0.0 => Duration::from_secs_f64(secs),
        _ => {
            tracing::warn!(
                "ignoring {name}=`{text}`: not a positive number of seconds; using {}s",
                default.as_secs_f64()
            );
            default
        }
    }
}

impl Default for SessionOptions {
    fn default() -> Self {
        SessionOptions {
            step_timeout: Duration::from_secs(60),
            start_timeout: seconds_from_env(
                envhub_core::env_vars::ENVHUB_START_TIMEOUT,
                Duration::from_secs(120),
            ),
            restart_on_crash: false,
            spin: Duration::from_micros(50),
            max_spin: Duration::from_millis(2),
            namespace: std::env::var(envhub_core::env_vars::ENVHUB_NAMESPACE)
                .unwrap_or_else(|_| "envhub_".to_string()),
            pool_bytes: 512 << 20,
            info_row_bytes: 0,
            remote_lanes: 1,
        }
    }
}

impl SessionOptions {
    /// How the client waits for its workers. Spinning yields the core on every round, so it
    /// costs nothing when another process needs the core, and saves a wake-up (tens of µs on
    /// a VM) when the answer is close; the 5 ms tick bounds how late a dead worker or a
    /// Ctrl-C is seen.
    ///
    /// With at least as many workers as cores, waits that usually last longer than
    /// [`BLOCK_BEYOND`] block at once: the workers need every core, and such a wait can afford
    /// a wake-up.
    pub(crate) fn wait_policy(&self, workers: usize) -> WaitPolicy {
        let cores = cores();
        WaitPolicy {
            spin: self.spin,
            max_spin: self.max_spin,
            tick: Duration::from_millis(5),
            block_beyond: if workers >= cores {
                BLOCK_BEYOND
            } else {
                Duration::ZERO
            },
        }
    }
}
