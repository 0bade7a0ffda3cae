//! EnvPool-style asynchronous stepping: `send` actions to some envs without waiting, `recv`
//! the results of the workers that finish first.
//!
//! Each `send` names a batch slot and every worker writes its envs' rows of it, so the workers
//! of one `send` fill one contiguous block. `recv` returns the first worker to answer together
//! with the other answered workers whose rows continue that block, so its results are viewed
//! in place; answers it leaves out are returned by the next `recv` without waiting. Only envs
//! picked out of a worker's (a `send` to envs 0 and 2 of a worker hosting 0..3) are gathered.

use crate::batch::Batch;
use crate::vec_env::{Phase, VecEnv, reset_options_json};
use envhub_protocol::HubError;
use std::time::Instant;

impl VecEnv {
    /// Sends actions to the envs in `env_ids` (one action each, in that order) without
    /// waiting; collect them with [`VecEnv::recv`]. A worker takes one request at a time, so
    /// an env whose worker still has results in flight or not yet received is refused; envs
    /// of other workers can be sent while those are stepping.
    ///
    /// In the EnvPool mode ([`VecEnv::set_batch_size`]) any env handed out may be sent: one
    /// whose worker is busy waits on the client and goes out when the worker answers.
    pub fn send(&mut self, actions: &[u8], env_ids: &[usize]) -> Result<(), HubError> {
        match self.phase {
            Phase::Closed => return self.check_open(),
            Phase::Created => return self.check_steppable(),
            Phase::Running => {}
        }
        self.check_env_ids(env_ids, "send one action per env")?;
        self.validate_actions(actions, env_ids)?;
        self.check_not_failed(env_ids)?;
        if self.env_pool.is_some() {
            return self.env_pool_send(actions, env_ids);
        }
        self.check_workers_free(env_ids)?;
        let ab = self.action_space.byte_len();
        let slot = self.pool.writable()?.index();
        for w in &mut self.workers {
            let (lo, n) = (w.job.env_offset, w.job.worker_envs);
            let mut selected = vec![false; n];
            let mut block = vec![0u8; n * ab];
            for (k, &env) in env_ids.iter().enumerate() {
                if (lo..lo + n).contains(&env) {
                    selected[env - lo] = true;
                    block[(env - lo) * ab..(env - lo + 1) * ab]
                        .copy_from_slice(&actions[k * ab..(k + 1) * ab]);
                }
            }
            if selected.iter().any(|&s| s) {
                w.send_step(slot, &block, Some(&selected))?;
                let envs = (0..n).filter(|&k| selected[k]).map(|k| lo + k);
                w.sent(slot, envs);
            }
        }
        Ok(())
    }

    /// Resets the envs in `env_ids` (env `env_ids[k]` with `seeds[k]`, `options` for all of
    /// them) without waiting, as [`VecEnv::send`] steps them: [`VecEnv::recv`] returns their
    /// first observations and reset infos like stepped envs' results (rewards 0, not done).
    /// An env's trajectory is the same as after a lock-step reset of it with the same seed
    /// and options: a worker resets the selected envs of its request only. Like `send`, an
    /// env whose worker has results in flight or not yet received is refused (the session's
    /// other envs go on stepping meanwhile). Not in the EnvPool mode, and not before the
    /// session's first [`VecEnv::reset`].
    pub fn send_reset(
        &mut self,
        env_ids: &[usize],
        seeds: &[Option<u64>],
        options: &envhub_core::ResetOptions,
    ) -> Result<(), HubError> {
        match self.phase {
            Phase::Closed => return self.check_open(),
            Phase::Created => return self.check_steppable(),
            Phase::Running => {}
        }
        if self.env_pool.is_some() {
            return Err(HubError::InvalidState(
                "`send_reset` is for `send`/`recv` without `batch_size`; in the EnvPool mode, reset every env with `async_reset`".into(),
            ));
        }
        self.check_env_ids(env_ids, "reset each env once")?;
        if seeds.len() != env_ids.len() {
            return Err(HubError::InvalidAction {
                reason: format!("{} seeds for {} envs", seeds.len(), env_ids.len()),
                hint: "pass one seed (or None) per env id".into(),
            });
        }
        self.check_workers_free(env_ids)?;
        let options_json = reset_options_json(options);
        let slot = self.pool.writable()?.index();
        for w in &mut self.workers {
            let (lo, n) = (w.job.env_offset, w.job.worker_envs);
            let mut selected = vec![false; n];
            let mut block = vec![None; n];
            for (&env, &seed) in env_ids.iter().zip(seeds) {
                if (lo..lo + n).contains(&env) {
                    selected[env - lo] = true;
                    block[env - lo] = seed;
                }
            }
            if selected.contains(&true) {
                w.send_reset(slot, &block, Some(&selected), &options_json)?;
                w.sent(slot, (0..n).filter(|&k| selected[k]).map(|k| lo + k));
            }
        }
        for &e in env_ids {
            self.must_reset[e] = false;
        }
        Ok(())
    }

