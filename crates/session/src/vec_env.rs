//! `VecEnv`: a batch of envs spread over worker processes, stepped through shared memory.
//!
//! Every request names a batch slot ([`envhub_shm::SlotPool`]); each worker writes its envs'
//! rows of it, so the results of a lock-step call are one contiguous block per field, viewed
//! in place. Asynchronous stepping (`send`/`recv`) lives in `async_step.rs`, the collection of
//! responses into results in `results.rs`.

use crate::batch::Batch;
use crate::launch::Launch;
use crate::remote::{LOCAL, Slice, SliceOpener};
use crate::results::Results;
use crate::session_options::SessionOptions;
use crate::worker_link::{InterruptCheck, WorkerLink, split_envs};
use envhub_core::{AutoresetMode, DType, Space};
use envhub_protocol::{Frame, HubError, OpenRequest, Route};
use envhub_shm::{BatchLayout, ChannelName, Doorbells, SlotPool, SlotsName, WaitPolicy, WorkerJob};
use std::sync::Arc;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Phase {
    Created,
    Running,
    Closed,
}

/// A batch of `num_envs` envs of one kind, hosted by worker processes and stepped in lock
/// step ([`VecEnv::step`]) or asynchronously ([`VecEnv::send`] / [`VecEnv::recv`]).
pub struct VecEnv {
    pub(crate) id: String,
    pub(crate) route: Route,
    pub(crate) session: String,
    pub(crate) options: SessionOptions,
    pub(crate) workers: Vec<WorkerLink>,
    pub(crate) observation_space: Space,
    pub(crate) action_space: Space,
    pub(crate) num_envs: usize,
    /// `0..num_envs`, for checking a full batch without allocating on every step.
    all_env_ids: Vec<usize>,
    pub(crate) phase: Phase,
    pub(crate) pool: SlotPool,
    pub(crate) results: Results,
    /// Envs whose last step or reset failed: they must be reset before they step again.
    pub(crate) must_reset: Vec<bool>,
    pub(crate) interrupt: Arc<InterruptCheck>,
    /// Observation bytes copied on the client so far (0 unless results had to be gathered).
    pub(crate) obs_bytes_copied: u64,
    /// Resets and steps (lock-step or `recv`) completed.
    pub(crate) steps_taken: u64,
    /// Opens and reaches the session's slices on other hubs (none: all envs are local).
    pub(crate) opener: Option<Arc<dyn SliceOpener>>,
    /// EnvPool's contract (`set_batch_size`, `async_reset`): each env's place; `None`
    /// outside that mode.
    pub(crate) env_pool: Option<crate::env_pool_state::EnvPoolState>,
}

/// One link of a session to start: local worker `job`, or a remote hub's slice.
enum Planned {
    Local(Box<WorkerJob>),
    /// A lane of a hub's slice ([`crate::lanes::split`]).
    Remote {
        hub: String,
        env_offset: usize,
        /// The envs of the lane.
        envs: usize,
        /// The lane's share of the session's `workers`, if it names them.
        workers: Option<usize>,
    },
}

/// What a session is started with besides its options.
pub struct StartPlan<'a> {
    /// The registry id (or env id) — what remote hubs are asked for.
    pub id: &'a str,
    /// The local route, when some envs run here.
    pub route: Option<Route>,
    /// The session's config (`num_envs` is the whole session's).
    pub config: envhub_core::EnvConfig,
    /// Where its envs run, in env order.
    pub slices: Vec<Slice>,
    /// Opens the slices placed on other hubs (needed when any is).
    pub opener: Option<Arc<dyn SliceOpener>>,
}

impl VecEnv {
    /// Starts the workers of a routed entry. `id` names the session in errors.
    pub fn start(
        id: &str,
        route: Route,
        options: SessionOptions,
        launcher: &Arc<dyn Launch>,
    ) -> Result<VecEnv, HubError> {
        let num_envs = route.config.num_envs;
        VecEnv::start_placed(
            StartPlan {
                id,
                config: route.config.clone(),
                route: Some(route),
                slices: vec![Slice {
                    place: LOCAL.into(),
                    num_envs,
                }],
                opener: None,
            },
            options,
            launcher,
        )
    }

