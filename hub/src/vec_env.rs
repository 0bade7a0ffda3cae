//! `VecEnv`: a batch of envs spread over worker processes, stepped through shared memory.

use crate::error::HubError;
use crate::launcher::Launcher;
use crate::routing::Route;
use crate::worker_link::{WorkerLink, split_envs};
use envhub_core::{AutoresetMode, DType, Space};
use envhub_shm::{ChannelName, Response, WaitPolicy, WorkerJob, status};
use std::time::Duration;

/// How a session behaves, beyond what `EnvConfig` says about the envs.
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
    /// iceoryx2 namespace (file prefix) of the session's channels.
    pub namespace: String,
}

impl Default for SessionOptions {
    fn default() -> Self {
        SessionOptions {
            step_timeout: Duration::from_secs(60),
            start_timeout: Duration::from_secs(60),
            restart_on_crash: false,
            spin: Duration::from_micros(50),
            max_spin: Duration::from_millis(2),
            namespace: std::env::var(crate::env_vars::ENVHUB_NAMESPACE)
                .unwrap_or_else(|_| "envhub_".to_string()),
        }
    }
}

impl SessionOptions {
    /// How the client waits for its workers. Spinning yields the core on every round, so it
    /// costs nothing when another process needs the core, and saves a wake-up (tens of µs on
    /// a VM) when the answer is close; the 5 ms tick bounds how late a dead worker is seen.
    fn wait_policy(&self) -> WaitPolicy {
        WaitPolicy {
            spin: self.spin,
            max_spin: self.max_spin,
            tick: Duration::from_millis(5),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Phase {
    Created,
    Running,
    Closed,
}

/// The results of a reset or step, for every env of the batch (or, from
/// [`VecEnv::recv`], for the envs listed in `env_ids`). With one worker, the observations,
/// rewards and flags are viewed in place in its shared-memory sample.
#[derive(Debug)]
pub struct Batch<'a> {
    /// The envs these results belong to, in order.
    pub env_ids: &'a [usize],
    /// Observations, `observation_space().byte_len()` bytes per env, contiguous.
    pub obs: &'a [u8],
    /// Rewards.
    pub rewards: &'a [f64],
    /// Terminated flags.
    pub terminated: &'a [bool],
    /// Truncated flags.
    pub truncated: &'a [bool],
    infos: &'a [serde_json::Value],
    final_obs: &'a [Option<Vec<u8>>],
    in_place: bool,
}

static NO_INFO: serde_json::Value = serde_json::Value::Null;

impl<'a> Batch<'a> {
    /// Observations as `f32` (when the observation space is a `float32` box).
    pub fn obs_f32(&self) -> &'a [f32] {
        bytemuck::cast_slice(self.obs)
    }

    /// The info of the `k`-th env of the batch (`Null` if it reported none).
    pub fn info(&self, k: usize) -> &'a serde_json::Value {
        self.infos.get(k).unwrap_or(&NO_INFO)
    }

    /// Whether any env reported info.
    pub fn has_info(&self) -> bool {
        !self.infos.is_empty()
    }

    /// Whether the observations are viewed in place in the worker's shared-memory response
    /// (which [`VecEnv::take_response`] can then hand over), rather than gathered.
    pub fn in_place(&self) -> bool {
        self.in_place
    }

    /// same_step autoreset: the final observation of the `k`-th env if its episode ended
    /// in this step.
    pub fn final_obs(&self, k: usize) -> Option<&'a [u8]> {
        self.final_obs.get(k).and_then(Option::as_deref)
    }
}

/// An RGB frame, row-major, 3 bytes per pixel.
#[derive(Clone, Debug, PartialEq)]
pub struct Frame {
    /// Rows.
    pub height: usize,
    /// Columns.
    pub width: usize,
    /// `height × width × 3` bytes.
    pub rgb: Vec<u8>,
}

