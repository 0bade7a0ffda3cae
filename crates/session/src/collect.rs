//! Turning workers' responses into a session's results: status and info from the responses,
//! observations, rewards and flags where the workers wrote them in the batch slot.

use crate::batch::{Batch, as_bools};
use crate::results::Place;
use crate::vec_env::VecEnv;
use crate::worker_link::{Answer, WorkerLink, env_range};
use envhub_protocol::HubError;
use envhub_protocol::batch_codec::{HUB_ERROR, RemoteAnswer, decode_error, land_rows};
use envhub_protocol::untrusted::{from_hub, read_failure_report};
use envhub_shm::{DataPlaneError, SlotPool, status};

/// Copies a remote hub's result rows of the envs it was sent into the batch slot, where a
/// local worker would have written them.
fn land_remote_rows(
    pool: &SlotPool,
    w: &WorkerLink,
    answer: &RemoteAnswer,
) -> Result<(), HubError> {
    let Some(remote) = w.remote_conn() else {
        return Ok(());
    };
    let layout = remote.rows_layout();
    let rows = answer.rows();
    if rows.len() != layout.size() {
        return Err(DataPlaneError::Protocol(format!(
            "hub `{}` sent {} bytes of results; its {} envs take {}",
            remote.hub(),
            rows.len(),
            layout.num_envs,
            layout.size()
        ))
        .into());
    }
    let slot = pool.get(w.slot).ok_or_else(|| {
        DataPlaneError::Protocol(format!(
            "results name batch slot {}, which is not open",
            w.slot
        ))
    })?;
    let lo = w.job.env_offset;
    let envs: Vec<usize> = w.sent.iter().map(|e| e - lo).collect();
    // SAFETY: these rows belong to this link's envs, which no worker writes (a remote slice
    // has none here), and results are being made: nothing reads them until they are placed.
    let mut to = unsafe { slot.rows_mut(lo, w.job.worker_envs) };
    land_rows(layout, rows, &envs, &mut to, 0);
    Ok(())
}

/// The error a remote hub sent for its whole slice (its session there is over).
fn remote_error(w: &WorkerLink, answer: &RemoteAnswer) -> HubError {
    let hub = w.remote_conn().map_or("?", |r| r.hub());
    match decode_error(hub, answer.info_bytes()) {
        HubError::WorkerDied { pid, why, .. } => HubError::WorkerDied {
            worker: w.index,
            envs: env_range(&w.job),
            pid,
            why: format!("on hub `{hub}`: {why}"),
        },
        e => from_hub(hub, e),
    }
}

/// A failure found while collecting, reported once every response has been read.
struct Failure {
    worker: usize,
    envs: Vec<usize>,
    message: String,
    /// The envs failed one by one while the others went on: they must be reset. (A worker
    /// that refuses or fails a request as a whole leaves its envs to the simulator.)
    per_env: bool,
}

impl VecEnv {
    /// Waits for the listed workers and makes their results the session's.
    pub(crate) fn collect(&mut self, workers: &[usize]) -> Result<(), HubError> {
        let timeout = self.options.step_timeout;
        for &i in workers {
            if !self.workers[i].pending {
                continue;
            }
            let interrupt = self.interrupt.clone();
            match self.workers[i].wait(timeout, &*interrupt) {
                Ok(r) => self.workers[i].response = Some(r),
                Err(e) => self.recover(i, e)?,
            }
        }
        self.take_results(workers, true)
    }

