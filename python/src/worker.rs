//! The Python worker's Rust half: `python -m envhub.worker serve` creates its envs in Python
//! and hands them to [`serve_worker`], which runs the same serve loop as the Rust worker
//! binary ([`envhub_shm::serve_batch`]) with the worker's Python envs as one batch
//! (`envhub.worker.batch.HostedBatch`, one call into Python per request); or, for a simulator that
//! holds all of the worker's envs in one vector env, to [`serve_vector_worker`], which serves
//! that object as the whole batch.
//!
//! Why a Python process driving the Rust loop rather than CPython embedded in
//! `envhub-worker`: the worker then runs in the user's own interpreter (the project's `.venv`
//! or `ENVHUB_PYTHON`), so their installed simulators, `sys.path` and numpy are simply there;
//! libpython stays out of the Rust worker binary (which keeps building and running where
//! Python is absent); and the module reused here is the one the client already ships. The
//! cost is a second entry point (`python -m envhub.worker`) the hub must know how to start.
//!
//! Copies kept to what Python needs: the wrapper gets a read-only view of the request sample
//! and copies the batch's actions once, into an array the envs own (the sample is reused by
//! later requests, and an env may keep its action, as "previous action" features do); each
//! observation is copied once, by numpy, into its row of the batch slot.

use envhub_core::{EnvError, ResetOptions, Space};
use envhub_shm::{
    Frame, ReadySpec, ResponseBlocksMut, ServedBatch, WorkerIdentity, WorkerJob, env_flag,
    frames_section,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use std::io::Write;

/// A numpy-ready `memoryview` over `bytes` (writable or not), valid while `bytes` is.
fn memory_view<'py>(
    py: Python<'py>,
    ptr: *const u8,
    len: usize,
    writable: bool,
) -> PyResult<Bound<'py, PyAny>> {
    // `PyBUF_WRITE` / `PyBUF_READ` of `memoryobject.h`, stable ABI since 3.3; pyo3-ffi
    // exports them only with the buffer protocol (stable from 3.11), and the module is
    // built for the stable ABI of 3.9.
    const PYBUF_READ: std::ffi::c_int = 0x100;
    const PYBUF_WRITE: std::ffi::c_int = 0x200;
    let flags = if writable { PYBUF_WRITE } else { PYBUF_READ };
    // SAFETY: the memory stays mapped for the whole call that uses the view (it is the
    // request or response sample being served); the wrappers in `envhub.worker` copy what an
    // env may keep beyond it (its action).
    unsafe {
        let view = pyo3::ffi::PyMemoryView_FromMemory(
            ptr as *mut std::ffi::c_char,
            len as pyo3::ffi::Py_ssize_t,
            flags,
        );
        Bound::from_owned_ptr_or_err(py, view)
    }
}

/// The Python traceback of `err`, as Python prints it.
fn traceback(py: Python<'_>, err: &PyErr) -> String {
    let formatted = py.import("traceback").and_then(|tb| {
        tb.call_method1(
            "format_exception",
            (err.get_type(py), err.value(py), err.traceback(py)),
        )?
        .extract::<Vec<String>>()
    });
    match formatted {
        Ok(lines) => lines.concat().trim_end().to_string(),
        Err(_) => err.to_string(),
    }
}

/// The error for a Python exception raised by `env_id`'s `what`, with its traceback.
fn python_failed(py: Python<'_>, env_id: &str, what: &str, err: PyErr) -> EnvError {
    EnvError::Simulator {
        env_id: env_id.to_string(),
        reason: format!(
            "the Python env raised in `{what}`:\n{}",
            traceback(py, &err)
        ),
    }
}

