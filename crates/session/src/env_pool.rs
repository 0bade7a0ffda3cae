//! EnvPool's asynchronous contract over the session's workers: with a `batch_size` of M out
//! of N envs, `async_reset` starts every env, `send(actions, env_ids)` steps any envs handed
//! out, and `recv` returns exactly the first M envs to finish, in the order they finished.
//!
//! The granularity is the env on the client and the worker request on the wire. Each env is
//! idle (handed to the caller), queued (sent while its worker was busy), in flight, or ready
//! (its results in its row of a batch slot, not handed out yet). A worker takes one request
//! at a time, for the envs queued on it; when it answers, its envs become ready and what was
//! queued on it meanwhile goes out at once. A slot holding rows not handed out yet is leased
//! (as the Python client's arrays lease what they view), so no request is written into it:
//! a worker clears the reward and flags of the envs of its own that a request does not step. Envs of one worker step one after another in its request: an env waits for the
//! other envs of its request, so one worker per env gives EnvPool's per-env granularity, and
//! M a multiple of the envs per worker keeps `recv`'s results in place (a worker's answer is
//! one contiguous run of rows).
//!
//! Autoreset and seeding stay per env (the worker applies them to each env as in a
//! lock-step run), so an env's trajectory does not depend on the order envs are received in.

use crate::batch::Batch;
use crate::env_pool_state::{Arrived, EnvPoolState, EnvState};
use crate::vec_env::{Phase, VecEnv};
use envhub_protocol::HubError;

impl VecEnv {
    /// Switches the session to EnvPool's asynchronous contract: [`VecEnv::recv`] returns
    /// exactly `batch_size` envs (between 1 and `num_envs`), the first to finish, and
    /// [`VecEnv::send`] takes any envs handed out so far (envs of a busy worker wait on the
    /// client and go out when it answers). Start it with [`VecEnv::async_reset`]. Lock-step
    /// `step` is refused while envs are in flight; `reset` first waits for them and drops
    /// their results.
    pub fn set_batch_size(&mut self, batch_size: usize) -> Result<(), HubError> {
        if batch_size == 0 || batch_size > self.num_envs {
            return Err(HubError::InvalidConfig {
                what: "batch_size",
                reason: format!(
                    "{batch_size} for {} envs; use between 1 and {} (recv returns that many envs)",
                    self.num_envs, self.num_envs
                ),
            });
        }
        self.drain_env_pool()?;
        self.check_open()?;
        self.env_pool = Some(EnvPoolState::new(
            batch_size,
            self.num_envs,
            self.action_space.byte_len(),
        ));
        Ok(())
    }

    /// The EnvPool mode's batch size (`None`: not in that mode; `recv` then returns what
    /// the first workers to answer stepped).
    pub fn batch_size(&self) -> Option<usize> {
        self.env_pool.as_ref().map(|p| p.batch_size)
    }

    /// EnvPool's `async_reset`: resets every env without waiting (env `i` seeded with
    /// `seed + i`; no seed: each continues its own stream); [`VecEnv::recv`] returns them
    /// `batch_size` at a time. Results not received yet are waited for and dropped. Puts the
    /// session in the EnvPool mode with `batch_size = num_envs` unless one was set.
    pub fn async_reset(&mut self, seed: Option<u64>) -> Result<(), HubError> {
        let seeds: Vec<Option<u64>> = (0..self.num_envs)
            .map(|i| seed.map(|s| s + i as u64))
            .collect();
        self.async_reset_with(&seeds)
    }

    /// [`VecEnv::async_reset`] with one seed (or `None`) per env.
    pub fn async_reset_with(&mut self, seeds: &[Option<u64>]) -> Result<(), HubError> {
        if self.env_pool.is_none() {
            self.set_batch_size(self.num_envs)?;
        }
        self.drain_env_pool()?;
        self.check_open()?;
        if seeds.len() != self.num_envs {
            return Err(HubError::InvalidAction {
                reason: format!("reset got {} seeds for {} envs", seeds.len(), self.num_envs),
                hint: "pass one seed (or None) per env".into(),
            });
        }
        let slot = self.pool.writable()?.index();
        for w in &mut self.workers {
            let range = w.job.env_offset..w.job.env_offset + w.job.worker_envs;
            w.send_reset(slot, &seeds[range.clone()], None, "")?;
            w.sent(slot, range);
        }
        let pool = self.env_pool.as_mut().expect("set above");
        pool.state.fill(EnvState::InFlight);
        self.must_reset.fill(false);
        self.phase = Phase::Running;
        Ok(())
    }