    /// Handles a worker failure: restarts it if allowed (its envs reset into the same slot),
    /// else ends the session and returns the error.
    pub(crate) fn recover(&mut self, i: usize, err: HubError) -> Result<(), HubError> {
        let recoverable = matches!(err, HubError::WorkerDied { .. } | HubError::HubLost { .. });
        if !recoverable || !self.options.restart_on_crash {
            return Err(self.give_up(err));
        }
        let (slot, sent) = (self.workers[i].slot, self.workers[i].sent.clone());
        if self.workers[i].remote_conn().is_some() {
            tracing::warn!(worker = i, error = %err, "placing a lost hub's envs again");
            if let Err(e) = self.place_again(i) {
                tracing::warn!(error = %e, "could not place them again");
                return Err(self.give_up(err));
            }
        } else {
            tracing::warn!(worker = i, error = %err, "restarting worker");
            let policy = self.options.wait_policy(self.workers.len());
            self.workers[i].restart(&self.session, policy, self.options.start_timeout)?;
        }
        let n = self.workers[i].job.worker_envs;
        self.workers[i].send_reset(slot, &vec![None; n], None, "")?;
        self.workers[i].sent(slot, sent);
        let interrupt = self.interrupt.clone();
        match self.workers[i].wait(self.options.step_timeout, &*interrupt) {
            Ok(r) => {
                self.workers[i].response = Some(r);
                Ok(())
            }
            Err(e) => Err(self.give_up(e)),
        }
    }

    /// Makes the received responses of `workers` (in env order, their envs one contiguous
    /// run of one slot unless results are to be gathered) the session's results. With
    /// `place` false the results are judged (statuses, infos, restarts) but left in their
    /// rows: `results.env_ids` and `results.infos` say what arrived, for the EnvPool mode to
    /// hand out later (`env_pool.rs`).
    pub(crate) fn take_results(&mut self, workers: &[usize], place: bool) -> Result<(), HubError> {
        if place {
            self.steps_taken += 1;
        }
        let mut failures = Vec::new();
        let mut infos: Vec<(usize, Option<serde_json::Value>)> = Vec::new();
        let mut any_info = false;
        // Every response of the group is taken and judged before anything is returned, so an
        // error about one worker never leaves the others' answers behind (the next call would
        // be refused with "call `recv` first").
        let mut ended: Option<HubError> = None;
        for &i in workers {
            let w = &mut self.workers[i];
            let Some(response) = w.response.take() else {
                continue;
            };
            let header = *response.header();
            let who = match w.remote_conn() {
                Some(r) => format!("hub `{}`", r.hub()),
                None => format!("worker {i}"),
            };
            // Results that could not be used: the worker's envs failed as a whole.
            let unusable = |w: &crate::worker_link::WorkerLink, message: String| Failure {
                worker: i,
                envs: w.sent.clone(),
                message,
                per_env: false,
            };
            if let Answer::Remote(answer) = &response {
                match header.status {
                    status::OK | status::ENV_FAILED => {
                        if let Err(e) = land_remote_rows(&self.pool, w, answer) {
                            failures.push(unusable(w, e.to_string()));
                            infos.push((i, None));
                            continue;
                        }
                    }
                    HUB_ERROR => {
                        let err = remote_error(w, answer);
                        ended = ended.or(Some(err));
                        infos.push((i, None));
                        continue;
                    }
                    _ => {}
                }
            }
            match header.status {
                status::OK => {
                    let parsed = response
                        .info_json()
                        .and_then(|text| serde_json::from_str(text).ok());
                    any_info |= parsed.is_some();
                    infos.push((i, parsed));
                }
                status::ENV_FAILED => {
                    let report =
                        read_failure_report(response.info_bytes(), &who, &w.sent, w.job.env_offset);
                    let report = match report {
                        Ok(report) => report,
                        Err(message) => {
                            failures.push(unusable(w, message));
                            infos.push((i, None));
                            continue;
                        }
                    };
                    let lo = w.job.env_offset;
                    let envs: Vec<usize> = report.failed.iter().map(|(k, _)| lo + k).collect();
                    let message = report
                        .failed
                        .iter()
                        .map(|(k, m)| format!("env {}: {m}", lo + k))
                        .collect::<Vec<_>>()
                        .join("\n");
                    any_info |= report.info.is_some();
                    infos.push((i, report.info));
                    failures.push(Failure {
                        worker: i,
                        envs,
                        message,
                        per_env: true,
                    });
                }
                status::ERROR => {
                    failures.push(Failure {
                        worker: i,
                        envs: w.sent.clone(),
                        message: response.error().unwrap_or_default(),
                        per_env: false,
                    });
                    infos.push((i, None));
                }
                other => {
                    let message = format!("{who} answered a step or reset with status {other}");
                    failures.push(unusable(w, message));
                    infos.push((i, None));
                }
            }
        }
        if let Some(err) = ended {
            return Err(self.give_up(err));
        }
        let any_restart = workers.iter().any(|&i| self.workers[i].restarted);
        if place {
            self.place_results(workers)?;
        } else {
            self.results.place = Place::Nowhere;
            self.results.env_ids.clear();
            for &i in workers {
                self.results
                    .env_ids
                    .extend_from_slice(&self.workers[i].sent);
            }
        }
        self.mark_restarts(workers);
        self.results.infos.clear();
        if any_info || any_restart {
            for (i, parsed) in infos {
                let w = &mut self.workers[i];
                let restarted = std::mem::take(&mut w.restarted);
                let lost_hub = w.lost_hub.take();
                for (k, _) in w.sent.iter().enumerate() {
                    let env_in_worker = w.sent[k] - w.job.env_offset;
                    let mut info = parsed
                        .as_ref()
                        .and_then(|v| v.get(env_in_worker).cloned())
                        .unwrap_or_default();
                    if restarted {
                        let mut map = info.as_object().cloned().unwrap_or_default();
                        map.insert("worker_restarted".into(), true.into());
                        map.insert("worker_restarts".into(), w.restarts.into());
                        if let Some(hub) = &lost_hub {
                            map.insert("hub_lost".into(), hub.clone().into());
                        }
                        info = serde_json::Value::Object(map);
                    }
                    self.results.infos.push(info);
                }
            }
        }
        for f in failures.iter().filter(|f| f.per_env) {
            for &e in &f.envs {
                self.must_reset[e] = true;
            }
        }
        match failures.into_iter().next() {
            None => Ok(()),
            Some(f) => Err(HubError::EnvFailed {
                worker: f.worker,
                envs: f.envs,
                message: f.message,
            }),
        }
    }

