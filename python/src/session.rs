//! `Session`: a `VecEnv` shared with Python, and `SharedSlot`, the owner object through which
//! numpy arrays keep a shared-memory batch slot alive.
//!
//! Ownership: results lie in a batch slot that all the session's workers write into. When a
//! call returns, the arrays of its observations, rewards and flags view that slot, and their
//! base object holds a lease on it: the slot is not written again, nor unmapped, until the
//! last array viewing it is gone, so arrays a user keeps (a frame stack, a replay buffer) stay
//! valid and unchanged. The session then writes into another slot; when every slot the memory
//! cap allows is lent, results land in a scratch slot and are copied into fresh arrays, so a
//! call never waits on the user. Arrays are writeable either way, as Gymnasium's are.

use crate::arrays::{self, ArrayLayout};
use crate::convert::info_to_py;
use crate::errors::{forked, hub_error, raise};
use crate::info_columns::{ColumnTuple, Schemas, uniform_id, vector_info};
use crate::registry::PyRegistry;
use envhub_hub::{AutoresetMode, Batch, EnvConfig, Hub, HubError, ResetOptions, SlotLease, VecEnv};
use numpy::{PyArray1, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyList, PyTuple};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

/// A session's `VecEnv` and the process that made it.
struct State {
    vec: std::mem::ManuallyDrop<VecEnv>,
    pid: u32,
}

impl Drop for State {
    fn drop(&mut self) {
        if std::process::id() != self.pid {
            // A forked child's copy: the workers and slots are the parent's; closing them here
            // would end the parent's session. Leak them.
            return;
        }
        // SAFETY: dropped once, here, and never used again.
        unsafe { std::mem::ManuallyDrop::drop(&mut self.vec) };
    }
}

/// The base object of arrays that view a batch slot: while it lives, the slot is neither
/// written again nor unmapped.
#[pyclass(name = "SharedSlot", module = "envhub._envhub", frozen)]
pub(crate) struct SlotOwner {
    lease: SlotLease,
    address: usize,
    nbytes: usize,
}

#[pymethods]
impl SlotOwner {
    /// Address of the observations in shared memory.
    #[getter]
    fn address(&self) -> usize {
        self.address
    }

    /// Bytes of observations viewed.
    #[getter]
    fn nbytes(&self) -> usize {
        self.nbytes
    }

    /// The batch slot's index in its session.
    #[getter]
    fn slot(&self) -> u32 {
        self.lease.index()
    }

    fn __repr__(&self) -> String {
        format!(
            "<envhub shared-memory batch slot {}: {} bytes of observations at {:#x}>",
            self.lease.index(),
            self.nbytes,
            self.address
        )
    }
}

/// Where a batch's observations, rewards and flags are.
enum Place {
    /// In a batch slot, at these addresses, lent through `lease`.
    Lent {
        lease: SlotLease,
        obs: usize,
        rewards: usize,
        terminated: usize,
        truncated: usize,
        info_cols: usize,
    },
    /// Copied (results in the scratch slot, or gathered).
    Copied {
        /// The observations' bytes, in words so that views of them are aligned.
        obs: Vec<u64>,
        rewards: Vec<f64>,
        terminated: Vec<bool>,
        truncated: Vec<bool>,
        info_cols: Vec<u8>,
    },
}

/// A batch's results, taken out of the session (no borrow of it left).
struct Results {
    env_ids: Vec<usize>,
    place: Place,
    infos: Option<Vec<serde_json::Value>>,
    final_obs: Option<Vec<Option<FinalObs>>>,
}

/// `(obs, rewards, terminated, truncated, info columns)` arrays, and the slot owner that is
/// their base when they view the slot.
type Arrays<'py> = ([Bound<'py, PyAny>; 5], Option<Bound<'py, PyAny>>);

/// One env's final observation (same_step): where it lies in the lent slot, or a copy.
enum FinalObs {
    /// The address of its row in the slot's final-observation block (the slot is lent with
    /// the other results, so the row stays valid and unchanged while they are viewed).
    At(usize),
    /// Copied (results in the scratch slot, or gathered), in words.
    Copy(Vec<u64>),
}