    /// Refuses env ids out of range or named twice.
    fn check_env_ids(&self, env_ids: &[usize], once: &str) -> Result<(), HubError> {
        if let Some(&bad) = env_ids.iter().find(|&&e| e >= self.num_envs) {
            return Err(HubError::InvalidAction {
                reason: format!("env id {bad} is out of range"),
                hint: format!("env ids go from 0 to {}", self.num_envs - 1),
            });
        }
        let mut seen = vec![false; self.num_envs];
        for &e in env_ids {
            if std::mem::replace(&mut seen[e], true) {
                return Err(HubError::InvalidAction {
                    reason: format!("env id {e} appears twice"),
                    hint: once.into(),
                });
            }
        }
        Ok(())
    }

    /// Refuses envs whose worker takes no request now: it has results in flight or not
    /// received.
    fn check_workers_free(&self, env_ids: &[usize]) -> Result<(), HubError> {
        for w in &self.workers {
            let range = w.job.env_offset..w.job.env_offset + w.job.worker_envs;
            if (w.pending || w.response.is_some())
                && let Some(e) = env_ids.iter().find(|e| range.contains(e))
            {
                return Err(HubError::InvalidState(format!(
                    "env {e} is still stepping: its worker (envs {}..{}) has results that were not received; call `recv` first",
                    range.start, range.end
                )));
            }
        }
        Ok(())
    }