    /// `send` in the EnvPool mode: queues each env's action and sends every free worker
    /// the envs queued on it.
    pub(crate) fn env_pool_send(
        &mut self,
        actions: &[u8],
        env_ids: &[usize],
    ) -> Result<(), HubError> {
        let pool = self.env_pool.as_ref().expect("in the EnvPool mode");
        if let Some(&e) = env_ids.iter().find(|&&e| pool.state[e] != EnvState::Idle) {
            return Err(HubError::InvalidState(format!(
                "env {e} was sent and not received yet; send an env again once `recv` has returned it (its id is in `env_ids`)"
            )));
        }
        let ab = self.action_space.byte_len();
        let pool = self.env_pool.as_mut().expect("in the EnvPool mode");
        for (k, &e) in env_ids.iter().enumerate() {
            pool.actions[e * ab..(e + 1) * ab].copy_from_slice(&actions[k * ab..(k + 1) * ab]);
            pool.state[e] = EnvState::Queued;
        }
        for i in 0..self.workers.len() {
            self.send_queued(i)?;
        }
        Ok(())
    }

    /// Sends worker `i`, if it is free, one request for the envs queued on it.
    fn send_queued(&mut self, i: usize) -> Result<(), HubError> {
        let w = &self.workers[i];
        if w.pending || w.response.is_some() {
            return Ok(());
        }
        let (lo, n) = (w.job.env_offset, w.job.worker_envs);
        let pool = self.env_pool.as_mut().expect("in the EnvPool mode");
        let selected: Vec<bool> = (lo..lo + n)
            .map(|e| pool.state[e] == EnvState::Queued)
            .collect();
        if !selected.contains(&true) {
            return Ok(());
        }
        let ab = self.action_space.byte_len();
        let block = &pool.actions[lo * ab..(lo + n) * ab];
        let writable = self.pool.writable()?;
        let slot = writable.index();
        // Only the scratch slot (every lendable one held, at the memory cap) is handed out
        // while leased: its rows of this worker's envs still to be handed out would be
        // cleared. The envs wait until those are handed out.
        if !writable.lendable() && pool.holds_rows(slot, lo..lo + n) {
            return Ok(());
        }
        let all = selected.iter().all(|&s| s);
        let w = &mut self.workers[i];
        w.send_step(slot, block, (!all).then_some(selected.as_slice()))?;
        w.sent(slot, (0..n).filter(|&k| selected[k]).map(|k| lo + k));
        for (k, &s) in selected.iter().enumerate() {
            if s {
                pool.state[lo + k] = EnvState::InFlight;
            }
        }
        Ok(())
    }