impl Results {
    fn of(batch: &Batch<'_>, lease: Option<SlotLease>, same_step: bool) -> Results {
        let n = batch.env_ids.len();
        let lent = lease.is_some();
        let place = match lease {
            Some(lease) => Place::Lent {
                lease,
                obs: batch.obs.as_ptr() as usize,
                rewards: batch.rewards.as_ptr() as usize,
                terminated: batch.terminated.as_ptr() as usize,
                truncated: batch.truncated.as_ptr() as usize,
                info_cols: batch.info_columns().as_ptr() as usize,
            },
            None => Place::Copied {
                obs: arrays::words_of(batch.obs),
                rewards: batch.rewards.to_vec(),
                terminated: batch.terminated.to_vec(),
                truncated: batch.truncated.to_vec(),
                info_cols: batch.info_columns().to_vec(),
            },
        };
        let final_obs = if same_step {
            let all: Vec<Option<FinalObs>> = (0..n)
                .map(|k| {
                    batch.final_obs(k).map(|row| {
                        if lent {
                            FinalObs::At(row.as_ptr() as usize)
                        } else {
                            FinalObs::Copy(arrays::words_of(row))
                        }
                    })
                })
                .collect();
            all.iter().any(Option::is_some).then_some(all)
        } else {
            None
        };
        Results {
            env_ids: batch.env_ids.to_vec(),
            place,
            infos: batch
                .has_info()
                .then(|| (0..n).map(|k| batch.info(k).clone()).collect()),
            final_obs,
        }
    }
}

/// A failed call: the error, and for an env failure the results of the envs that did not fail.
type Failed = Box<(HubError, Option<Results>)>;

/// Runs `op` on the session and takes its results out.
fn run(
    vec: &mut VecEnv,
    op: impl for<'a> FnOnce(&'a mut VecEnv) -> Result<Batch<'a>, HubError>,
) -> Result<Results, Failed> {
    let same_step = vec.autoreset_mode() == AutoresetMode::SameStep;
    match op(vec) {
        Ok(batch) => Ok(Results::of(&batch, batch.lease(), same_step)),
        Err(e @ HubError::EnvFailed { .. }) => {
            let partial = vec
                .last_batch()
                .map(|b| Results::of(&b, b.lease(), same_step));
            Err(Box::new((e, partial)))
        }
        Err(e) => Err(Box::new((e, None))),
    }
}

/// One env's results as Python values: `(obs, reward, terminated, truncated, info)`.
type Single<'py> = (Bound<'py, PyAny>, f64, bool, bool, Bound<'py, PyAny>);

/// A batch of envs in worker processes (the compiled half of `envhub.VectorEnv` and
/// `envhub.Env`).
///
/// What does not change during a session is plain read-only attributes.
#[pyclass(name = "Session", module = "envhub._envhub", frozen)]
pub(crate) struct Session {
    state: Mutex<State>,
    /// Pid of the process that made the session.
    #[pyo3(get, name = "owner_pid")]
    pid: u32,
    /// The exception (KeyboardInterrupt) that interrupted the last wait, to re-raise.
    interrupted: Arc<Mutex<Option<PyErr>>>,
    closed: AtomicBool,
    /// Registry id.
    #[pyo3(get)]
    id: String,
    /// Adapter that runs the envs.
    #[pyo3(get)]
    adapter: String,
    /// The framework's env id.
    #[pyo3(get)]
    env_id: String,
    /// Number of envs.
    #[pyo3(get)]
    num_envs: usize,
    /// Number of worker processes.
    #[pyo3(get)]
    num_workers: usize,
    /// Worker pids, in env order (on its hub's machine for a remote slice).
    #[pyo3(get)]
    worker_pids: Vec<u32>,
    /// Each worker's envs as `(first, end)`, in env order: envs of one worker are sent,
    /// reset and received together.
    #[pyo3(get)]
    worker_envs: Vec<(usize, usize)>,
    /// Where the envs run: `(hub, first env, end)` runs, `local` for this machine.
    #[pyo3(get)]
    placement: Vec<(String, usize, usize)>,
    /// The episode limit applied, if any.
    #[pyo3(get)]
    max_episode_steps: Option<u32>,
    /// Frames per second of the envs' rendering (Gymnasium's `metadata["render_fps"]`).
    #[pyo3(get)]
    render_fps: Option<f64>,
    /// `next_step`, `same_step` or `disabled`.
    #[pyo3(get)]
    autoreset_mode: String,
    /// Observation space of one env, as JSON.
    #[pyo3(get, name = "observation_space_json")]
    observation_space: String,
    /// Action space of one env, as JSON.
    #[pyo3(get, name = "action_space_json")]
    action_space: String,
    /// Leaves of the observation space with their byte offsets, as JSON.
    #[pyo3(get, name = "obs_leaves_json")]
    obs_leaves: String,
    /// Leaves of the action space with their byte offsets, as JSON.
    #[pyo3(get, name = "action_leaves_json")]
    action_leaves: String,
    obs: ArrayLayout,
    act: ArrayLayout,
    /// Bytes per env of the slots' typed info columns (0: none).
    #[pyo3(get)]
    info_row_bytes: usize,
    /// The info-column schemas the workers announced.
    schemas: Mutex<Schemas>,
    /// Observation bytes this side copied (results that could not be lent in place).
    copied: AtomicU64,
}