    /// Points the results at the workers' rows: in place when they are one contiguous run of
    /// one slot, else gathered.
    fn place_results(&mut self, workers: &[usize]) -> Result<(), HubError> {
        let mut rows = std::mem::take(&mut self.results.rows);
        rows.clear();
        for &i in workers {
            let w = &self.workers[i];
            rows.extend(w.sent.iter().map(|&e| (w.slot, e)));
        }
        let placed = self.place_rows(&rows);
        self.results.rows = rows;
        placed
    }

    /// Makes the rows `(slot, env)` the session's results, in that order: viewed in place
    /// when they are one ascending run of one slot, else gathered into a copy.
    pub(crate) fn place_rows(&mut self, rows: &[(u32, usize)]) -> Result<(), HubError> {
        let r = &mut self.results;
        r.env_ids.clear();
        r.env_ids.extend(rows.iter().map(|&(_, e)| e));
        let slot = rows.first().map_or(0, |&(s, _)| s);
        let first = r.env_ids.first().copied().unwrap_or(0);
        let contiguous = rows
            .iter()
            .enumerate()
            .all(|(k, &(s, e))| s == slot && e == first + k);
        if contiguous {
            r.place = Place::Slot { index: slot, first };
            let n = r.env_ids.len();
            let pool_slot = self.pool.get(slot).ok_or_else(|| {
                DataPlaneError::Protocol(format!(
                    "results name batch slot {slot}, which is not open"
                ))
            })?;
            let rows = pool_slot.rows(first, n);
            let (Some(term), Some(trunc)) = (as_bools(rows.terminated), as_bools(rows.truncated))
            else {
                return Err(DataPlaneError::Protocol(
                    "a worker wrote done flags other than 0 and 1".into(),
                )
                .into());
            };
            // The flags as checked, for a worker that writes its rows again after it answered
            // (broken or hostile): the batch then shows these instead of panicking.
            let g = &mut self.results.gathered;
            g.terminated.clear();
            g.terminated.extend_from_slice(term);
            g.truncated.clear();
            g.truncated.extend_from_slice(trunc);
            return Ok(());
        }
        // Results from several slots, or envs picked out of a worker's: copy them together,
        // a run of consecutive rows of one slot at a time.
        let mut g = std::mem::take(&mut self.results.gathered);
        g.clear();
        let mut start = 0;
        while start < rows.len() {
            let (slot, env) = rows[start];
            let mut n = 1;
            while rows
                .get(start + n)
                .is_some_and(|&(s, e)| s == slot && e == env + n)
            {
                n += 1;
            }
            start += n;
            let row = self.slot_rows(slot, env, n)?;
            let (Some(term), Some(trunc)) = (as_bools(row.terminated), as_bools(row.truncated))
            else {
                return Err(DataPlaneError::Protocol(
                    "a worker wrote done flags other than 0 and 1".into(),
                )
                .into());
            };
            g.push_obs(row.obs);
            g.rewards.extend_from_slice(row.rewards);
            g.terminated.extend_from_slice(term);
            g.truncated.extend_from_slice(trunc);
            g.final_mask.extend_from_slice(row.final_mask);
            g.final_obs.extend_from_slice(row.final_obs);
            g.info_cols.extend_from_slice(row.info_cols);
            self.obs_bytes_copied += row.obs.len() as u64;
        }
        self.results.gathered = g;
        self.results.place = Place::Gathered;
        Ok(())
    }