impl Frame {
    /// Reads one frame as the worker encodes it (`u32` height, `u32` width, pixels);
    /// `Some(None)` for an env that rendered nothing.
    fn parse(bytes: &[u8]) -> Option<(Option<Frame>, &[u8])> {
        let h = u32::from_le_bytes(bytes.get(..4)?.try_into().ok()?) as usize;
        let w = u32::from_le_bytes(bytes.get(4..8)?.try_into().ok()?) as usize;
        let n = h * w * 3;
        let rgb = bytes.get(8..8 + n)?;
        let frame = (n > 0).then(|| Frame {
            height: h,
            width: w,
            rgb: rgb.to_vec(),
        });
        Some((frame, &bytes[8 + n..]))
    }
}

/// Buffers the results are gathered into when they span several workers.
#[derive(Default)]
struct Gathered {
    env_ids: Vec<usize>,
    obs: Vec<u64>,
    obs_len: usize,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    infos: Vec<serde_json::Value>,
    final_obs: Vec<Option<Vec<u8>>>,
}

impl Gathered {
    fn clear(&mut self) {
        self.env_ids.clear();
        self.obs_len = 0;
        self.rewards.clear();
        self.terminated.clear();
        self.truncated.clear();
        self.infos.clear();
        self.final_obs.clear();
    }

    fn push_obs(&mut self, bytes: &[u8]) {
        let end = self.obs_len + bytes.len();
        if self.obs.len() * 8 < end {
            self.obs.resize(end.div_ceil(8), 0);
        }
        let all: &mut [u8] = bytemuck::cast_slice_mut(&mut self.obs);
        all[self.obs_len..end].copy_from_slice(bytes);
        self.obs_len = end;
    }

    fn obs_bytes(&self) -> &[u8] {
        &bytemuck::cast_slice(&self.obs)[..self.obs_len]
    }
}

/// A batch of `num_envs` envs of one kind, hosted by worker processes and stepped in lock
/// step ([`VecEnv::step`]) or asynchronously ([`VecEnv::send`] / [`VecEnv::recv`]).
pub struct VecEnv {
    id: String,
    route: Route,
    session: String,
    options: SessionOptions,
    workers: Vec<WorkerLink>,
    observation_space: Space,
    action_space: Space,
    num_envs: usize,
    /// `0..num_envs`, for validating a full batch without allocating.
    all_env_ids: Vec<usize>,
    phase: Phase,
    gathered: Gathered,
    /// Whether the last results are viewed straight in the one worker's sample.
    direct: bool,
}

fn session_name() -> String {
    use std::sync::atomic::{AtomicU64, Ordering};
    static COUNTER: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    format!(
        "{}-{}-{nanos:x}",
        std::process::id(),
        COUNTER.fetch_add(1, Ordering::Relaxed)
    )
}