pub(crate) fn leaves_json(space: &envhub_hub::Space) -> String {
    let leaves: Vec<serde_json::Value> = space
        .leaves()
        .iter()
        .map(|(path, offset, leaf)| {
            serde_json::json!({
                "path": path,
                "offset": offset,
                "dtype": leaf.dtype().map(|d| d.name()),
                "shape": leaf.shape(),
                "bytes": leaf.byte_len(),
            })
        })
        .collect();
    serde_json::Value::Array(leaves).to_string()
}

fn invalid_config(py: Python<'_>, message: String) -> PyErr {
    raise(py, "InvalidConfigError", message, vec![])
}

/// Starts a session of `num_envs` envs of registry entry `id`. `config_json` is an
/// `EnvConfig` as JSON (unknown fields are an error); `registry` replaces the one found the
/// usual way. With `adapter`, `id` is that adapter's env id and no registry is involved
/// (`envhub.AsyncVectorEnv`'s factories, which no daemon's registry could know).
#[pyfunction]
#[pyo3(signature = (id, num_envs, config_json, registry=None, step_timeout=None, restart_on_crash=false, pool_bytes=None, adapter=None, hubs=None, info_row_bytes=0, remote_lanes=1))]
#[allow(clippy::too_many_arguments)] // Python keyword arguments
pub(crate) fn make_session(
    py: Python<'_>,
    id: String,
    num_envs: usize,
    config_json: &str,
    registry: Option<PyRef<'_, PyRegistry>>,
    step_timeout: Option<f64>,
    restart_on_crash: bool,
    pool_bytes: Option<usize>,
    adapter: Option<String>,
    hubs: Option<String>,
    info_row_bytes: usize,
    remote_lanes: usize,
) -> PyResult<Session> {
    if remote_lanes == 0 {
        return Err(invalid_config(
            py,
            "remote_lanes must be at least 1 (sessions per remote hub's slice)".into(),
        ));
    }
    let config: EnvConfig = serde_json::from_str(config_json)
        .map_err(|e| invalid_config(py, format!("invalid env config: {e}")))?;
    let timeout = match step_timeout {
        None => None,
        Some(t) if t.is_finite() && t > 0.0 => Some(Duration::from_secs_f64(t)),
        Some(t) => {
            return Err(invalid_config(
                py,
                format!("invalid step_timeout: {t}; use a positive number of seconds"),
            ));
        }
    };
    let registry = registry.map(|r| r.inner.clone());
    let placement: envhub_hub::Placement = match hubs.as_deref().map(str::parse).transpose() {
        Ok(p) => p.unwrap_or_default(),
        Err(e) => return Err(hub_error(py, e)),
    };
    if adapter.is_some() && !placement.is_local() {
        return Err(invalid_config(
            py,
            "env factories run on this machine only: `hubs=` takes registry ids".into(),
        ));
    }
    let made = py
        .detach(move || -> Result<State, HubError> {
            let hub = match registry {
                None => Hub::from_env()?,
                Some(registry) => match std::env::var_os(envhub_hub::env_vars::ENVHUB_HUB)
                    .filter(|s| !s.is_empty())
                {
                    Some(socket) => Hub::connect(std::path::Path::new(&socket), registry)?,
                    None => Hub::new(registry),
                }
                .with_network(Hub::from_env()?.network_config().clone()),
            };
            let mut options = hub.options().clone();
            if let Some(t) = timeout {
                options.step_timeout = t;
            }
            options.restart_on_crash = restart_on_crash;
            if let Some(bytes) = pool_bytes {
                options.pool_bytes = bytes;
            }
            options.info_row_bytes = info_row_bytes;
            options.remote_lanes = remote_lanes;
            let hub = hub.with_options(options);
            let vec = match adapter {
                Some(adapter) => {
                    let mut config = config;
                    config.num_envs = num_envs;
                    hub.make_vec_direct(&adapter, &id, &config)?
                }
                None => hub.make_vec_on(&id, num_envs, &config, &placement)?,
            };
            Ok(State {
                vec: std::mem::ManuallyDrop::new(vec),
                pid: std::process::id(),
            })
        })
        .map_err(|e| hub_error(py, e))?;
    let mut st = made;
    let interrupted: Arc<Mutex<Option<PyErr>>> = Arc::default();
    st.vec.set_interrupt(ctrl_c_check(interrupted.clone()));
    let v = &*st.vec;
    let session = Session {
        closed: AtomicBool::new(false),
        id: v.id().to_string(),
        adapter: v.route().adapter.clone(),
        env_id: v.route().env_id.clone(),
        num_envs: v.num_envs(),
        num_workers: v.num_workers(),
        worker_pids: v.worker_pids(),
        worker_envs: v
            .worker_envs()
            .into_iter()
            .map(|r| (r.start, r.end))
            .collect(),
        placement: v
            .placement()
            .into_iter()
            .map(|(place, r)| (place, r.start, r.end))
            .collect(),
        max_episode_steps: v.max_episode_steps(),
        render_fps: v.render_fps(),
        autoreset_mode: serde_json::to_value(v.autoreset_mode())
            .ok()
            .and_then(|m| m.as_str().map(str::to_string))
            .unwrap_or_default(),
        observation_space: serde_json::to_string(v.observation_space()).expect("space json"),
        action_space: serde_json::to_string(v.action_space()).expect("space json"),
        obs_leaves: leaves_json(v.observation_space()),
        action_leaves: leaves_json(v.action_space()),
        obs: ArrayLayout::of(v.observation_space()),
        act: ArrayLayout::of(v.action_space()),
        info_row_bytes: v.info_row_bytes(),
        schemas: Mutex::default(),
        copied: AtomicU64::new(0),
        pid: st.pid,
        state: Mutex::new(st),
        interrupted,
    };
    Ok(session)
}