    fn slot_rows(
        &self,
        index: u32,
        first: usize,
        n: usize,
    ) -> Result<envhub_shm::ResponseBlocks<'_>, HubError> {
        let slot = self.pool.get(index).ok_or_else(|| {
            DataPlaneError::Protocol(format!(
                "results name batch slot {index}, which is not open"
            ))
        })?;
        Ok(slot.rows(first, n))
    }

    /// A restarted worker's envs come back truncated: set the flag in its rows.
    fn mark_restarts(&mut self, workers: &[usize]) {
        for &i in workers {
            let w = &self.workers[i];
            if !w.restarted {
                continue;
            }
            match self.results.place {
                Place::Slot { index, first } => {
                    if let Some(slot) = self.pool.get(index) {
                        for &env in &w.sent {
                            // SAFETY: the worker has answered (it writes these rows no more)
                            // and the slot is not lent yet: these are the results being made.
                            unsafe { slot.set_truncated(env) };
                            if let Some(t) = self.results.gathered.truncated.get_mut(env - first) {
                                *t = true;
                            }
                        }
                    }
                }
                Place::Gathered => {
                    for (k, e) in self.results.env_ids.iter().enumerate() {
                        if w.sent.contains(e) {
                            self.results.gathered.truncated[k] = true;
                        }
                    }
                }
                // Judged but not placed (the EnvPool mode): the worker's own rows.
                Place::Nowhere => {
                    if let Some(slot) = self.pool.get(w.slot) {
                        for &env in &w.sent {
                            // SAFETY: as above: the worker has answered, and its rows are
                            // handed to the caller only later.
                            unsafe { slot.set_truncated(env) };
                        }
                    }
                }
            }
        }
    }

    /// The last results as a [`Batch`].
    pub(crate) fn batch(&self) -> Batch<'_> {
        let r = &self.results;
        match r.place {
            Place::Slot { index, first } => {
                let slot = self.pool.get(index).expect("checked when collected");
                let rows = slot.rows(first, r.env_ids.len());
                // Checked when collected; a worker that wrote them again since is shown the
                // flags as they were then.
                let flags = as_bools(rows.terminated).zip(as_bools(rows.truncated));
                let (terminated, truncated) =
                    flags.unwrap_or((&r.gathered.terminated, &r.gathered.truncated));
                Batch {
                    env_ids: &r.env_ids,
                    obs: rows.obs,
                    rewards: rows.rewards,
                    terminated,
                    truncated,
                    infos: &r.infos,
                    final_mask: rows.final_mask,
                    final_obs: rows.final_obs,
                    info_cols: rows.info_cols,
                    in_place: true,
                    slot: Some(slot),
                }
            }
            Place::Gathered | Place::Nowhere => Batch {
                env_ids: &r.env_ids,
                obs: r.gathered.obs_bytes(),
                rewards: &r.gathered.rewards,
                terminated: &r.gathered.terminated,
                truncated: &r.gathered.truncated,
                infos: &r.infos,
                final_mask: &r.gathered.final_mask,
                final_obs: &r.gathered.final_obs,
                info_cols: &r.gathered.info_cols,
                in_place: false,
                slot: None,
            },
        }
    }
}
