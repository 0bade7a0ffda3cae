//! `envhub._envhub`: the compiled half of the Python package `envhub`.
//!
//! Thin on purpose: sessions, the registry and task matching are the Rust client's, results
//! cross as numpy arrays and metadata as JSON, and everything Gymnasium-shaped lives in the
//! pure-Python package on top, where Python users can read it. The one decision made here is
//! ownership of shared memory: a batch's observations, rewards and flags are numpy arrays
//! viewing the session's batch slot in place, and their base object holds a lease on the
//! slot, so arrays a user keeps stay valid and unchanged. The price is memory: a slot stays
//! while arrays view it, up to the session's cap (`pool_bytes`), past which results are
//! copied. Waiting on workers releases the GIL and checks for Ctrl-C every few milliseconds.

mod arrays;
mod convert;
mod errors;
mod info_columns;
mod registry;
mod session;
mod worker;

use pyo3::prelude::*;
use std::path::PathBuf;

/// Sets where the hub looks for `envhub-worker` when `ENVHUB_WORKER` is not set (the Python
/// package points it at the binary installed beside it). Returns whether it was set (the
/// first call wins).
#[pyfunction]
fn set_worker_binary(path: PathBuf) -> bool {
    envhub_hub::set_default_worker_binary(path)
}

/// The `envhub-worker` binary the hub would start.
#[pyfunction]
fn worker_binary() -> PathBuf {
    envhub_hub::worker_binary()
}

/// Sets the interpreter Python-hosted adapters run in when neither `ENVHUB_PYTHON` nor the
/// config names one (the package passes `sys.executable`). The first call wins.
#[pyfunction]
fn set_python(path: PathBuf) -> bool {
    envhub_hub::set_default_python(path)
}

/// Forgets the adapter catalog, so the next look-up asks the workers again (after a Python
/// adapter was registered).
#[pyfunction]
fn refresh_adapters() {
    envhub_hub::refresh_adapters()
}

/// Every adapter with its availability, as JSON.
#[pyfunction]
fn adapters_json(py: Python<'_>) -> PyResult<String> {
    let adapters = py
        .detach(|| envhub_hub::Hub::from_env().and_then(|hub| hub.adapters()))
        .map_err(|e| errors::hub_error(py, e))?;
    Ok(serde_json::to_string(&adapters).expect("adapters serialize"))
}

/// The live hubs on the network (the settings of `envhub.yaml` and `ENVHUB_CONNECT`), as
/// JSON.
#[pyfunction]
fn hubs_json(py: Python<'_>) -> PyResult<String> {
    let hubs = py
        .detach(|| envhub_hub::Hub::from_env().and_then(|hub| hub.hubs()))
        .map_err(|e| errors::hub_error(py, e))?;
    Ok(serde_json::to_string(&hubs).expect("hub infos serialize"))
}

#[pymodule]
fn _envhub(m: &Bound<'_, PyModule>) -> PyResult<()> {
    envhub_core::init_logging();
    m.add("WORKER_PROTOCOL", envhub_shm::WORKER_PROTOCOL)?;
    m.add_function(wrap_pyfunction!(set_worker_binary, m)?)?;
    m.add_function(wrap_pyfunction!(worker_binary, m)?)?;
    m.add_function(wrap_pyfunction!(adapters_json, m)?)?;
    m.add_function(wrap_pyfunction!(hubs_json, m)?)?;
    m.add_function(wrap_pyfunction!(set_python, m)?)?;
    m.add_function(wrap_pyfunction!(refresh_adapters, m)?)?;
    m.add_function(wrap_pyfunction!(session::make_session, m)?)?;
    m.add_function(wrap_pyfunction!(worker::serve_worker, m)?)?;
    m.add_function(wrap_pyfunction!(info_columns::info_schema, m)?)?;
    m.add_function(wrap_pyfunction!(worker::serve_vector_worker, m)?)?;
    m.add_function(wrap_pyfunction!(worker::space_leaves_json, m)?)?;
    m.add_class::<session::Session>()?;
    m.add_class::<session::SlotOwner>()?;
    m.add_class::<registry::PyRegistry>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