/// What a session asks while it waits on workers: whether Python has a signal to handle (Ctrl-C).
/// The exception it raises is kept for the caller to re-raise once the wait has ended.
fn ctrl_c_check(slot: Arc<Mutex<Option<PyErr>>>) -> Arc<envhub_hub::InterruptCheck> {
    Arc::new(move || {
        Python::attach(|py| match py.check_signals() {
            Ok(()) => false,
            Err(e) => {
                *slot.lock().unwrap_or_else(PoisonError::into_inner) = Some(e);
                true
            }
        })
    })
}

impl Session {
    fn schemas(&self) -> MutexGuard<'_, Schemas> {
        self.schemas.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Takes the info-column schemas announced in `infos` out of them (checked, remembered);
    /// `infos` becomes `None` when no env has anything left.
    fn learn_schemas(
        &self,
        py: Python<'_>,
        infos: &mut Option<Vec<serde_json::Value>>,
    ) -> PyResult<()> {
        let Some(list) = infos.as_mut() else {
            return Ok(());
        };
        for info in list.iter_mut() {
            if let serde_json::Value::Object(map) = info
                && let Some(text) = map.remove(envhub_protocol::info_columns::SCHEMA_KEY)
            {
                let serde_json::Value::String(text) = text else {
                    return Err(pyo3::exceptions::PyValueError::new_err(
                        "a worker announced an info-column schema that is not text\nhint: the worker runs another envhub version or misbehaves",
                    ));
                };
                self.schemas().learn(py, &text, self.info_row_bytes)?;
            }
        }
        if list
            .iter()
            .all(|i| i.is_null() || i.as_object().is_some_and(|m| m.is_empty()))
        {
            *infos = None;
        }
        Ok(())
    }

