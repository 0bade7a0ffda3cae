//! Rust errors as the Python exceptions of `envhub.errors`, one class per kind.
//!
//! The classes are defined in Python (they inherit from both `EnvHubError` and the builtin a
//! caller would catch: `KeyError`, `ValueError`, `ImportError`, ...), so this side only picks
//! the class by name and sets the attributes a caller can react to.

use envhub_hub::{HubError, MatchError, RegistryError};
use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;

static ERRORS: PyOnceLock<Py<PyModule>> = PyOnceLock::new();

/// An instance of `envhub.errors.<class>` with `message`, and `attrs` set on it.
pub(crate) fn raise(
    py: Python<'_>,
    class: &str,
    message: String,
    attrs: Vec<(&'static str, Bound<'_, PyAny>)>,
) -> PyErr {
    let build = || -> PyResult<PyErr> {
        let module =
            ERRORS.get_or_try_init(py, || py.import("envhub.errors").map(Bound::unbind))?;
        let exc = module.bind(py).getattr(class)?.call1((message.clone(),))?;
        for (name, value) in attrs {
            exc.setattr(name, value)?;
        }
        Ok(PyErr::from_value(exc))
    };
    // Only a broken installation gets here; still say what the error was.
    build().unwrap_or_else(|e| PyRuntimeError::new_err(format!("{message} (and {e})")))
}

fn text<'py>(py: Python<'py>, s: &str) -> Bound<'py, PyAny> {
    pyo3::types::PyString::new(py, s).into_any()
}

/// The exception for a hub error.
pub(crate) fn hub_error(py: Python<'_>, e: HubError) -> PyErr {
    let message = e.to_string();
    match e {
        HubError::Registry(RegistryError::UnknownId { id, closest }) => {
            unknown_id(py, message, &id, &closest)
        }
        HubError::Registry(_) => raise(py, "RegistryError", message, vec![]),
        HubError::NoAdapter { .. } => raise(py, "NoAdapterError", message, vec![]),
        HubError::Unavailable {
            adapter,
            reason,
            hint,
        } => raise(
            py,
            "AdapterUnavailableError",
            message,
            vec![
                ("adapter", text(py, &adapter)),
                ("reason", text(py, &reason)),
                ("hint", text(py, &hint)),
            ],
        ),
        HubError::InvalidConfig { .. } => raise(py, "InvalidConfigError", message, vec![]),
        HubError::WorkerBinary { .. } => raise(py, "WorkerBinaryError", message, vec![]),
        HubError::MakeFailed(_) | HubError::PythonEnv { .. } => {
            raise(py, "MakeError", message, vec![])
        }
        HubError::InvalidAction { .. } => raise(py, "InvalidActionError", message, vec![]),
        HubError::InvalidState(_)
        | HubError::Closed { .. }
        | HubError::NotReset { .. }
        | HubError::MustReset { .. }
        | HubError::SpacesDiffer(_)
        | HubError::Internal(_) => raise(py, "InvalidStateError", message, vec![]),
        HubError::WorkerDied {
            worker, pid, envs, ..
        } => {
            let attrs = (|| -> PyResult<Vec<(&'static str, Bound<'_, PyAny>)>> {
                Ok(vec![
                    ("worker", worker.into_pyobject(py)?.into_any()),
                    ("pid", pid.into_pyobject(py)?.into_any()),
                    ("envs", text(py, &envs)),
                ])
            })()
            .unwrap_or_default();
            raise(py, "WorkerDiedError", message, attrs)
        }
        HubError::EnvFailed { worker, envs, .. } => {
            let attrs = (|| -> PyResult<Vec<(&'static str, Bound<'_, PyAny>)>> {
                Ok(vec![
                    ("worker", worker.into_pyobject(py)?.into_any()),
                    ("env_ids", pyo3::types::PyList::new(py, envs)?.into_any()),
                ])
            })()
            .unwrap_or_default();
            raise(py, "EnvFailedError", message, attrs)
        }
        HubError::Interrupted => pyo3::exceptions::PyKeyboardInterrupt::new_err(message),
        HubError::DataPlane(_) => raise(py, "DataPlaneError", message, vec![]),
        HubError::Remote(_) | HubError::Daemon { .. } => {
            raise(py, "HubDaemonError", message, vec![])
        }
        HubError::HubLost { hub, envs, .. } => raise(
            py,
            "HubLostError",
            message,
            vec![("hub", text(py, &hub)), ("envs", text(py, &envs))],
        ),
        HubError::UnknownHub { name, .. } => raise(
            py,
            "UnknownHubError",
            message,
            vec![("hub", text(py, &name))],
        ),
        HubError::Network { .. } => raise(py, "NetworkError", message, vec![]),
        HubError::Refused { hub, .. } => raise(
            py,
            "HubRefusedError",
            message,
            vec![("hub", text(py, &hub))],
        ),
    }
}

fn unknown_id(py: Python<'_>, message: String, id: &str, closest: &[String]) -> PyErr {
    let suggestions = pyo3::types::PyList::new(py, closest)
        .map(Bound::into_any)
        .unwrap_or_else(|_| py.None().into_bound(py));
    raise(
        py,
        "UnknownEnvError",
        message,
        vec![("env_id", text(py, id)), ("suggestions", suggestions)],
    )
}

/// The exception for a registry error.
pub(crate) fn registry_error(py: Python<'_>, e: RegistryError) -> PyErr {
    hub_error(py, HubError::Registry(e))
}

/// The exception for a failed task match.
pub(crate) fn match_error(py: Python<'_>, e: MatchError) -> PyErr {
    match e {
        MatchError::UnknownId(e) => registry_error(py, e),
        e @ MatchError::NoMatch { .. } => raise(py, "NoMatchError", e.to_string(), vec![]),
    }
}

/// The exception for using an env in a process forked from the one that made it.
pub(crate) fn forked(py: Python<'_>, id: &str, owner: u32) -> PyErr {
    raise(
        py,
        "ForkError",
        format!(
            "`{id}` was made in process {owner}; this process ({}) is a fork of it and cannot use its workers or shared memory\nhint: make envs after forking (in the child), or start children with multiprocessing's `spawn` or `forkserver` method",
            std::process::id()
        ),
        vec![],
    )
}