    /// Waits until at least one worker with work in flight has answered and returns the
    /// results of exactly the envs it stepped — with those of other answered workers whose
    /// rows continue them in the same slot, so the results are one block viewed in place.
    /// The first worker to finish wakes the caller (an iceoryx2 WaitSet over all of them).
    ///
    /// In the EnvPool mode ([`VecEnv::set_batch_size`]): exactly `batch_size` envs, the
    /// first to finish, in the order they finished.
    pub fn recv(&mut self) -> Result<Batch<'_>, HubError> {
        if self.phase == Phase::Closed {
            self.check_open()?;
        }
        if self.env_pool.is_some() {
            return self.env_pool_recv();
        }
        if !self
            .workers
            .iter()
            .any(|w| w.pending || w.response.is_some())
        {
            return Err(HubError::InvalidState(
                "nothing was sent; call `send` first".into(),
            ));
        }
        self.wait_for_any()?;
        let group = self.answered_block();
        self.take_results(&group, true)?;
        Ok(self.batch())
    }

    /// Polls every worker in flight; returns whether any has an answer waiting.
    pub(crate) fn poll_all(&mut self, check_exit: bool) -> Result<bool, HubError> {
        let mut any = false;
        for i in 0..self.workers.len() {
            if self.workers[i].pending {
                let polled = if check_exit {
                    self.workers[i].poll()
                } else {
                    self.workers[i].try_take()
                };
                match polled {
                    Ok(Some(r)) => self.workers[i].response = Some(r),
                    Ok(None) => {}
                    Err(e) => self.recover(i, e)?,
                }
            }
            any |= self.workers[i].response.is_some();
        }
        Ok(any)
    }

    /// Waits until some worker has answered: a short adaptive spin (yielding the core), then
    /// blocking on all pending workers' listeners at once, checking liveness, the step
    /// timeout and the interrupt every tick.
    pub(crate) fn wait_for_any(&mut self) -> Result<(), HubError> {
        if self.poll_all(false)? {
            return Ok(());
        }
        let budget = self
            .workers
            .iter()
            .filter(|w| w.pending)
            .map(|w| w.spin_budget())
            .max()
            .unwrap_or_default();
        let start = Instant::now();
        while start.elapsed() < budget {
            std::thread::yield_now();
            if self.poll_all(false)? {
                return Ok(());
            }
        }
        let tick = self.options.wait_policy(self.workers.len()).tick;
        loop {
            self.block_on_pending(tick)?;
            if self.poll_all(true)? {
                return Ok(());
            }
            // A remote request or answer lost on the way is asked for again, as a lock-step
            // wait does; a failure to send is the link's loss.
            for i in 0..self.workers.len() {
                if let Err(e) = self.workers[i].resend_if_silent() {
                    self.recover(i, e)?;
                    return Ok(());
                }
            }
            if (self.interrupt)() {
                return Err(self.give_up(HubError::Interrupted));
            }
            let timeout = self.options.step_timeout;
            if let Some(i) = self.workers.iter().position(|w| w.overdue(timeout)) {
                let err = self.workers[i].hung(timeout);
                self.recover(i, err)?;
                return Ok(());
            }
        }
    }

    /// Blocks until a pending worker may have answered, or `tick`: on the local workers'
    /// listeners (an iceoryx2 WaitSet), on the session's remote inbox, or — with both kinds
    /// pending — on each in turn with a short wait, so neither waits a tick behind the other.
    fn block_on_pending(&mut self, tick: std::time::Duration) -> Result<(), HubError> {
        let local: Vec<&envhub_shm::ClientChannel> = self
            .workers
            .iter()
            .filter(|w| w.pending)
            .filter_map(|w| w.local_channel())
            .collect();
        let remote: Vec<usize> = self
            .workers
            .iter()
            .filter(|w| w.pending)
            .filter_map(|w| w.remote_conn().map(|r| r.mailbox()))
            .collect();
        const SHARED: std::time::Duration = std::time::Duration::from_micros(200);
        match (
            local.is_empty(),
            self.opener.as_ref().filter(|_| !remote.is_empty()),
        ) {
            (_, None) => envhub_shm::wait_any(&local, tick)?,
            (true, Some(opener)) => opener.wait_any(&remote, tick),
            (false, Some(opener)) => {
                envhub_shm::wait_any(&local, SHARED)?;
                opener.wait_any(&remote, SHARED);
            }
        }
        Ok(())
    }

    /// The answered workers to return now: the lowest answered one and the answered workers
    /// whose envs continue its rows in the same slot, in env order.
    fn answered_block(&self) -> Vec<usize> {
        let answered = |i: usize| self.workers[i].response.is_some();
        let contiguous = |i: usize| {
            let sent = &self.workers[i].sent;
            sent.windows(2).all(|p| p[1] == p[0] + 1)
        };
        let first = (0..self.workers.len())
            .find(|&i| answered(i))
            .expect("an answer was waited for");
        let mut group = vec![first];
        if !contiguous(first) || self.workers[first].sent.is_empty() {
            return group;
        }
        let slot = self.workers[first].slot;
        let joins = |i: usize, start: usize| {
            answered(i)
                && contiguous(i)
                && self.workers[i].slot == slot
                && self.workers[i].sent.first() == Some(&start)
        };
        let mut end = self.workers[first].sent.last().expect("non-empty") + 1;
        while let Some(next) = (first + 1..self.workers.len()).find(|&i| joins(i, end)) {
            end = self.workers[next].sent.last().expect("non-empty") + 1;
            group.push(next);
        }
        group
    }
}