    fn check_pid(&self, py: Python<'_>) -> PyResult<()> {
        if std::process::id() != self.pid {
            return Err(forked(py, &self.id, self.pid));
        }
        Ok(())
    }

    fn lock(&self) -> MutexGuard<'_, State> {
        self.state.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// The Python exception for `e`: the Ctrl-C that interrupted a wait is re-raised as it
    /// came (the session was closed), an env failure carries the other envs' results.
    fn error(&self, py: Python<'_>, e: HubError, partial: Option<Results>) -> PyErr {
        if matches!(e, HubError::Interrupted) {
            self.closed.store(true, Ordering::SeqCst);
            if let Some(err) = self
                .interrupted
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .take()
            {
                return err;
            }
            return pyo3::exceptions::PyKeyboardInterrupt::new_err(e.to_string());
        }
        let err = hub_error(py, e);
        if let Some(partial) = partial
            && let Ok(tuple) = self.batch_tuple(py, partial, false, false)
        {
            let _ = err.value(py).setattr("results", tuple);
        }
        err
    }

    /// Runs `op` without the GIL (waiting on workers) and takes its results out.
    fn call(
        &self,
        py: Python<'_>,
        op: impl for<'a> FnOnce(&'a mut VecEnv) -> Result<Batch<'a>, HubError> + Send,
    ) -> PyResult<Results> {
        self.check_pid(py)?;
        py.detach(|| run(&mut self.lock().vec, op))
            .map_err(|failed| {
                let (e, partial) = *failed;
                self.error(py, e, partial)
            })
    }

    /// Actions as bytes, checked against the action space's dtype.
    fn action_bytes(
        &self,
        py: Python<'_>,
        actions: &Bound<'_, PyUntypedArray>,
    ) -> PyResult<Vec<u8>> {
        let want = arrays::dtype_of(py, &self.act);
        if !actions.dtype().is_equiv_to(&want) {
            return Err(raise(
                py,
                "InvalidActionError",
                format!(
                    "actions are {} but the action space takes {}\nhint: convert them with `numpy.asarray(actions, dtype=...)`",
                    actions.dtype(),
                    want
                ),
                vec![],
            ));
        }
        arrays::bytes_of(actions).ok_or_else(|| {
            raise(
                py,
                "InvalidActionError",
                "actions must be a C-contiguous array\nhint: pass `numpy.ascontiguousarray(actions)`"
                    .to_string(),
                vec![],
            )
        })
    }

    /// `(obs, rewards, terminated, truncated, info columns)` arrays of `results`: views of
    /// the batch slot with its lease as their base (returned too, for the final
    /// observations), or fresh arrays. `n` `None`: one env, no leading axis.
    fn arrays<'py>(
        &self,
        py: Python<'py>,
        place: Place,
        n: Option<usize>,
    ) -> PyResult<Arrays<'py>> {
        let count = n.unwrap_or(1);
        let cols = ArrayLayout {
            dtype: Some(envhub_core::DType::Uint8),
            shape: vec![self.info_row_bytes],
            bytes: self.info_row_bytes,
        };
        match place {
            Place::Lent {
                lease,
                obs,
                rewards,
                terminated,
                truncated,
                info_cols,
            } => {
                let owner = Bound::new(
                    py,
                    SlotOwner {
                        lease,
                        address: obs,
                        nbytes: count * self.obs.bytes,
                    },
                )?
                .into_any();
                // SAFETY: the slot holds these blocks (observations aligned for any dtype:
                // blocks start on 8-byte boundaries, rows are whole observations; rewards
                // f64, flags 0/1 bytes), and the lease in `owner`, the arrays' base, keeps the
                // slot mapped and unwritten while any of them lives.
                unsafe {
                    Ok((
                        [
                            arrays::view(&self.obs, n, obs as *const u8, owner.clone())?,
                            arrays::view(
                                &arrays::REWARDS,
                                Some(count),
                                rewards as *const u8,
                                owner.clone(),
                            )?,
                            arrays::view(
                                &arrays::FLAGS,
                                Some(count),
                                terminated as *const u8,
                                owner.clone(),
                            )?,
                            arrays::view(
                                &arrays::FLAGS,
                                Some(count),
                                truncated as *const u8,
                                owner.clone(),
                            )?,
                            if self.info_row_bytes == 0 {
                                py.None().into_bound(py)
                            } else {
                                arrays::view(
                                    &cols,
                                    Some(count),
                                    info_cols as *const u8,
                                    owner.clone(),
                                )?
                            },
                        ],
                        Some(owner),
                    ))
                }
            }
            Place::Copied {
                obs,
                rewards,
                terminated,
                truncated,
                info_cols,
            } => {
                self.copied
                    .fetch_add((count * self.obs.bytes) as u64, Ordering::Relaxed);
                Ok((
                    [
                        arrays::owned(py, &self.obs, n, obs)?,
                        PyArray1::from_vec(py, rewards).into_any(),
                        PyArray1::from_vec(py, terminated).into_any(),
                        PyArray1::from_vec(py, truncated).into_any(),
                        if self.info_row_bytes == 0 {
                            py.None().into_bound(py)
                        } else {
                            arrays::copy(py, &cols, Some(count), &info_cols)
                        },
                    ],
                    None,
                ))
            }
        }
    }

    /// `(obs, rewards, terminated, truncated, infos or None, final_obs or None[, env_ids],
    /// info columns or None)`: the columns as a `[n, info_row_bytes]` uint8 array (a view of
    /// the slot when the others are), read with the schemas the infos announce.
    ///
    /// Schemas the infos announce are taken out of them and remembered. With `ready_infos`,
    /// when every env's info is in its row under one known schema and nothing else came,
    /// the last item is Gymnasium's vector info itself, a dict of views of the rows
    /// (see [`vector_info`]), not the rows.
    fn batch_tuple<'py>(
        &self,
        py: Python<'py>,
        mut r: Results,
        with_ids: bool,
        ready_infos: bool,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let n = r.env_ids.len();
        if self.info_row_bytes > 0 {
            self.learn_schemas(py, &mut r.infos)?;
        }
        let ([obs, rewards, terminated, truncated, mut cols], owner) =
            self.arrays(py, r.place, Some(n))?;
        if ready_infos
            && n > 0
            && r.infos.is_none()
            && r.final_obs.is_none()
            && let Ok(rows) = cols.cast::<PyUntypedArray>()
        {
            let at = arrays::data_ptr(rows);
            // SAFETY: `rows` is an `[n, info_row_bytes]` uint8 array (`arrays`), C-contiguous,
            // and `info_row_bytes` is at least 8 (a layout with columns).
            let id = unsafe { uniform_id(at, n, self.info_row_bytes) };
            let schema = id.and_then(|id| self.schemas().get(id));
            if let Some(schema) = schema {
                // SAFETY: `rows` (the base of the views) owns or leases the memory, which is
                // aligned (slot blocks and numpy's allocations are 8-byte aligned) and
                // checked against `schema`.
                let dict = unsafe { vector_info(py, &schema, at, n, self.info_row_bytes, &cols)? };
                cols = dict.into_any();
            }
        }
        let infos = match &r.infos {
            None => py.None().into_bound(py),
            Some(infos) => {
                let list = PyList::empty(py);
                for info in infos {
                    list.append(info_to_py(py, info)?)?;
                }
                list.into_any()
            }
        };
        let final_obs = match r.final_obs {
            None => py.None().into_bound(py),
            Some(all) => {
                let row = ArrayLayout {
                    dtype: Some(envhub_core::DType::Uint8),
                    shape: vec![self.obs.bytes],
                    bytes: self.obs.bytes,
                };
                let list = PyList::empty(py);
                for f in all {
                    match (f, &owner) {
                        (None, _) => list.append(py.None())?,
                        // SAFETY: the row lies in the slot that `owner`'s lease keeps mapped
                        // and unwritten, `obs.bytes` bytes of it.
                        (Some(FinalObs::At(at)), Some(owner)) => list.append(unsafe {
                            arrays::view(&row, None, at as *const u8, owner.clone())?
                        })?,
                        (Some(FinalObs::Copy(words)), _) => {
                            self.copied
                                .fetch_add(self.obs.bytes as u64, Ordering::Relaxed);
                            list.append(arrays::owned(py, &row, None, words)?)?
                        }
                        (Some(FinalObs::At(_)), None) => {
                            unreachable!("a final observation in place comes with a lent slot")
                        }
                    }
                }
                list.into_any()
            }
        };
        let mut items = vec![obs, rewards, terminated, truncated, infos, final_obs];
        if with_ids {
            let ids: Vec<i64> = r.env_ids.iter().map(|&i| i as i64).collect();
            items.push(PyArray1::from_vec(py, ids).into_any());
        }
        items.push(cols);
        PyTuple::new(py, items)
    }

    /// `(obs, reward, terminated, truncated, info)` of one env.
    fn single<'py>(&self, py: Python<'py>, mut r: Results) -> PyResult<Single<'py>> {
        let info = r.infos.take().and_then(|mut i| i.pop());
        let (reward, terminated, truncated) = match &r.place {
            Place::Lent {
                rewards,
                terminated,
                truncated,
                ..
            } => {
                // SAFETY: the lease in `r.place` keeps the slot mapped; one value each.
                unsafe {
                    (
                        *(*rewards as *const f64),
                        *(*terminated as *const u8) != 0,
                        *(*truncated as *const u8) != 0,
                    )
                }
            }
            Place::Copied {
                rewards,
                terminated,
                truncated,
                ..
            } => (
                rewards.first().copied().unwrap_or(0.0),
                terminated.first().copied().unwrap_or(false),
                truncated.first().copied().unwrap_or(false),
            ),
        };
        let ([obs, ..], _) = self.arrays(py, r.place, None)?;
        let info = match &info {
            Some(i) => info_to_py(py, i)?,
            None => pyo3::types::PyDict::new(py).into_any(),
        };
        Ok((obs, reward, terminated, truncated, info))
    }
}