impl VecEnv {
    /// Starts the workers of a routed entry. `id` names the session in errors.
    pub(crate) fn start(
        id: &str,
        route: Route,
        options: SessionOptions,
        launcher: &Launcher,
    ) -> Result<VecEnv, HubError> {
        let num_envs = route.config.num_envs;
        if num_envs == 0 {
            return Err(HubError::InvalidConfig {
                what: "num_envs",
                reason: "must be at least 1".into(),
            });
        }
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
        let workers = route.config.workers.unwrap_or_else(|| cores.min(num_envs));
        if workers == 0 || workers > num_envs {
            return Err(HubError::InvalidConfig {
                what: "workers",
                reason: format!(
                    "{workers} workers for {num_envs} envs; use between 1 and {num_envs} (each worker hosts at least one env)"
                ),
            });
        }
        let session = session_name();
        let policy = options.wait_policy();
        let spin = policy.spin;
        let jobs: Vec<WorkerJob> = split_envs(num_envs, workers)
            .into_iter()
            .map(|(env_offset, count)| {
                let mut config = route.config.clone();
                config.num_envs = count;
                WorkerJob {
                    adapter: route.adapter.clone(),
                    env_id: route.env_id.clone(),
                    config,
                    env_offset,
                    num_envs: count,
                    channel: ChannelName {
                        prefix: options.namespace.clone(),
                        service: String::new(),
                    },
                    owner_pid: std::process::id(),
                    spin_us: spin.as_micros() as u64,
                    max_spin_us: options.max_spin.as_micros() as u64,
                }
            })
            .collect();
        // Workers start in parallel: a simulator that takes a while to load (MuJoCo, Python)
        // costs its load time once, not once per worker.
        let started: Vec<Result<WorkerLink, HubError>> = std::thread::scope(|scope| {
            let handles: Vec<_> = jobs
                .into_iter()
                .enumerate()
                .map(|(index, job)| {
                    let (session, start_timeout) = (&session, options.start_timeout);
                    scope.spawn(move || {
                        WorkerLink::start(index, job, session, 0, policy, start_timeout, launcher)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join().unwrap_or_else(|_| {
                        Err(HubError::InvalidState(
                            "a worker start thread panicked".into(),
                        ))
                    })
                })
                .collect()
        });
        let links = started.into_iter().collect::<Result<Vec<_>, _>>()?;
        let observation_space = links[0].spec.observation_space.clone();
        let action_space = links[0].spec.action_space.clone();
        Ok(VecEnv {
            id: id.to_string(),
            route,
            session,
            options,
            workers: links,
            observation_space,
            action_space,
            num_envs,
            all_env_ids: (0..num_envs).collect(),
            phase: Phase::Created,
            gathered: Gathered::default(),
            direct: false,
        })
    }

    /// Number of envs.
    pub fn num_envs(&self) -> usize {
        self.num_envs
    }

    /// Number of worker processes.
    pub fn num_workers(&self) -> usize {
        self.workers.len()
    }

    /// Pids of the worker processes, in env order.
    pub fn worker_pids(&self) -> Vec<u32> {
        self.workers.iter().map(WorkerLink::pid).collect()
    }

    /// Observation space of one env.
    pub fn observation_space(&self) -> &Space {
        &self.observation_space
    }

    /// Action space of one env.
    pub fn action_space(&self) -> &Space {
        &self.action_space
    }

    /// The registry id (or env id) this batch was made from.
    pub fn id(&self) -> &str {
        &self.id
    }

    /// The adapter and config that run it.
    pub fn route(&self) -> &Route {
        &self.route
    }

    /// The episode limit applied, if any.
    pub fn max_episode_steps(&self) -> Option<u32> {
        self.workers[0].spec.max_episode_steps
    }

    /// Frames per second of the envs' rendering (Gymnasium's `metadata["render_fps"]`), if
    /// the env says.
    pub fn render_fps(&self) -> Option<f64> {
        self.workers[0].spec.render_fps
    }

    /// Autoreset mode.
    pub fn autoreset_mode(&self) -> AutoresetMode {
        self.route.config.autoreset_mode
    }

    fn check_open(&self) -> Result<(), HubError> {
        if self.phase == Phase::Closed {
            return Err(HubError::InvalidState(format!(
                "`{}` is closed; make a new env",
                self.id
            )));
        }
        if self.workers.iter().any(|w| w.pending) {
            return Err(HubError::InvalidState(
                "results of an earlier `send` have not been received; call `recv` first".into(),
            ));
        }
        Ok(())
    }

    /// Resets every env; env `i` is seeded with `seed + i` (no seed: each continues its own
    /// random stream, or draws one from the OS on its first reset).
    pub fn reset(&mut self, seed: Option<u64>) -> Result<Batch<'_>, HubError> {
        let seeds: Vec<Option<u64>> = (0..self.num_envs)
            .map(|i| seed.map(|s| s + i as u64))
            .collect();
        self.reset_with(&seeds, None, &Default::default())
    }

    /// Resets the envs where `mask` is true (all if `None`), each with its seed, passing
    /// `options` to every env's reset. Unselected envs keep their state; their slots in the
    /// results are not meaningful.
    pub fn reset_with(
        &mut self,
        seeds: &[Option<u64>],
        mask: Option<&[bool]>,
        options: &envhub_core::ResetOptions,
    ) -> Result<Batch<'_>, HubError> {
        self.check_open()?;
        if seeds.len() != self.num_envs || mask.is_some_and(|m| m.len() != self.num_envs) {
            return Err(HubError::InvalidAction {
                reason: format!(
                    "reset got {} seeds and {} mask entries for {} envs",
                    seeds.len(),
                    mask.map_or(self.num_envs, <[bool]>::len),
                    self.num_envs
                ),
                hint: "pass one seed (or None) and one mask flag per env".into(),
            });
        }
        let options_json = if options.is_empty() {
            String::new()
        } else {
            serde_json::to_string(options).expect("options serialize")
        };
        for w in &mut self.workers {
            let range = w.job.env_offset..w.job.env_offset + w.job.num_envs;
            w.response = None;
            w.channel.send_reset(
                &seeds[range.clone()],
                mask.map(|m| &m[range]),
                &options_json,
            )?;
            w.pending = true;
        }
        let all: Vec<usize> = (0..self.workers.len()).collect();
        self.collect(&all)?;
        self.phase = Phase::Running;
        Ok(self.batch())
    }

