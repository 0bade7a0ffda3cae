//! `Session`: a `VecEnv` shared with Python, and `SharedSample`, the owner object through
//! which numpy arrays keep a worker's shared-memory response alive.
//!
//! Ownership: when a batch's observations lie in place in the one worker's response, the
//! response is taken out of the `VecEnv` (so the next step cannot drop it) and parked in the
//! session's `held` map; a `SharedSample` names it and is the numpy array's base. When the
//! last array viewing it goes away, the sample is released. iceoryx2 lets a client borrow at
//! most `MAX_BORROWED_RESPONSES` samples per worker, one of which the session needs for the
//! next response, so at most `LENDABLE` are lent: past that, observations are copied into a
//! fresh array instead of blocking the worker or failing. Sessions with several workers have
//! their observations in several samples; those are gathered by the hub and copied into one
//! fresh array (one numpy array per batch either way).

use crate::arrays::{self, ArrayLayout};
use crate::convert::info_to_py;
use crate::errors::{forked, hub_error, raise};
use crate::registry::PyRegistry;
use envhub::{
    AutoresetMode, Batch, EnvConfig, Hub, HubError, MAX_BORROWED_RESPONSES, ResetOptions, Response,
    VecEnv,
};
use numpy::{PyArray1, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray, PyUntypedArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyBytes, PyList, PyTuple};
use std::collections::HashMap;
use std::mem::ManuallyDrop;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError, TryLockError};
use std::time::Duration;

/// Responses lent to Python at once per session; the session keeps one for itself.
pub(crate) const LENDABLE: usize = MAX_BORROWED_RESPONSES - 1;

/// Everything of a session that touches iceoryx2.
struct State {
    vec: ManuallyDrop<VecEnv>,
    /// Responses lent to numpy arrays, by slot.
    held: ManuallyDrop<HashMap<u64, Response>>,
    next_slot: u64,
    pid: u32,
}

// SAFETY: iceoryx2's `ipc` ports and samples count their shared parts without atomics, so
// they must never be used from two threads at the same time. Every one of them lives in a
// `State` (the session's ports in `vec`, the lent samples in `held`), and a `State` is only
// reached through the `Mutex` of its `Shared`: uses are serialized, and moving the whole
// group between threads is sound.
unsafe impl Send for State {}

impl Drop for State {
    fn drop(&mut self) {
        if std::process::id() != self.pid {
            // A forked child's copy: the workers and samples are the parent's; closing or
            // releasing them here would corrupt the parent's session. Leak them.
            return;
        }
        // SAFETY: dropped once, here, and never used again.
        unsafe {
            ManuallyDrop::drop(&mut self.held);
            ManuallyDrop::drop(&mut self.vec);
        }
    }
}

/// A session's state and the queue of samples released while it was busy.
struct Shared {
    state: Mutex<State>,
    released: Mutex<Vec<u64>>,
    pid: u32,
}

impl Shared {
    /// Locks the state and releases the samples queued meanwhile.
    fn lock(&self) -> MutexGuard<'_, State> {
        let mut st = self.state.lock().unwrap_or_else(PoisonError::into_inner);
        let queued =
            std::mem::take(&mut *self.released.lock().unwrap_or_else(PoisonError::into_inner));
        for slot in queued {
            st.held.remove(&slot);
        }
        st
    }

    /// Releases a lent sample now, or queues it when the session is busy (a step in another
    /// thread): never waits, so dropping an array never blocks on a step.
    fn release(&self, slot: u64) {
        match self.state.try_lock() {
            Ok(mut st) => {
                st.held.remove(&slot);
            }
            Err(TryLockError::Poisoned(p)) => {
                p.into_inner().held.remove(&slot);
            }
            Err(TryLockError::WouldBlock) => self
                .released
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .push(slot),
        }
    }
}

/// The base object of observation arrays that view a worker's shared-memory response: while
/// it lives, the response is not reused.
#[pyclass(name = "SharedSample", module = "envhub._envhub", frozen)]
pub(crate) struct SampleOwner {
    shared: Arc<Shared>,
    slot: u64,
    address: usize,
    nbytes: usize,
}

#[pymethods]
impl SampleOwner {
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

    fn __repr__(&self) -> String {
        format!(
            "<envhub shared-memory sample: {} bytes at {:#x}>",
            self.nbytes, self.address
        )
    }
}

impl Drop for SampleOwner {
    fn drop(&mut self) {
        if std::process::id() == self.shared.pid {
            self.shared.release(self.slot);
        }
    }
}

/// Where a batch's observations went.
enum Obs {
    /// Left in the worker's response, lent under `slot`.
    Lent { slot: u64, address: usize },
    /// Copied into the array allocated before the call.
    Filled,
    /// Copied here.
    Copied(Vec<u8>),
}