/// All of a worker's Python envs (one env object each), through the wrapper
/// `envhub.worker.batch.HostedBatch` (methods `reset_into`, `step_into`, `render_rgb`, `close`):
/// one call into Python per request for the whole batch, not one per env. The wrapper loops
/// over the envs, applies the autoreset mode as [`EnvBatch`](envhub_shm::EnvBatch) does for
/// native envs, writes each result straight into the env's rows of the blocks it is given
/// (typed info columns included, when the session has them) and answers with the info
/// section (JSON text of the infos that did not go into columns, or `None`) and the envs
/// that raised, so one env's exception does not cost the others their step.
struct PyBatch {
    batch: Py<PyAny>,
    env_id: String,
    num_envs: usize,
    failures: Vec<(usize, String)>,
}

/// What `HostedBatch.reset_into` / `step_into` return: the info section, and
/// `(env index, method, traceback)` for each env that raised.
type BatchAnswer = (Option<String>, Vec<(usize, String, String)>);

impl PyBatch {
    fn failed(&self, py: Python<'_>, what: &str, err: PyErr) -> EnvError {
        python_failed(py, &self.env_id, what, err)
    }

    /// The info section of an answer, keeping its failed envs for `take_failures`.
    fn answer(&mut self, (info, failed): BatchAnswer) -> Vec<u8> {
        for (i, what, tb) in failed {
            let e = EnvError::Simulator {
                env_id: self.env_id.clone(),
                reason: format!("the Python env raised in `{what}`:\n{tb}"),
            };
            self.failures.push((i, e.to_string()));
        }
        info.map(String::into_bytes).unwrap_or_default()
    }
}

/// A writable memoryview of `block`, or `None` when it is empty (a block the slot lacks).
fn optional_view<'py>(py: Python<'py>, block: &mut [u8]) -> PyResult<Option<Bound<'py, PyAny>>> {
    if block.is_empty() {
        return Ok(None);
    }
    memory_view(py, block.as_mut_ptr(), block.len(), true).map(Some)
}

impl ServedBatch for PyBatch {
    fn len(&self) -> usize {
        self.num_envs
    }