fn parse_options(py: Python<'_>, options_json: Option<&str>) -> PyResult<ResetOptions> {
    match options_json {
        None | Some("") => Ok(ResetOptions::new()),
        Some(text) => serde_json::from_str(text).map_err(|e| {
            invalid_config(
                py,
                format!("reset options must be a JSON-serializable dict: {e}"),
            )
        }),
    }
}

#[pymethods]
impl Session {
    /// Resets the envs where `mask` is true (all if `None`), env `i` with `seeds[i]`.
    #[pyo3(signature = (seeds, mask=None, options_json=None))]
    fn reset<'py>(
        &self,
        py: Python<'py>,
        seeds: Vec<Option<u64>>,
        mask: Option<Vec<bool>>,
        options_json: Option<&str>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let options = parse_options(py, options_json)?;
        let r = self.call(py, move |v| v.reset_with(&seeds, mask.as_deref(), &options))?;
        self.batch_tuple(py, r, false, true)
    }

    /// Steps every env with `actions` (an array of the action space's dtype, C-contiguous).
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: &Bound<'py, PyUntypedArray>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let bytes = self.action_bytes(py, actions)?;
        let r = self.call(py, move |v| v.step(&bytes))?;
        self.batch_tuple(py, r, false, true)
    }

    /// The info-column schema `id` a worker announced, as `info_schema` describes it; `None`
    /// if none was.
    fn info_schema(&self, id: u64) -> Option<(u64, Vec<ColumnTuple>)> {
        self.schemas().describe(id)
    }

    /// One env: `(obs, info)` of a reset with `seed`.
    #[pyo3(signature = (seed=None, options_json=None))]
    fn reset_single<'py>(
        &self,
        py: Python<'py>,
        seed: Option<u64>,
        options_json: Option<&str>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let options = parse_options(py, options_json)?;
        let r = self.call(py, move |v| v.reset_with(&[seed], None, &options))?;
        let (obs, _, _, _, info) = self.single(py, r)?;
        PyTuple::new(py, [obs, info])
    }

    /// One env: `(obs, reward, terminated, truncated, info)` of a step.
    fn step_single<'py>(
        &self,
        py: Python<'py>,
        action: &Bound<'py, PyUntypedArray>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let bytes = self.action_bytes(py, action)?;
        let r = self.call(py, move |v| v.step(&bytes))?;
        let (obs, reward, terminated, truncated, info) = self.single(py, r)?;
        PyTuple::new(
            py,
            [
                obs,
                reward.into_pyobject(py)?.into_any(),
                PyBool::new(py, terminated).to_owned().into_any(),
                PyBool::new(py, truncated).to_owned().into_any(),
                info,
            ],
        )
    }

    /// One frame per env (`render_mode="rgb_array"`): `(height, width, 3)` uint8 arrays, or
    /// `None` for an env that rendered nothing. Frames are copies (large, and rare).
    fn render<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        self.check_pid(py)?;
        let frames = py
            .detach(|| self.lock().vec.render())
            .map_err(|e| self.error(py, e, None))?;
        let list = PyList::empty(py);
        for frame in frames {
            match frame {
                None => list.append(py.None())?,
                Some(f) => {
                    let (h, w) = (f.height, f.width);
                    let array = PyArray1::from_vec(py, f.rgb).reshape([h, w, 3])?;
                    list.append(array)?;
                }
            }
        }
        Ok(list)
    }

    /// Sends actions to the envs in `env_ids` without waiting (collect with `recv`).
    fn send(
        &self,
        py: Python<'_>,
        actions: &Bound<'_, PyUntypedArray>,
        env_ids: Vec<usize>,
    ) -> PyResult<()> {
        self.check_pid(py)?;
        let bytes = self.action_bytes(py, actions)?;
        py.detach(|| self.lock().vec.send(&bytes, &env_ids))
            .map_err(|e| self.error(py, e, None))
    }

    /// Resets the envs in `env_ids` (env `env_ids[k]` with `seeds[k]`, the options for all)
    /// without waiting; `recv` returns their first observations like stepped envs'.
    #[pyo3(signature = (env_ids, seeds, options_json=None))]
    fn send_reset(
        &self,
        py: Python<'_>,
        env_ids: Vec<usize>,
        seeds: Vec<Option<u64>>,
        options_json: Option<&str>,
    ) -> PyResult<()> {
        self.check_pid(py)?;
        let options = parse_options(py, options_json)?;
        py.detach(|| self.lock().vec.send_reset(&env_ids, &seeds, &options))
            .map_err(|e| self.error(py, e, None))
    }

    /// EnvPool's contract: `recv` returns exactly `batch_size` envs, the first to finish.
    fn set_batch_size(&self, py: Python<'_>, batch_size: usize) -> PyResult<()> {
        self.check_pid(py)?;
        py.detach(|| self.lock().vec.set_batch_size(batch_size))
            .map_err(|e| self.error(py, e, None))
    }

    /// The EnvPool mode's batch size (`None` outside it).
    #[getter]
    fn batch_size(&self, py: Python<'_>) -> Option<usize> {
        py.detach(|| self.lock().vec.batch_size())
    }

    /// EnvPool's `async_reset`: resets every env (env `i` with `seeds[i]`) without waiting;
    /// `recv` returns them.
    fn async_reset(&self, py: Python<'_>, seeds: Vec<Option<u64>>) -> PyResult<()> {
        self.check_pid(py)?;
        py.detach(|| self.lock().vec.async_reset_with(&seeds))
            .map_err(|e| self.error(py, e, None))
    }

    /// Waits for the first workers to finish; the results of exactly the envs they stepped,
    /// with their env ids as a 7th item.
    fn recv<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let r = self.call(py, |v| v.recv())?;
        self.batch_tuple(py, r, true, false)
    }

    /// Stops the workers. Closing twice is fine; in a forked child it only marks this copy
    /// closed (the workers are the parent's). Arrays already returned stay valid.
    fn close(&self, py: Python<'_>) {
        if self.closed.swap(true, Ordering::SeqCst) || std::process::id() != self.pid {
            return;
        }
        py.detach(|| self.lock().vec.close());
    }

    /// Whether `close` was called (or the session ended on Ctrl-C).
    #[getter]
    fn closed(&self) -> bool {
        self.closed.load(Ordering::SeqCst)
    }

    /// Batch slots (whole batches of results in shared memory) created so far: slots stay
    /// while arrays view them, so this grows with the arrays a user keeps, up to the cap.
    #[getter]
    fn slots(&self, py: Python<'_>) -> usize {
        py.detach(|| self.lock().vec.slots_in_use())
    }

    /// Observation bytes copied on the client so far (0 when every result was viewed in
    /// place): rows the session gathered out of workers' rows, and results it could not lend
    /// in place (the scratch slot), each copy counted.
    #[getter]
    fn obs_bytes_copied(&self, py: Python<'_>) -> u64 {
        py.detach(|| self.lock().vec.obs_bytes_copied()) + self.copied.load(Ordering::Relaxed)
    }
}