/// A batch's results, taken out of the session (no borrow of it left).
struct Results {
    env_ids: Vec<usize>,
    obs: Obs,
    rewards: Vec<f64>,
    terminated: Vec<bool>,
    truncated: Vec<bool>,
    infos: Option<Vec<serde_json::Value>>,
    final_obs: Option<Vec<Option<Vec<u8>>>>,
}

/// Runs `op` on the session and takes its results out: the observations lent if they lie in
/// place and the pool allows, else copied (into `fill`, an array of the whole batch, when
/// given).
fn run(
    st: &mut State,
    fill: Option<usize>,
    op: impl for<'a> FnOnce(&'a mut VecEnv) -> Result<Batch<'a>, HubError>,
) -> Result<Results, HubError> {
    let same_step = st.vec.autoreset_mode() == AutoresetMode::SameStep;
    let can_lend = fill.is_none() && st.held.len() < LENDABLE;
    let (mut results, lend) = {
        let batch = op(&mut st.vec)?;
        let n = batch.env_ids.len();
        let lend = can_lend && batch.in_place();
        let obs = if lend {
            Obs::Filled // replaced below, once the batch no longer borrows the session
        } else if let Some(dst) = fill {
            // SAFETY: `fill` is a fresh array of the whole batch that only this call sees.
            unsafe { arrays::copy_into(dst, batch.obs) };
            Obs::Filled
        } else {
            Obs::Copied(batch.obs.to_vec())
        };
        let final_obs = if same_step {
            let all: Vec<Option<Vec<u8>>> = (0..n)
                .map(|k| batch.final_obs(k).map(<[u8]>::to_vec))
                .collect();
            all.iter().any(Option::is_some).then_some(all)
        } else {
            None
        };
        let results = Results {
            env_ids: batch.env_ids.to_vec(),
            obs,
            rewards: batch.rewards.to_vec(),
            terminated: batch.terminated.to_vec(),
            truncated: batch.truncated.to_vec(),
            infos: batch
                .has_info()
                .then(|| (0..n).map(|k| batch.info(k).clone()).collect()),
            final_obs,
        };
        (results, lend)
    };
    if lend {
        let response = st
            .vec
            .take_response()
            .expect("results in place have a response to take");
        let address = response.blocks().obs.as_ptr() as usize;
        let slot = st.next_slot;
        st.next_slot += 1;
        st.held.insert(slot, response);
        results.obs = Obs::Lent { slot, address };
    }
    Ok(results)
}

/// A batch of envs in worker processes (the compiled half of `envhub.VectorEnv` and
/// `envhub.Env`).
#[pyclass(name = "Session", module = "envhub._envhub", frozen)]
pub(crate) struct Session {
    shared: Arc<Shared>,
    closed: AtomicBool,
    id: String,
    adapter: String,
    env_id: String,
    num_envs: usize,
    num_workers: usize,
    worker_pids: Vec<u32>,
    max_episode_steps: Option<u32>,
    render_fps: Option<f64>,
    autoreset_mode: String,
    observation_space: String,
    action_space: String,
    obs_leaves: String,
    action_leaves: String,
    obs: ArrayLayout,
    act: ArrayLayout,
}

/// A session made without the GIL, not yet shared with Python.
struct Made(State);

// SAFETY: as for `State`: nothing else refers to its iceoryx2 parts.
unsafe impl Send for Made {}