    /// Starts a session over local workers and remote hubs: envs `0..a` on the first slice's
    /// place, `a..b` on the second's, and so on.
    ///
    /// Its steps: count the envs and the local workers; plan one link per local worker and
    /// per remote slice; start them all in parallel; check that they agree on the spaces and
    /// lay out the batch slots by them; reserve the first slot. What started is closed again
    /// when a later step fails.
    pub fn start_placed(
        plan: StartPlan<'_>,
        options: SessionOptions,
        launcher: &Arc<dyn Launch>,
    ) -> Result<VecEnv, HubError> {
        let StartPlan {
            id,
            route,
            config,
            slices,
            opener,
        } = plan;
        let num_envs = session_envs(&slices)?;
        let local_workers = local_workers(&config, &slices)?;
        let session = envhub_protocol::session_id();
        let starting = Starting {
            id,
            config: &config,
            options: &options,
            session: &session,
            slots: SlotsName::new(options.namespace.clone(), session.clone()),
            policy: options.wait_policy(local_workers.max(1)),
            num_envs,
            local_workers,
            with_final: config.autoreset_mode == AutoresetMode::SameStep,
        };
        let planned = starting.plan_links(&slices, route.as_ref())?;
        let bells = if local_workers > 0 {
            Some(Doorbells::create(&starting.slots, local_workers)?)
        } else {
            None
        };
        let started = starting.start_links(planned, bells.as_ref(), opener.as_ref(), launcher);
        let (links, route) = starting.all_started(started, route)?;
        let checked = same_spaces(id, &links).and_then(|(observation, action)| {
            let layout = starting.batch_layout(&observation)?;
            Ok((observation, action, layout))
        });
        let (observation_space, action_space, layout) = match checked {
            Ok(checked) => checked,
            Err(e) => {
                starting.abandon(links);
                return Err(e);
            }
        };
        let mut pool = SlotPool::new(starting.slots.clone(), layout, options.pool_bytes);
        // The first slot now, reserved in full: a `/dev/shm` too small fails the open with
        // the bytes needed and free, not a worker's SIGBUS at the first step.
        if let Err(e) = pool.writable() {
            close_all(links);
            return Err(e.into());
        }
        Ok(VecEnv {
            id: id.to_string(),
            route: Route {
                config: envhub_core::EnvConfig {
                    num_envs,
                    ..route.config
                },
                ..route
            },
            session,
            options,
            workers: links,
            observation_space,
            action_space,
            num_envs,
            all_env_ids: (0..num_envs).collect(),
            phase: Phase::Created,
            pool,
            results: Results::default(),
            must_reset: vec![false; num_envs],
            interrupt: Arc::new(|| false),
            obs_bytes_copied: 0,
            steps_taken: 0,
            opener,
            env_pool: None,
        })
    }

    /// Opens a lost remote slice's envs again on another live hub of this session (the one
    /// hosting the fewest of its envs), connected as the same link.
    pub(crate) fn place_again(&mut self, i: usize) -> Result<(), HubError> {
        let w = &self.workers[i];
        let remote = w.remote_conn().expect("a remote link");
        let lost = remote.hub().to_string();
        let mailbox = remote.mailbox();
        let opener = self
            .opener
            .clone()
            .ok_or_else(|| HubError::Internal("remote envs without a network".into()))?;
        let mut load: Vec<(String, usize)> = Vec::new();
        for other in &self.workers {
            if let Some(r) = other.remote_conn()
                && r.hub() != lost
                && opener.is_alive(r.hub())
            {
                match load.iter_mut().find(|(h, _)| h == r.hub()) {
                    Some((_, n)) => *n += other.job.worker_envs,
                    None => load.push((r.hub().to_string(), other.job.worker_envs)),
                }
            }
        }
        let Some((target, _)) = load.into_iter().min_by_key(|(_, n)| *n) else {
            return Err(HubError::HubLost {
                hub: lost,
                envs: crate::worker_link::env_range(&w.job),
                why: "no other hub of the session is live to take its envs".into(),
            });
        };
        let n = w.job.worker_envs;
        let request = OpenRequest {
            id: self.id.clone(),
            config: w.job.config.clone(),
            client: opener.client_id(),
            restart_on_crash: true,
            step_timeout_ms: self.options.step_timeout.as_millis() as u64,
        };
        let with_final = self.autoreset_mode() == AutoresetMode::SameStep;
        let (reply, conn) = opener.open(
            &target,
            &request,
            mailbox,
            with_final,
            self.options.start_timeout,
        )?;
        if reply.spec.observation_space != self.observation_space
            || reply.spec.action_space != self.action_space
        {
            return Err(HubError::SpacesDiffer(format!(
                "hub `{target}` runs `{}` with other spaces than the session's",
                self.id
            )));
        }
        tracing::warn!(lost = %lost, to = %target, envs = n, "envs placed again");
        self.workers[i].replace_remote(reply.spec, conn, lost);
        Ok(())
    }