    fn reset(
        &mut self,
        flags: &[u8],
        seeds: &[u64],
        options: &ResetOptions,
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError> {
        let seeds: Vec<Option<u64>> = flags
            .iter()
            .zip(seeds)
            .map(|(f, &s)| (f & env_flag::SEEDED != 0).then_some(s))
            .collect();
        let got = Python::attach(|py| {
            let run = || -> PyResult<BatchAnswer> {
                let options = (!options.is_empty())
                    .then(|| serde_json::to_string(options).unwrap_or_default());
                let args = (
                    selected(flags),
                    seeds,
                    options,
                    memory_view(py, out.obs.as_mut_ptr(), out.obs.len(), true)?,
                    f64_view(py, out.rewards)?,
                    memory_view(py, out.terminated.as_mut_ptr(), out.terminated.len(), true)?,
                    memory_view(py, out.truncated.as_mut_ptr(), out.truncated.len(), true)?,
                    memory_view(py, out.final_mask.as_mut_ptr(), out.final_mask.len(), true)?,
                    optional_view(py, out.info_cols)?,
                );
                self.batch.call_method1(py, "reset_into", args)?.extract(py)
            };
            run().map_err(|e| self.failed(py, "reset", e))
        })?;
        Ok(self.answer(got))
    }

    fn step(
        &mut self,
        flags: &[u8],
        actions: &[u8],
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError> {
        let got = Python::attach(|py| {
            let mut run = || -> PyResult<BatchAnswer> {
                let args = (
                    selected(flags),
                    memory_view(py, actions.as_ptr(), actions.len(), false)?,
                    memory_view(py, out.obs.as_mut_ptr(), out.obs.len(), true)?,
                    f64_view(py, out.rewards)?,
                    memory_view(py, out.terminated.as_mut_ptr(), out.terminated.len(), true)?,
                    memory_view(py, out.truncated.as_mut_ptr(), out.truncated.len(), true)?,
                    memory_view(py, out.final_mask.as_mut_ptr(), out.final_mask.len(), true)?,
                    optional_view(py, out.final_obs)?,
                    optional_view(py, out.info_cols)?,
                );
                self.batch.call_method1(py, "step_into", args)?.extract(py)
            };
            run().map_err(|e| self.failed(py, "step", e))
        })?;
        Ok(self.answer(got))
    }

    fn render(&mut self, flags: &[u8]) -> Result<Vec<u8>, EnvError> {
        let frames = Python::attach(|py| {
            let frames: PyResult<Vec<Option<Frame>>> = self
                .batch
                .call_method1(py, "render_rgb", (selected(flags),))
                .and_then(|f| f.extract(py));
            frames.map_err(|e| self.failed(py, "render", e))
        })?;
        Ok(frames_section(frames))
    }

    fn close(&mut self) {
        Python::attach(|py| {
            if let Err(e) = self.batch.call_method0(py, "close") {
                tracing::warn!(env_id = %self.env_id, "close raised: {}", traceback(py, &e));
            }
        });
    }

    fn take_failures(&mut self) -> Vec<(usize, String)> {
        std::mem::take(&mut self.failures)
    }
}

/// A simulator that holds all of the worker's envs in one object (a Gymnasium `VectorEnv`:
/// Isaac Lab, `gymnasium.make_vec(..., vectorization_mode="vector_entry_point")`), through
/// the wrapper `envhub.worker.batch.HostedVectorEnv` (methods `reset_into`, `step_into`,
/// `render_rgb`, `close`). It steps every env at once and autoresets them itself; the wrapper
/// checked when it was made that its autoreset mode is the session's. Each call hands the
/// wrapper memoryviews of whole blocks, so every result is copied once, batched.
struct PyVectorEnv {
    env: Py<PyAny>,
    env_id: String,
    num_envs: usize,
    /// The session's id of the first env (for error messages).
    env_offset: usize,
}

impl PyVectorEnv {
    fn failed(&self, py: Python<'_>, what: &str, err: PyErr) -> EnvError {
        python_failed(py, &self.env_id, what, err)
    }
}

fn selected(flags: &[u8]) -> Vec<bool> {
    flags.iter().map(|f| f & env_flag::SELECTED != 0).collect()
}

/// A writable memoryview of a block of `f64`s.
fn f64_view<'py>(py: Python<'py>, block: &mut [f64]) -> PyResult<Bound<'py, PyAny>> {
    memory_view(
        py,
        block.as_mut_ptr().cast(),
        std::mem::size_of_val(block),
        true,
    )
}

impl ServedBatch for PyVectorEnv {
    fn len(&self) -> usize {
        self.num_envs
    }