pub(crate) fn leaves_json(space: &envhub::Space) -> String {
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
/// usual way.
#[pyfunction]
#[pyo3(signature = (id, num_envs, config_json, registry=None, step_timeout=None, restart_on_crash=false))]
pub(crate) fn make_session(
    py: Python<'_>,
    id: String,
    num_envs: usize,
    config_json: &str,
    registry: Option<PyRef<'_, PyRegistry>>,
    step_timeout: Option<f64>,
    restart_on_crash: bool,
) -> PyResult<Session> {
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
    let made = py
        .detach(move || -> Result<Made, HubError> {
            let hub = match registry {
                None => Hub::from_env()?,
                Some(registry) => {
                    match std::env::var_os(envhub::env_vars::ENVHUB_HUB).filter(|s| !s.is_empty()) {
                        Some(socket) => Hub::connect(std::path::Path::new(&socket), registry)?,
                        None => Hub::new(registry),
                    }
                }
            };
            let mut options = hub.options().clone();
            if let Some(t) = timeout {
                options.step_timeout = t;
            }
            options.restart_on_crash = restart_on_crash;
            let vec = hub.with_options(options).make_vec(&id, num_envs, &config)?;
            Ok(Made(State {
                vec: ManuallyDrop::new(vec),
                held: ManuallyDrop::new(HashMap::new()),
                next_slot: 0,
                pid: std::process::id(),
            }))
        })
        .map_err(|e| hub_error(py, e))?;
    let st = made.0;
    let v = &*st.vec;
    let session = Session {
        closed: AtomicBool::new(false),
        id: v.id().to_string(),
        adapter: v.route().adapter.clone(),
        env_id: v.route().env_id.clone(),
        num_envs: v.num_envs(),
        num_workers: v.num_workers(),
        worker_pids: v.worker_pids(),
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
        shared: Arc::new(Shared {
            pid: st.pid,
            state: Mutex::new(st),
            released: Mutex::new(Vec::new()),
        }),
    };
    Ok(session)
}

impl Session {
    fn check_pid(&self, py: Python<'_>) -> PyResult<()> {
        if std::process::id() != self.shared.pid {
            return Err(forked(py, &self.id, self.shared.pid));
        }
        Ok(())
    }

    /// Runs `op` without the GIL (waiting on workers) and takes its results out.
    fn call(
        &self,
        py: Python<'_>,
        fill: Option<usize>,
        op: impl for<'a> FnOnce(&'a mut VecEnv) -> Result<Batch<'a>, HubError> + Send,
    ) -> PyResult<Results> {
        self.check_pid(py)?;
        let shared = &self.shared;
        py.detach(move || run(&mut shared.lock(), fill, op))
            .map_err(|e| hub_error(py, e))
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

    /// The observation array of `results` (`n` values, or one without a leading axis).
    fn obs_array<'py>(
        &self,
        py: Python<'py>,
        obs: Obs,
        n: Option<usize>,
        filled: Option<Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, PyAny>> {
        let count = n.unwrap_or(1);
        match obs {
            Obs::Lent { slot, address } => {
                let owner = SampleOwner {
                    shared: self.shared.clone(),
                    slot,
                    address,
                    nbytes: count * self.obs.bytes,
                };
                let owner = Bound::new(py, owner)?;
                // SAFETY: the sample in `slot` holds these bytes, aligned for any dtype
                // (blocks start on 8-byte boundaries), and is neither reused nor freed until
                // the owner, the array's base, is dropped.
                unsafe { arrays::view(&self.obs, n, address as *const u8, owner.into_any()) }
            }
            Obs::Filled => Ok(filled.expect("a filled array was allocated")),
            Obs::Copied(bytes) => Ok(arrays::copy(py, &self.obs, n, &bytes)),
        }
    }

    /// `(obs, rewards, terminated, truncated, infos or None, final_obs or None)`.
    fn batch_tuple<'py>(
        &self,
        py: Python<'py>,
        r: Results,
        filled: Option<Bound<'py, PyAny>>,
        with_ids: bool,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let n = r.env_ids.len();
        let obs = self.obs_array(py, r.obs, Some(n), filled)?;
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
        let final_obs = match &r.final_obs {
            None => py.None().into_bound(py),
            Some(all) => {
                let list = PyList::empty(py);
                for f in all {
                    match f {
                        Some(bytes) => list.append(PyBytes::new(py, bytes))?,
                        None => list.append(py.None())?,
                    }
                }
                list.into_any()
            }
        };
        let mut items = vec![
            obs,
            PyArray1::from_vec(py, r.rewards).into_any(),
            PyArray1::from_vec(py, r.terminated).into_any(),
            PyArray1::from_vec(py, r.truncated).into_any(),
            infos,
            final_obs,
        ];
        if with_ids {
            let ids: Vec<i64> = r.env_ids.iter().map(|&i| i as i64).collect();
            items.push(PyArray1::from_vec(py, ids).into_any());
        }
        PyTuple::new(py, items)
    }

    /// A fresh array for a whole batch of observations when they will be gathered anyway.
    fn prealloc<'py>(&self, py: Python<'py>) -> (Option<Bound<'py, PyAny>>, Option<usize>) {
        if self.num_workers > 1 {
            let (array, ptr) = arrays::empty(py, &self.obs, Some(self.num_envs));
            (Some(array), Some(ptr))
        } else {
            (None, None)
        }
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
        let (filled, fill) = if mask.is_none() {
            self.prealloc(py)
        } else {
            (None, None)
        };
        let r = self.call(py, fill, move |v| {
            v.reset_with(&seeds, mask.as_deref(), &options)
        })?;
        self.batch_tuple(py, r, filled, false)
    }

    /// Steps every env with `actions` (an array of the action space's dtype, C-contiguous).
    fn step<'py>(
        &self,
        py: Python<'py>,
        actions: &Bound<'py, PyUntypedArray>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let bytes = self.action_bytes(py, actions)?;
        let (filled, fill) = self.prealloc(py);
        let r = self.call(py, fill, move |v| v.step(&bytes))?;
        self.batch_tuple(py, r, filled, false)
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
        let mut r = self.call(py, None, move |v| v.reset_with(&[seed], None, &options))?;
        let info = r.infos.take().and_then(|mut i| i.pop());
        let obs = self.obs_array(py, r.obs, None, None)?;
        let info = match &info {
            Some(i) => info_to_py(py, i)?,
            None => pyo3::types::PyDict::new(py).into_any(),
        };
        PyTuple::new(py, [obs, info])
    }

    /// One env: `(obs, reward, terminated, truncated, info)` of a step.
    fn step_single<'py>(
        &self,
        py: Python<'py>,
        action: &Bound<'py, PyUntypedArray>,
    ) -> PyResult<Bound<'py, PyTuple>> {
        let bytes = self.action_bytes(py, action)?;
        let mut r = self.call(py, None, move |v| v.step(&bytes))?;
        let info = r.infos.take().and_then(|mut i| i.pop());
        let reward = r.rewards.first().copied().unwrap_or(0.0);
        let terminated = r.terminated.first().copied().unwrap_or(false);
        let truncated = r.truncated.first().copied().unwrap_or(false);
        let obs = self.obs_array(py, r.obs, None, None)?;
        let info = match &info {
            Some(i) => info_to_py(py, i)?,
            None => pyo3::types::PyDict::new(py).into_any(),
        };
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
        let shared = &self.shared;
        let frames = py
            .detach(move || shared.lock().vec.render())
            .map_err(|e| hub_error(py, e))?;
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
        let shared = &self.shared;
        py.detach(move || shared.lock().vec.send(&bytes, &env_ids))
            .map_err(|e| hub_error(py, e))
    }

    /// Waits for the first workers to finish; their results with the env ids as a 7th item.
    fn recv<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyTuple>> {
        let r = self.call(py, None, |v| v.recv())?;
        self.batch_tuple(py, r, None, true)
    }

    /// Stops the workers. Closing twice is fine; in a forked child it only marks this copy
    /// closed (the workers are the parent's).
    fn close(&self, py: Python<'_>) {
        if self.closed.swap(true, Ordering::SeqCst) || std::process::id() != self.shared.pid {
            return;
        }
        let shared = &self.shared;
        py.detach(move || shared.lock().vec.close());
    }

    /// Whether `close` was called.
    #[getter]
    fn closed(&self) -> bool {
        self.closed.load(Ordering::SeqCst)
    }

    /// Samples lent to arrays right now (at most `LENDABLE`; later arrays are copies).
    #[getter]
    fn lent(&self, py: Python<'_>) -> usize {
        let shared = &self.shared;
        py.detach(move || shared.lock().held.len())
    }

    /// Registry id.
    #[getter]
    fn id(&self) -> &str {
        &self.id
    }

    /// Adapter that runs the envs.
    #[getter]
    fn adapter(&self) -> &str {
        &self.adapter
    }

    /// The framework's env id.
    #[getter]
    fn env_id(&self) -> &str {
        &self.env_id
    }

    /// Number of envs.
    #[getter]
    fn num_envs(&self) -> usize {
        self.num_envs
    }

    /// Number of worker processes.
    #[getter]
    fn num_workers(&self) -> usize {
        self.num_workers
    }

    /// Worker pids, in env order.
    #[getter]
    fn worker_pids(&self) -> Vec<u32> {
        self.worker_pids.clone()
    }

    /// Pid of the process that made the session.
    #[getter]
    fn owner_pid(&self) -> u32 {
        self.shared.pid
    }

    /// The episode limit applied, if any.
    #[getter]
    fn max_episode_steps(&self) -> Option<u32> {
        self.max_episode_steps
    }

    /// Frames per second of the envs' rendering (Gymnasium's `metadata["render_fps"]`), if
    /// the env says.
    #[getter]
    fn render_fps(&self) -> Option<f64> {
        self.render_fps
    }

    /// `next_step`, `same_step` or `disabled`.
    #[getter]
    fn autoreset_mode(&self) -> &str {
        &self.autoreset_mode
    }

    /// Observation space of one env, as JSON.
    #[getter]
    fn observation_space_json(&self) -> &str {
        &self.observation_space
    }

    /// Action space of one env, as JSON.
    #[getter]
    fn action_space_json(&self) -> &str {
        &self.action_space
    }

    /// Leaves of the observation space with their byte offsets, as JSON.
    #[getter]
    fn obs_leaves_json(&self) -> &str {
        &self.obs_leaves
    }

    /// Leaves of the action space with their byte offsets, as JSON.
    #[getter]
    fn action_leaves_json(&self) -> &str {
        &self.action_leaves
    }
}