    /// The hubs this session runs on, with the env range each hosts (`local`: this machine).
    pub fn placement(&self) -> Vec<(String, std::ops::Range<usize>)> {
        let mut out: Vec<(String, std::ops::Range<usize>)> = Vec::new();
        for w in &self.workers {
            let place = w
                .remote_conn()
                .map_or_else(|| LOCAL.to_string(), |r| r.hub().to_string());
            let range = w.job.env_offset..w.job.env_offset + w.job.worker_envs;
            match out.last_mut() {
                Some((p, r)) if *p == place && r.end == range.start => r.end = range.end,
                _ => out.push((place, range)),
            }
        }
        out
    }

    /// Number of envs.
    pub fn num_envs(&self) -> usize {
        self.num_envs
    }

    /// Number of worker processes.
    pub fn num_workers(&self) -> usize {
        self.workers.len()
    }

    /// The envs each worker (or remote link) hosts, in env order: a request goes to one
    /// worker, so envs of one range are sent, reset and received together.
    pub fn worker_envs(&self) -> Vec<std::ops::Range<usize>> {
        (self.workers.iter())
            .map(|w| w.job.env_offset..w.job.env_offset + w.job.worker_envs)
            .collect()
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
        self.workers.first().and_then(|w| w.spec.max_episode_steps)
    }

    /// Frames per second of the envs' rendering (Gymnasium's `metadata["render_fps"]`), if
    /// the env says.
    pub fn render_fps(&self) -> Option<f64> {
        self.workers.first().and_then(|w| w.spec.render_fps)
    }

    /// Autoreset mode.
    pub fn autoreset_mode(&self) -> AutoresetMode {
        self.route.config.autoreset_mode
    }

    /// Bytes of typed info columns per env in the session's slots (0: none; the hub asks
    /// for them only where a Python worker writes them).
    pub fn info_row_bytes(&self) -> usize {
        self.options.info_row_bytes
    }

    /// Observation bytes this session has copied on the client so far. Results are viewed in
    /// place in shared memory, so this stays 0 except for `recv` of envs that do not lie
    /// contiguously in one slot.
    pub fn obs_bytes_copied(&self) -> u64 {
        self.obs_bytes_copied
    }

    /// Resets, steps and `recv`s completed so far (the denominator of per-step figures).
    pub fn steps_taken(&self) -> u64 {
        self.steps_taken
    }

    /// Batch slots created so far (each one whole batch of results in shared memory).
    pub fn slots_in_use(&self) -> usize {
        self.pool.len()
    }

    /// Sets what is asked every few milliseconds while waiting on workers: when it answers
    /// `true`, the wait stops with [`HubError::Interrupted`] and the session is aborted (its
    /// workers killed and its shared memory removed). The Python client checks for Ctrl-C.
    pub fn set_interrupt(&mut self, check: Arc<InterruptCheck>) {
        self.interrupt = check;
    }

    /// Whether the session is closed (closed, or ended by an error).
    pub fn is_closed(&self) -> bool {
        self.phase == Phase::Closed
    }