    fn reset(
        &mut self,
        flags: &[u8],
        seeds: &[u64],
        options: &ResetOptions,
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError> {
        let seeds: Vec<Option<u64>> = flags
            .iter()
            .zip(seeds)
            .map(|(f, &s)| (f & env_flag::SEEDED != 0).then_some(s))
            .collect();
        out.rewards.fill(0.0);
        out.terminated.fill(0);
        out.truncated.fill(0);
        out.final_mask.fill(0);
        let info = Python::attach(|py| {
            let run = || -> PyResult<Option<String>> {
                let obs = memory_view(py, out.obs.as_mut_ptr(), out.obs.len(), true)?;
                let options = (!options.is_empty())
                    .then(|| serde_json::to_string(options).unwrap_or_default());
                self.env
                    .call_method1(py, "reset_into", (selected(flags), seeds, options, obs))?
                    .extract(py)
            };
            run().map_err(|e| self.failed(py, "reset", e))
        })?;
        Ok(info.map(String::into_bytes).unwrap_or_default())
    }

    fn step(
        &mut self,
        flags: &[u8],
        actions: &[u8],
        out: &mut ResponseBlocksMut<'_>,
    ) -> Result<Vec<u8>, EnvError> {
        let stepped = flags
            .iter()
            .filter(|&&f| f & env_flag::SELECTED != 0)
            .count();
        if stepped != self.num_envs {
            let (first, last) = (self.env_offset, self.env_offset + self.num_envs - 1);
            return Err(EnvError::Simulator {
                env_id: self.env_id.clone(),
                reason: format!(
                    "its vector env steps its {} envs (env ids {first} to {last}) together, and this step selects {stepped} of them; step all of them\nhint: `step(actions)`, or `send` an action to every one of env ids {first} to {last} at once",
                    self.num_envs
                ),
            });
        }
        out.final_mask.fill(0);
        let info = Python::attach(|py| {
            let mut run = || -> PyResult<Option<String>> {
                let act = memory_view(py, actions.as_ptr(), actions.len(), false)?;
                let obs = memory_view(py, out.obs.as_mut_ptr(), out.obs.len(), true)?;
                let rewards = f64_view(py, out.rewards)?;
                let terminated =
                    memory_view(py, out.terminated.as_mut_ptr(), out.terminated.len(), true)?;
                let truncated =
                    memory_view(py, out.truncated.as_mut_ptr(), out.truncated.len(), true)?;
                // Only same_step sessions have a final-observation block.
                let final_obs = if out.final_obs.is_empty() {
                    None
                } else {
                    Some(memory_view(
                        py,
                        out.final_obs.as_mut_ptr(),
                        out.final_obs.len(),
                        true,
                    )?)
                };
                let final_mask =
                    memory_view(py, out.final_mask.as_mut_ptr(), out.final_mask.len(), true)?;
                self.env
                    .call_method1(
                        py,
                        "step_into",
                        (
                            act, obs, rewards, terminated, truncated, final_obs, final_mask,
                        ),
                    )?
                    .extract(py)
            };
            run().map_err(|e| self.failed(py, "step", e))
        })?;
        Ok(info.map(String::into_bytes).unwrap_or_default())
    }

    fn render(&mut self, flags: &[u8]) -> Result<Vec<u8>, EnvError> {
        let frames = Python::attach(|py| {
            let frames: PyResult<Vec<Option<Frame>>> = self
                .env
                .call_method1(py, "render_rgb", (selected(flags),))
                .and_then(|f| f.extract(py));
            frames.map_err(|e| self.failed(py, "render", e))
        })?;
        Ok(frames_section(frames))
    }

    fn close(&mut self) {
        Python::attach(|py| {
            if let Err(e) = self.env.call_method0(py, "close") {
                tracing::warn!(env_id = %self.env_id, "close raised: {}", traceback(py, &e));
            }
        });
    }
}

fn parse_space(what: &str, json: &str) -> PyResult<Space> {
    serde_json::from_str(json)
        .map_err(|e| PyValueError::new_err(format!("invalid {what} space `{json}`: {e}")))
}

/// The job and the spec a ready worker reports, from `serve_worker`'s arguments.
fn job_and_spec(
    py: Python<'_>,
    job_json: &str,
    observation_space: &str,
    action_space: &str,
    max_episode_steps: Option<u32>,
    render_fps: Option<f64>,
) -> PyResult<(WorkerJob, ReadySpec)> {
    let job: WorkerJob = serde_json::from_str(job_json)
        .map_err(|e| PyValueError::new_err(format!("invalid job: {e}")))?;
    let ready = ReadySpec {
        observation_space: parse_space("observation", observation_space)?,
        action_space: parse_space("action", action_space)?,
        max_episode_steps,
        render_fps,
        pid: std::process::id(),
        worker: Some(WorkerIdentity::current(package_folder(py)?)),
    };
    Ok((job, ready))
}

/// The folder of the `envhub` package this worker imported (what its ready line reports).
fn package_folder(py: Python<'_>) -> PyResult<std::path::PathBuf> {
    py.import("envhub")?
        .getattr("__path__")?
        .get_item(0)?
        .extract::<std::path::PathBuf>()
}

/// Runs the serve loop for `batch`, with the GIL released while waiting for requests; the
/// ready line goes to the file descriptor `reply_fd`.
fn serve(
    py: Python<'_>,
    job: &WorkerJob,
    batch: impl ServedBatch + Send,
    ready: ReadySpec,
    reply_fd: i32,
) -> PyResult<()> {
    // SAFETY: the caller passes a descriptor it owns and keeps open (a dup of stdout).
    let fd = unsafe { std::os::fd::BorrowedFd::borrow_raw(reply_fd) };
    let mut out = std::fs::File::from(
        fd.try_clone_to_owned()
            .map_err(|e| PyRuntimeError::new_err(format!("bad reply descriptor: {e}")))?,
    );
    let span = tracing::info_span!("worker", adapter = %job.adapter, env_id = %job.env_id, pid = std::process::id());
    py.detach(|| {
        let _guard = span.enter();
        envhub_shm::serve_batch(job, batch, ready, |line| {
            let text = serde_json::to_string(line).map_err(std::io::Error::other)?;
            out.write_all(text.as_bytes())?;
            out.write_all(b"\n")?;
            out.flush()
        })
    })
    .map_err(|e| PyRuntimeError::new_err(format!("worker data plane failed: {e}")))
}

/// Serves `batch` (an `envhub.worker.batch.HostedBatch` over the job's envs) for the job `job_json` until the client
/// closes the session or exits: prints the ready line on the file descriptor `reply_fd`,
/// then answers requests. `max_episode_steps` is the limit the envs apply themselves and
/// `render_fps` their `metadata["render_fps"]` (both reported to the client). Releases the
/// GIL while waiting for requests.
#[pyfunction]
#[pyo3(signature = (job_json, observation_space, action_space, max_episode_steps, batch, reply_fd, render_fps=None))]
#[expect(
    clippy::too_many_arguments,
    reason = "the Python function's parameters, one each"
)]
pub(crate) fn serve_worker(
    py: Python<'_>,
    job_json: &str,
    observation_space: &str,
    action_space: &str,
    max_episode_steps: Option<u32>,
    batch: Py<PyAny>,
    reply_fd: i32,
    render_fps: Option<f64>,
) -> PyResult<()> {
    let (job, ready) = job_and_spec(
        py,
        job_json,
        observation_space,
        action_space,
        max_episode_steps,
        render_fps,
    )?;
    let num_envs: usize = batch.getattr(py, "num_envs")?.extract(py)?;
    let batch = PyBatch {
        batch,
        env_id: job.env_id.clone(),
        num_envs,
        failures: Vec::new(),
    };
    serve(py, &job, batch, ready, reply_fd)
}