    /// `recv` in the EnvPool mode: waits until `batch_size` envs have arrived and returns
    /// the first `batch_size` of them, in the order they arrived.
    pub(crate) fn env_pool_recv(&mut self) -> Result<Batch<'_>, HubError> {
        // Envs left queued (behind rows handed out by the last `recv`) go out now.
        for i in 0..self.workers.len() {
            self.send_queued(i)?;
        }
        loop {
            self.poll_answers()?;
            let pool = self.env_pool.as_ref().expect("in the EnvPool mode");
            let m = pool.batch_size;
            if pool.arrived_envs >= m {
                break;
            }
            let coming = pool.count(EnvState::InFlight) + pool.count(EnvState::Queued);
            if pool.arrived_envs + coming < m {
                return Err(HubError::InvalidState(format!(
                    "`recv` returns batch_size = {m} envs, but only {} are sent or waiting to be received; send actions to more envs first (or `async_reset`)",
                    pool.arrived_envs + coming
                )));
            }
            if !self.workers.iter().any(|w| w.pending) {
                return Err(HubError::InvalidState(format!(
                    "`recv` cannot gather batch_size = {m} envs: the session's slots are all held by results you keep (its `pool_bytes` cap), and the envs still to step would overwrite rows not handed out yet\nhint: keep fewer results, or make the session with a larger `pool_bytes`"
                )));
            }
            self.wait_for_any()?;
        }
        let pool = self.env_pool.as_mut().expect("in the EnvPool mode");
        let m = pool.batch_size;
        let mut rows = std::mem::take(&mut self.results.rows);
        rows.clear();
        // Infos only once an answer carried some: the envs before it get nulls.
        let (mut infos, mut with_infos) = (Vec::new(), false);
        while rows.len() < m {
            let a = pool.arrived.front_mut().expect("batch_size envs arrived");
            let take = (m - rows.len()).min(a.left().len());
            let (from, to) = (a.next, a.next + take);
            if !a.infos.is_empty() && !with_infos {
                infos.resize(rows.len(), serde_json::Value::Null);
                with_infos = true;
            }
            if with_infos {
                match a.infos.get_mut(from..to) {
                    Some(own) => infos.extend(own.iter_mut().map(std::mem::take)),
                    None => infos.resize(rows.len() + take, serde_json::Value::Null),
                }
            }
            for &env in &a.envs[from..to] {
                pool.state[env] = EnvState::Idle;
                rows.push((a.slot, env));
            }
            a.next = to;
            if a.left().is_empty() {
                pool.arrived.pop_front();
            }
        }
        pool.arrived_envs -= m;
        let placed = self.place_rows(&rows);
        self.results.rows = rows;
        placed?;
        self.results.infos = infos;
        self.steps_taken += 1;
        Ok(self.batch())
    }

    /// Takes every answer that has arrived: its envs become ready (or idle, when they
    /// failed), and the envs queued on its worker go out. An env failure is returned after
    /// the other answers were taken.
    fn poll_answers(&mut self) -> Result<(), HubError> {
        self.poll_all(false)?;
        let mut failure = None;
        for i in 0..self.workers.len() {
            if self.workers[i].response.is_none() {
                continue;
            }
            let taken = self.take_results(&[i], false);
            let failed: &[usize] = match &taken {
                Ok(()) => &[],
                Err(HubError::EnvFailed { envs, .. }) => envs,
                Err(_) => return taken,
            };
            let slot = self.workers[i].slot;
            let lease = self.pool.get(slot).filter(|s| s.lendable()).cloned();
            let pool = self.env_pool.as_mut().expect("in the EnvPool mode");
            let mut infos = std::mem::take(&mut self.results.infos);
            let mut envs = self.results.env_ids.clone();
            if !failed.is_empty() {
                // Failed envs are idle again, and neither they nor their infos are handed out.
                for &env in envs.iter().filter(|e| failed.contains(e)) {
                    pool.state[env] = EnvState::Idle;
                }
                if !infos.is_empty() {
                    infos = (envs.iter().zip(infos))
                        .filter(|(env, _)| !failed.contains(env))
                        .map(|(_, info)| info)
                        .collect();
                }
                envs.retain(|env| !failed.contains(env));
            }
            if infos.iter().all(serde_json::Value::is_null) {
                infos.clear();
            }
            for &env in &envs {
                pool.state[env] = EnvState::Ready;
            }
            if !envs.is_empty() {
                pool.arrived_envs += envs.len();
                pool.arrived.push_back(Arrived {
                    slot,
                    envs,
                    infos,
                    next: 0,
                    _lease: lease,
                });
            }
            if let Err(e) = taken {
                failure = failure.or(Some(e));
            }
            self.send_queued(i)?;
        }
        failure.map_or(Ok(()), Err)
    }

    /// Waits for every request in flight and drops its results and what was queued or not
    /// received: every env idle again (before a reset, or a change of batch size).
    pub(crate) fn drain_env_pool(&mut self) -> Result<(), HubError> {
        if !self.env_pool.as_ref().is_some_and(EnvPoolState::busy) {
            return Ok(());
        }
        let timeout = self.options.step_timeout;
        for i in 0..self.workers.len() {
            if self.workers[i].pending {
                let interrupt = self.interrupt.clone();
                if let Err(e) = self.workers[i].wait(timeout, &*interrupt) {
                    self.recover(i, e)?;
                }
            }
            self.workers[i].response = None;
        }
        let pool = self.env_pool.as_mut().expect("checked above");
        pool.state.fill(EnvState::Idle);
        pool.clear_arrived();
        Ok(())
    }
}