    /// Validates a batch of actions (`n` actions back to back) against the action space.
    fn batch_shape(&self, n: usize) -> String {
        let mut shape = vec![n];
        shape.extend(self.action_space.shape().unwrap_or_default());
        let dtype = self
            .action_space
            .dtype()
            .map_or("bytes".to_string(), |d| d.to_string());
        format!("{shape:?} of {dtype}")
    }

    /// Checks a typed action buffer against the action space's dtype.
    fn typed<T: bytemuck::Pod>(&self, dtype: DType, actions: &[T]) -> Result<Vec<u8>, HubError> {
        match self.action_space.dtype() {
            Some(d) if d == dtype => Ok(bytemuck::cast_slice(actions).to_vec()),
            other => Err(HubError::InvalidAction {
                reason: format!(
                    "actions are {dtype} but {} takes {}",
                    self.action_space,
                    other.map_or("a composite value".to_string(), |d| d.to_string())
                ),
                hint: format!("pass an array of shape {}", self.batch_shape(self.num_envs)),
            }),
        }
    }

    /// Steps every env with `actions` (one per env, back to back in the action space's layout).
    pub fn step(&mut self, actions: &[u8]) -> Result<Batch<'_>, HubError> {
        self.check_steppable()?;
        self.validate_actions(actions, &self.all_env_ids)?;
        let ab = self.action_space.byte_len();
        for w in &mut self.workers {
            let (lo, n) = (w.job.env_offset, w.job.num_envs);
            w.response = None;
            w.channel
                .send_step(&actions[lo * ab..(lo + n) * ab], None)?;
            w.pending = true;
        }
        let workers: Vec<usize> = (0..self.workers.len()).collect();
        self.collect(&workers)?;
        Ok(self.batch())
    }

    fn check_steppable(&self) -> Result<(), HubError> {
        self.check_open()?;
        if self.phase == Phase::Created {
            return Err(HubError::InvalidState(format!(
                "`{}` must be reset before it is stepped",
                self.id
            )));
        }
        Ok(())
    }

    /// Checks `env_ids.len()` actions back to back against the action space, holding float
    /// boxes to their bounds only with `strict_actions`; an error names the env (by its id)
    /// and the valid range or shape.
    fn validate_actions(&self, actions: &[u8], env_ids: &[usize]) -> Result<(), HubError> {
        self.action_space
            .validate_batch(actions, env_ids.len(), self.route.config.action_bounds())
            .map_err(|(k, e)| match e {
                envhub_core::SpaceError::Length { .. } => HubError::InvalidAction {
                    reason: format!(
                        "got {} bytes of actions for {} envs; each action of {} is {} bytes",
                        actions.len(),
                        env_ids.len(),
                        self.action_space,
                        self.action_space.byte_len()
                    ),
                    hint: format!("pass an array of shape {}", self.batch_shape(env_ids.len())),
                },
                e @ envhub_core::SpaceError::NotFinite { .. } => HubError::InvalidAction {
                    reason: format!("`{}` env {}: {e}", self.id, env_ids[k]),
                    hint: "actions must be finite numbers, with or without `strict_actions`".into(),
                },
                e => HubError::InvalidAction {
                    reason: format!("`{}` env {}: {e}", self.id, env_ids[k]),
                    hint: format!("actions must lie in {}", self.action_space),
                },
            })
    }

    /// [`VecEnv::step`] with `float32` actions (a continuous box).
    pub fn step_f32(&mut self, actions: &[f32]) -> Result<Batch<'_>, HubError> {
        let bytes = self.typed(DType::Float32, actions)?;
        self.step(&bytes)
    }

    /// [`VecEnv::step`] with `int64` actions (discrete).
    pub fn step_i64(&mut self, actions: &[i64]) -> Result<Batch<'_>, HubError> {
        let bytes = self.typed(DType::Int64, actions)?;
        self.step(&bytes)
    }

    /// Sends actions to the envs in `env_ids` (one action each, in that order) without
    /// waiting. Envs of a worker not named keep their state. Collect with [`VecEnv::recv`].
    pub fn send(&mut self, actions: &[u8], env_ids: &[usize]) -> Result<(), HubError> {
        self.check_steppable()?;
        if let Some(&bad) = env_ids.iter().find(|&&e| e >= self.num_envs) {
            return Err(HubError::InvalidAction {
                reason: format!("env id {bad} is out of range"),
                hint: format!("env ids go from 0 to {}", self.num_envs - 1),
            });
        }
        self.validate_actions(actions, env_ids)?;
        let ab = self.action_space.byte_len();
        for w in &mut self.workers {
            let (lo, n) = (w.job.env_offset, w.job.num_envs);
            let mut selected = vec![false; n];
            let mut block = vec![0u8; n * ab];
            let mut any = false;
            for (k, &env) in env_ids.iter().enumerate() {
                if (lo..lo + n).contains(&env) {
                    selected[env - lo] = true;
                    block[(env - lo) * ab..(env - lo + 1) * ab]
                        .copy_from_slice(&actions[k * ab..(k + 1) * ab]);
                    any = true;
                }
            }
            if any {
                w.response = None;
                w.channel.send_step(&block, Some(&selected))?;
                w.pending = true;
            }
        }
        Ok(())
    }

    /// Waits until at least one worker with work in flight has answered and returns the
    /// results of every worker that has (EnvPool's async `recv`).
    pub fn recv(&mut self) -> Result<Batch<'_>, HubError> {
        if !self.workers.iter().any(|w| w.pending) {
            return Err(HubError::InvalidState(
                "nothing was sent; call `send` first".into(),
            ));
        }
        let timeout = self.options.step_timeout;
        let started = std::time::Instant::now();
        let mut ready = Vec::new();
        loop {
            for i in 0..self.workers.len() {
                if self.workers[i].pending {
                    match self.workers[i].poll() {
                        Ok(Some(r)) => {
                            self.workers[i].response = Some(r);
                            ready.push(i);
                        }
                        Ok(None) => {}
                        Err(e) => {
                            self.recover(i, e)?;
                            ready.push(i);
                        }
                    }
                }
            }
            if !ready.is_empty() || self.workers.iter().all(|w| !w.pending) {
                break;
            }
            // Block briefly on the first pending worker; the others' answers queue meanwhile.
            let i = self
                .workers
                .iter()
                .position(|w| w.pending)
                .expect("one is pending");
            if started.elapsed() >= timeout {
                let err = self.workers[i].hung(timeout);
                self.recover(i, err)?;
                ready.push(i);
                continue;
            }
            match self.workers[i].wait_for(Duration::from_millis(1)) {
                Ok(Some(r)) => {
                    self.workers[i].response = Some(r);
                    ready.push(i);
                }
                Ok(None) => {}
                Err(e) => {
                    self.recover(i, e)?;
                    ready.push(i);
                }
            }
        }
        self.collect_ready(&ready)?;
        Ok(self.batch())
    }

    /// Handles a worker failure: restarts it if allowed, else closes the session and errs.
    fn recover(&mut self, i: usize, err: HubError) -> Result<(), HubError> {
        if !matches!(err, HubError::WorkerDied { .. }) || !self.options.restart_on_crash {
            if matches!(err, HubError::WorkerDied { .. }) {
                self.fail();
            }
            return Err(err);
        }
        tracing::warn!(worker = i, error = %err, "restarting worker");
        let policy = self.options.wait_policy();
        self.workers[i].restart(&self.session, policy, self.options.start_timeout)?;
        let n = self.workers[i].job.num_envs;
        let seeds = vec![None; n];
        self.workers[i].channel.send_reset(&seeds, None, "")?;
        self.workers[i].pending = true;
        let r = self.workers[i].wait(self.options.step_timeout)?;
        self.workers[i].response = Some(r);
        Ok(())
    }

    /// Waits for the listed workers and gathers their results.
    fn collect(&mut self, workers: &[usize]) -> Result<(), HubError> {
        let timeout = self.options.step_timeout;
        for &i in workers {
            if !self.workers[i].pending {
                continue;
            }
            match self.workers[i].wait(timeout) {
                Ok(r) => self.workers[i].response = Some(r),
                Err(e) => self.recover(i, e)?,
            }
        }
        self.collect_ready(workers)
    }

    /// Gathers the responses of `workers` into the batch buffers.
    fn collect_ready(&mut self, workers: &[usize]) -> Result<(), HubError> {
        for &i in workers {
            if let Some(r) = &self.workers[i].response
                && r.header().status == status::ERROR
            {
                let message = r.error().unwrap_or_default();
                return Err(HubError::EnvFailed { worker: i, message });
            }
        }
        let ob = self.observation_space.byte_len();
        self.gathered.clear();
        self.direct = workers.len() == 1 && self.workers.len() == 1;
        let any_info = workers.iter().any(|&i| {
            let w = &self.workers[i];
            w.restarted || w.response.as_ref().is_some_and(|r| r.header().info_len > 0)
        });
        let any_final = workers.iter().any(|&i| {
            self.workers[i]
                .response
                .as_ref()
                .is_some_and(|r| r.blocks().final_mask.iter().any(|&f| f != 0))
        });
        for &i in workers {
            let w = &mut self.workers[i];
            let restarted = std::mem::take(&mut w.restarted);
            let restarts = w.restarts;
            let Some(r) = &w.response else { continue };
            let b = r.blocks();
            let n = w.job.num_envs;
            if as_bools(b.terminated).is_none() || as_bools(b.truncated).is_none() {
                return Err(HubError::DataPlane(envhub_shm::DataPlaneError::Protocol(
                    format!("worker {i} sent done flags other than 0 and 1"),
                )));
            }
            self.gathered
                .env_ids
                .extend(w.job.env_offset..w.job.env_offset + n);
            if !self.direct {
                self.gathered.push_obs(&b.obs[..n * ob]);
                self.gathered.rewards.extend_from_slice(b.rewards);
                self.gathered
                    .terminated
                    .extend(b.terminated.iter().map(|&t| t != 0));
                self.gathered
                    .truncated
                    .extend(b.truncated.iter().map(|&t| t != 0 || restarted));
            }
            if any_info {
                let infos = parse_infos(r);
                for k in 0..n {
                    let mut info = infos
                        .as_ref()
                        .and_then(|v| v.get(k).cloned())
                        .unwrap_or_default();
                    if restarted {
                        let mut map = info.as_object().cloned().unwrap_or_default();
                        map.insert("worker_restarted".into(), true.into());
                        map.insert("worker_restarts".into(), restarts.into());
                        info = serde_json::Value::Object(map);
                    }
                    self.gathered.infos.push(info);
                }
            }
            if any_final {
                for k in 0..n {
                    self.gathered.final_obs.push(
                        (b.final_mask[k] != 0).then(|| b.final_obs[k * ob..(k + 1) * ob].to_vec()),
                    );
                }
            }
            if self.direct && restarted {
                // A restart must show in the flags, which the direct view cannot change.
                self.direct = false;
                self.gathered.push_obs(&b.obs[..n * ob]);
                self.gathered.rewards.extend_from_slice(b.rewards);
                self.gathered
                    .terminated
                    .extend(b.terminated.iter().map(|&t| t != 0));
                self.gathered.truncated.extend(std::iter::repeat_n(true, n));
            }
        }
        Ok(())
    }

    fn batch(&self) -> Batch<'_> {
        let g = &self.gathered;
        if self.direct {
            let w = &self.workers[0];
            let r = w.response.as_ref().expect("a response was collected");
            let b = r.blocks();
            let n = w.job.num_envs;
            return Batch {
                env_ids: &g.env_ids,
                obs: &b.obs[..n * self.observation_space.byte_len()],
                rewards: b.rewards,
                terminated: as_bools(b.terminated).expect("checked when collected"),
                truncated: as_bools(b.truncated).expect("checked when collected"),
                infos: &g.infos,
                final_obs: &g.final_obs,
                in_place: true,
            };
        }
        Batch {
            env_ids: &g.env_ids,
            obs: g.obs_bytes(),
            rewards: &g.rewards,
            terminated: &g.terminated,
            truncated: &g.truncated,
            infos: &g.infos,
            final_obs: &g.final_obs,
            in_place: false,
        }
    }

    /// Takes the shared-memory response behind the last results out of the session, so that
    /// views into it stay valid after later steps: the sample lives as long as the returned
    /// [`Response`] (the Python client hands it to numpy this way). `None` unless the last
    /// results were viewed in place (one worker, see [`Batch`]); then they were gathered into
    /// the session's own buffers, which the next call overwrites.
    ///
    /// iceoryx2 lets a client hold at most [`envhub_shm::MAX_BORROWED_RESPONSES`] responses
    /// per worker, the session's own latest one included: keep fewer than that taken, or
    /// copy instead, or the next receive fails.
    pub fn take_response(&mut self) -> Option<Response> {
        if !self.direct {
            return None;
        }
        self.direct = false;
        self.workers.first_mut().and_then(|w| w.response.take())
    }

    /// Renders every env (`render_mode = "rgb_array"`): one frame per env, `None` where the
    /// env renders nothing. Frames are copied out of shared memory (they are large and rare).
    pub fn render(&mut self) -> Result<Vec<Option<Frame>>, HubError> {
        self.check_open()?;
        for w in &mut self.workers {
            w.channel.send_render(None)?;
            w.pending = true;
        }
        let mut frames = Vec::with_capacity(self.num_envs);
        for i in 0..self.workers.len() {
            let response = match self.workers[i].wait(self.options.step_timeout) {
                Ok(r) => r,
                Err(e) => {
                    if matches!(e, HubError::WorkerDied { .. }) {
                        self.fail();
                    }
                    return Err(e);
                }
            };
            if let Some(message) = response.error() {
                return Err(HubError::EnvFailed { worker: i, message });
            }
            let mut bytes = response.info_bytes();
            for _ in 0..self.workers[i].job.num_envs {
                let (frame, rest) = Frame::parse(bytes).ok_or_else(|| {
                    HubError::DataPlane(envhub_shm::DataPlaneError::Protocol(format!(
                        "worker {i} sent a truncated frame"
                    )))
                })?;
                frames.push(frame);
                bytes = rest;
            }
        }
        Ok(frames)
    }

    /// Random actions for every env, drawn from the action space.
    pub fn sample_actions(&self, rng: &mut impl rand::Rng) -> Vec<u8> {
        let mut out = vec![0u8; self.num_envs * self.action_space.byte_len()];
        for chunk in out.chunks_mut(self.action_space.byte_len()) {
            self.action_space.sample_into(rng, chunk);
        }
        out
    }

    fn fail(&mut self) {
        self.phase = Phase::Closed;
        for w in &mut self.workers {
            w.response = None;
        }
        self.workers.clear();
    }

    /// Closes the envs and stops the workers. Further calls are errors; closing twice is fine.
    pub fn close(&mut self) {
        if self.phase == Phase::Closed {
            return;
        }
        self.phase = Phase::Closed;
        for w in &mut self.workers {
            w.close();
        }
        self.workers.clear();
    }
}

impl Drop for VecEnv {
    fn drop(&mut self) {
        self.close();
    }
}

/// Views flag bytes as `bool`s, if every byte is 0 or 1 (the worker writes nothing else;
/// a corrupted sample is caught when the response is collected).
fn as_bools(flags: &[u8]) -> Option<&[bool]> {
    flags.iter().all(|&f| f <= 1).then(|| {
        // SAFETY: every byte is 0 or 1, the two valid bit patterns of `bool`, which has the
        // size and alignment of `u8`.
        unsafe { std::slice::from_raw_parts(flags.as_ptr().cast::<bool>(), flags.len()) }
    })
}

/// The per-env infos of a response, if any env reported info.
fn parse_infos(r: &Response) -> Option<Vec<serde_json::Value>> {
    serde_json::from_str(r.info_json()?).ok()
}