/// As [`serve_worker`], for one `envhub.worker.batch.HostedVectorEnv` holding all of the job's
/// envs (its `num_envs`; the loop refuses a count that is not the job's): it steps them
/// together and autoresets them itself.
#[pyfunction]
#[pyo3(signature = (job_json, observation_space, action_space, max_episode_steps, vector_env, reply_fd, render_fps=None))]
#[expect(
    clippy::too_many_arguments,
    reason = "the Python function's parameters, one each"
)]
pub(crate) fn serve_vector_worker(
    py: Python<'_>,
    job_json: &str,
    observation_space: &str,
    action_space: &str,
    max_episode_steps: Option<u32>,
    vector_env: Py<PyAny>,
    reply_fd: i32,
    render_fps: Option<f64>,
) -> PyResult<()> {
    let (job, ready) = job_and_spec(
        py,
        job_json,
        observation_space,
        action_space,
        max_episode_steps,
        render_fps,
    )?;
    let num_envs: usize = vector_env.getattr(py, "num_envs")?.extract(py)?;
    let batch = PyVectorEnv {
        env: vector_env,
        env_id: job.env_id.clone(),
        num_envs,
        env_offset: job.env_offset,
    };
    serve(py, &job, batch, ready, reply_fd)
}

/// The layout of a space's leaves (`[{path, offset, dtype, shape, bytes}]`) from its JSON.
#[pyfunction]
pub(crate) fn space_leaves_json(space: &str) -> PyResult<String> {
    Ok(crate::session::leaves_json(&parse_space("the", space)?))
}