    pub(crate) fn check_open(&self) -> Result<(), HubError> {
        if self.phase == Phase::Closed {
            return Err(HubError::Closed {
                id: self.id.clone(),
            });
        }
        if self
            .env_pool
            .as_ref()
            .is_some_and(crate::env_pool_state::EnvPoolState::busy)
        {
            return Err(HubError::InvalidState(
                "envs sent with `send` (or `async_reset`) have not all been received: in the EnvPool mode, step with `send`/`recv`, or `reset` (which drops what was not received)".into(),
            ));
        }
        if self
            .workers
            .iter()
            .any(|w| w.pending || w.response.is_some())
        {
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
    /// `options` to every env's reset. Unselected envs keep their state; their rows in the
    /// results are not meaningful.
    pub fn reset_with(
        &mut self,
        seeds: &[Option<u64>],
        mask: Option<&[bool]>,
        options: &envhub_core::ResetOptions,
    ) -> Result<Batch<'_>, HubError> {
        self.drain_env_pool()?;
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
        let options_json = reset_options_json(options);
        let slot = self.pool.writable()?.index();
        for w in &mut self.workers {
            let range = w.job.env_offset..w.job.env_offset + w.job.worker_envs;
            w.send_reset(
                slot,
                &seeds[range.clone()],
                mask.map(|m| &m[range.clone()]),
                &options_json,
            )?;
            w.sent(slot, range);
        }
        for (i, done) in self.must_reset.iter_mut().enumerate() {
            if mask.is_none_or(|m| m[i]) {
                *done = false;
            }
        }
        let all: Vec<usize> = (0..self.workers.len()).collect();
        self.collect(&all)?;
        self.phase = Phase::Running;
        Ok(self.batch())
    }

    /// Describes a batch of `n` actions' shape and dtype.
    pub(crate) fn batch_shape(&self, n: usize) -> String {
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
        self.check_not_failed(&self.all_env_ids)?;
        self.validate_actions(actions, &self.all_env_ids)?;
        let ab = self.action_space.byte_len();
        let slot = self.pool.writable()?.index();
        for w in &mut self.workers {
            let (lo, n) = (w.job.env_offset, w.job.worker_envs);
            w.send_step(slot, &actions[lo * ab..(lo + n) * ab], None)?;
            w.sent(slot, lo..lo + n);
        }
        let workers: Vec<usize> = (0..self.workers.len()).collect();
        self.collect(&workers)?;
        Ok(self.batch())
    }

    pub(crate) fn check_steppable(&self) -> Result<(), HubError> {
        self.check_open()?;
        if self.phase == Phase::Created {
            return Err(HubError::NotReset {
                id: self.id.clone(),
            });
        }
        Ok(())
    }

    /// Refuses to step envs whose last step or reset failed (their state is unknown).
    pub(crate) fn check_not_failed(&self, env_ids: &[usize]) -> Result<(), HubError> {
        // The usual case, checked without allocating: nothing failed.
        if !self.must_reset.contains(&true) {
            return Ok(());
        }
        let failed: Vec<usize> = env_ids
            .iter()
            .copied()
            .filter(|&e| self.must_reset[e])
            .collect();
        if failed.is_empty() {
            return Ok(());
        }
        Err(HubError::MustReset {
            id: self.id.clone(),
            envs: failed,
        })
    }

    /// Checks `env_ids.len()` actions back to back against the action space, holding float
    /// boxes to their bounds only with `strict_actions`; an error names the env (by its id)
    /// and the valid range or shape.
    pub(crate) fn validate_actions(
        &self,
        actions: &[u8],
        env_ids: &[usize],
    ) -> Result<(), HubError> {
        let n = env_ids.len();
        self.action_space
            .validate_batch(actions, n, self.route.config.action_bounds())
            .map_err(|(k, e)| match e {
                envhub_core::SpaceError::Length { .. } => HubError::InvalidAction {
                    reason: format!(
                        "got {} bytes of actions for {} envs; each action of {} is {} bytes",
                        actions.len(),
                        n,
                        self.action_space,
                        self.action_space.byte_len()
                    ),
                    hint: format!("pass an array of shape {}", self.batch_shape(n)),
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

    /// The results of the last reset, step or `recv`. After an [`HubError::EnvFailed`], these
    /// are the results of the envs that did not fail (the failed envs' rows are not
    /// meaningful); `None` before the first results.
    pub fn last_batch(&self) -> Option<Batch<'_>> {
        (self.phase != Phase::Closed && self.results.is_set()).then(|| self.batch())
    }

    /// Renders every env (`render_mode = "rgb_array"`): one frame per env, `None` where the
    /// env renders nothing. Frames are copied out of shared memory (they are large and rare).
    pub fn render(&mut self) -> Result<Vec<Option<Frame>>, HubError> {
        self.check_open()?;
        for w in &mut self.workers {
            w.send_render()?;
        }
        let mut frames = Vec::with_capacity(self.num_envs);
        for i in 0..self.workers.len() {
            let response = match self.workers[i].wait(self.options.step_timeout, &*self.interrupt) {
                Ok(r) => r,
                Err(e) => return Err(self.give_up(e)),
            };
            if let Some(message) = response.error() {
                // The other workers' answers are read and dropped, so the next request starts
                // clean.
                for w in &mut self.workers[i + 1..] {
                    let _ = w.wait(self.options.step_timeout, &|| false);
                }
                return Err(HubError::EnvFailed {
                    worker: i,
                    envs: self.workers[i].sent.clone(),
                    message,
                });
            }
            let mut bytes = response.info_bytes();
            for _ in 0..self.workers[i].job.worker_envs {
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

    /// After a worker died (without restart) or the caller interrupted a wait: the session is
    /// over. Kills what is left, removes its shared memory, and passes the error on.
    pub(crate) fn give_up(&mut self, err: HubError) -> HubError {
        if matches!(
            err,
            HubError::WorkerDied { .. } | HubError::HubLost { .. } | HubError::Interrupted
        ) {
            self.abort();
        }
        err
    }

    /// Ends the session at once: workers killed, shared memory removed. For when waiting for
    /// a clean close is not an option (a dead worker, Ctrl-C).
    pub fn abort(&mut self) {
        if self.phase == Phase::Closed {
            return;
        }
        self.phase = Phase::Closed;
        for w in &mut self.workers {
            w.abort();
        }
        self.workers.clear();
        self.pool.close();
        let _ = envhub_shm::cleanup_dead_nodes(&self.options.namespace);
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
        self.pool.close();
    }
}

impl Drop for VecEnv {
    fn drop(&mut self) {
        self.close();
    }
}

/// The envs of the whole session: those of every slice (at least one).
fn session_envs(slices: &[Slice]) -> Result<usize, HubError> {
    let num_envs: usize = slices.iter().map(|s| s.num_envs).sum();
    if num_envs == 0 {
        return Err(HubError::InvalidConfig {
            what: "num_envs",
            reason: "must be at least 1".into(),
        });
    }
    Ok(num_envs)
}

/// The workers to start on this machine for the envs placed here (0 when none is).
fn local_workers(config: &envhub_core::EnvConfig, slices: &[Slice]) -> Result<usize, HubError> {
    let local_envs: usize = slices
        .iter()
        .filter(|s| s.place == LOCAL)
        .map(|s| s.num_envs)
        .sum();
    if local_envs == 0 {
        return Ok(0);
    }
    let workers = crate::session_options::workers_for(config, local_envs);
    if workers == 0 || workers > local_envs {
        return Err(HubError::InvalidConfig {
            what: "workers",
            reason: format!(
                "{workers} workers for {local_envs} envs; use between 1 and {local_envs} (each worker hosts at least one env)"
            ),
        });
    }
    Ok(workers)
}

/// A session being started: what the steps of [`VecEnv::start_placed`] share.
struct Starting<'a> {
    id: &'a str,
    /// The session's config (its `num_envs`: the whole session's).
    config: &'a envhub_core::EnvConfig,
    options: &'a SessionOptions,
    session: &'a str,
    slots: SlotsName,
    policy: WaitPolicy,
    /// Envs of the whole session (rows of a batch slot).
    num_envs: usize,
    local_workers: usize,
    /// Whether steps also return the final observation of an episode that ended.
    with_final: bool,
}

impl Starting<'_> {
    /// One link per local worker (each slice placed here split among them) and one per
    /// remote slice, in env order.
    fn plan_links(
        &self,
        slices: &[Slice],
        route: Option<&Route>,
    ) -> Result<Vec<Planned>, HubError> {
        let mut planned = Vec::new();
        let mut offset = 0;
        let mut worker_index = 0;
        for slice in slices {
            if slice.place != LOCAL {
                let lanes = crate::lanes::split(
                    slice.num_envs,
                    self.options.remote_lanes,
                    self.config.workers,
                );
                for (lane_offset, envs, workers) in lanes {
                    planned.push(Planned::Remote {
                        hub: slice.place.clone(),
                        env_offset: offset + lane_offset,
                        envs,
                        workers,
                    });
                }
                offset += slice.num_envs;
                continue;
            }
            let route = route.ok_or_else(|| {
                HubError::Internal("envs placed here without a local route".into())
            })?;
            for (local_offset, count) in split_envs(slice.num_envs, self.local_workers) {
                planned.push(Planned::Local(Box::new(self.local_job(
                    route,
                    offset + local_offset,
                    count,
                    worker_index,
                ))));
                worker_index += 1;
            }
            offset += slice.num_envs;
        }
        Ok(planned)
    }

    /// The job of local worker `worker_index`, hosting `count` envs from `env_offset`.
    fn local_job(
        &self,
        route: &Route,
        env_offset: usize,
        count: usize,
        worker_index: usize,
    ) -> WorkerJob {
        WorkerJob {
            adapter: route.adapter.clone(),
            env_id: route.env_id.clone(),
            config: config_for(&route.config, count),
            env_offset,
            worker_envs: count,
            session_envs: self.num_envs,
            channel: ChannelName {
                prefix: self.options.namespace.clone(),
                service: String::new(),
            },
            slots: self.slots.clone(),
            worker_index,
            session_workers: self.local_workers,
            owner_pid: std::process::id(),
            spin_us: self.policy.spin.as_micros() as u64,
            max_spin_us: self.options.max_spin.as_micros() as u64,
            info_row_bytes: self.options.info_row_bytes,
            python: route.python.clone(),
        }
    }

    /// Starts every planned link, in parallel: a simulator that takes a while to load
    /// (MuJoCo, Python) costs its load time once, not once per worker or hub. A remote
    /// link comes with the route its hub chose.
    fn start_links(
        &self,
        planned: Vec<Planned>,
        bells: Option<&Arc<Doorbells>>,
        opener: Option<&Arc<dyn SliceOpener>>,
        launcher: &Arc<dyn Launch>,
    ) -> Vec<Result<(WorkerLink, Option<Route>), HubError>> {
        std::thread::scope(|scope| {
            let handles: Vec<_> = planned
                .into_iter()
                .enumerate()
                .map(|(index, plan)| {
                    scope.spawn(move || match plan {
                        Planned::Local(job) => {
                            let bell = bells
                                .expect("made for local workers")
                                .bell(job.worker_index)?;
                            let link = WorkerLink::start(
                                index,
                                *job,
                                self.session,
                                0,
                                self.policy,
                                self.options.start_timeout,
                                launcher,
                                bell,
                            )?;
                            Ok((link, None))
                        }
                        Planned::Remote {
                            hub,
                            env_offset,
                            envs,
                            workers,
                        } => {
                            let opener = opener.ok_or_else(|| {
                                HubError::Internal("remote envs without a network".into())
                            })?;
                            let (link, route) =
                                self.open_remote(opener, index, &hub, env_offset, envs, workers)?;
                            Ok((link, Some(route)))
                        }
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join().unwrap_or_else(|_| {
                        Err(HubError::Internal("a worker start thread panicked".into()))
                    })
                })
                .collect()
        })
    }

    /// Opens the lane of `envs` envs (from `env_offset`, on `workers` workers if the session
    /// names them) on `hub` as link `index`.
    fn open_remote(
        &self,
        opener: &Arc<dyn SliceOpener>,
        index: usize,
        hub: &str,
        env_offset: usize,
        envs: usize,
        workers: Option<usize>,
    ) -> Result<(WorkerLink, Route), HubError> {
        let request = OpenRequest {
            id: self.id.to_string(),
            // A session of its own on that hub: its `num_envs` is the lane's.
            config: envhub_core::EnvConfig {
                num_envs: envs,
                workers,
                ..self.config.clone()
            },
            client: opener.client_id(),
            restart_on_crash: self.options.restart_on_crash,
            step_timeout_ms: self.options.step_timeout.as_millis() as u64,
        };
        let (reply, conn) = opener.open(
            hub,
            &request,
            index,
            self.with_final,
            self.options.start_timeout,
        )?;
        let job = WorkerJob {
            adapter: reply.route.adapter.clone(),
            env_id: reply.route.env_id.clone(),
            config: request.config,
            env_offset,
            worker_envs: envs,
            session_envs: self.num_envs,
            channel: ChannelName {
                prefix: String::new(),
                service: String::new(),
            },
            slots: self.slots.clone(),
            worker_index: index,
            session_workers: 0,
            owner_pid: std::process::id(),
            spin_us: 0,
            max_spin_us: 0,
            info_row_bytes: 0,
            python: None,
        };
        Ok((
            WorkerLink::remote(index, job, reply.spec, conn),
            reply.route,
        ))
    }

    /// The links, once every one started, with the session's route (the local one, else
    /// the first remote hub's); else the first error, the others closed.
    fn all_started(
        &self,
        started: Vec<Result<(WorkerLink, Option<Route>), HubError>>,
        mut route: Option<Route>,
    ) -> Result<(Vec<WorkerLink>, Route), HubError> {
        let mut links = Vec::with_capacity(started.len());
        let mut failure = None;
        for result in started {
            match result {
                Ok((link, remote_route)) => {
                    if route.is_none() {
                        route = remote_route;
                    }
                    links.push(link);
                }
                Err(e) => failure = failure.or(Some(e)),
            }
        }
        if let Some(e) = failure {
            self.abandon(links);
            return Err(e);
        }
        Ok((links, route.expect("some link started")))
    }

    /// The batch slots' layout for this session's envs. The spaces came from other
    /// processes (workers running user code, hubs): sizes are checked before a slot is laid
    /// out by them.
    fn batch_layout(&self, observation_space: &Space) -> Result<BatchLayout, HubError> {
        let (id, num_envs) = (self.id, self.num_envs);
        observation_space
            .check()
            .ok()
            .and_then(|obs| BatchLayout::checked(num_envs, obs, self.with_final))
            .and_then(|layout| layout.with_info_columns(self.options.info_row_bytes))
            .ok_or_else(|| {
                HubError::SpacesDiffer(format!(
                    "`{id}` has an observation space too large for a batch of {num_envs} envs: {observation_space}"
                ))
            })
    }

    /// Closes what started and removes the session's slots: a later step failed.
    fn abandon(&self, links: Vec<WorkerLink>) {
        close_all(links);
        self.slots.unlink_all();
    }
}

/// The config a worker hosting `count` envs is started with: the session's, with its
/// `num_envs` the worker's own (what an adapter builds, `make_vec(num_envs=...)` included).
fn config_for(session: &envhub_core::EnvConfig, count: usize) -> envhub_core::EnvConfig {
    envhub_core::EnvConfig {
        num_envs: count,
        ..session.clone()
    }
}

/// The spaces every link reports, which must be the same everywhere (hubs running
/// different versions of an env would not batch).
fn same_spaces(id: &str, links: &[WorkerLink]) -> Result<(Space, Space), HubError> {
    let observation_space = links[0].spec.observation_space.clone();
    let action_space = links[0].spec.action_space.clone();
    if let Some(odd) = links.iter().find(|l| {
        l.spec.observation_space != observation_space || l.spec.action_space != action_space
    }) {
        let where_ = |l: &WorkerLink| {
            l.remote_conn().map_or_else(
                || "this machine".to_string(),
                |r| format!("hub `{}`", r.hub()),
            )
        };
        return Err(HubError::SpacesDiffer(format!(
            "`{id}` has different spaces on {} ({} / {}) and {} ({} / {}); the hubs run different versions of it",
            where_(&links[0]),
            observation_space,
            action_space,
            where_(odd),
            odd.spec.observation_space,
            odd.spec.action_space
        )));
    }
    Ok((observation_space, action_space))
}

fn close_all(links: Vec<WorkerLink>) {
    for mut link in links {
        link.close();
    }
}

/// Reset options as a request carries them: empty when there are none.
pub(crate) fn reset_options_json(options: &envhub_core::ResetOptions) -> String {
    if options.is_empty() {
        String::new()
    } else {
        serde_json::to_string(options).expect("options serialize")
    }
}
