//! The adapter catalog: which adapters exist, what they run, whether they can run here.
//!
//! The hub links no simulator, so it asks the worker binary (`envhub-worker describe`) and
//! the Python worker (`python -m envhub.worker describe`) once per process and keeps the
//! answer; [`refresh_adapters`] asks again (after a Python adapter is registered). A hub
//! daemon also describes each client's own user adapters, once per distinct set.

use crate::error::HubError;
use crate::python_host::{self, UserAdapters};
use crate::worker_binary::worker_binary;
use envhub_core::Availability;
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};

/// Which worker process hosts an adapter.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Host {
    /// `envhub-worker` (Rust).
    #[default]
    Native,
    /// `python -m envhub.worker`, in the configured interpreter.
    Python,
}

/// What the hub knows about one adapter.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct AdapterInfo {
    /// Adapter name.
    pub name: String,
    /// Frameworks it serves (canonical names).
    pub frameworks: Vec<String>,
    /// What it needs installed.
    pub requires: Vec<String>,
    /// One line for people.
    pub description: String,
    /// Whether it can run here, and if not why.
    pub availability: Availability,
    /// Env ids it implements natively (empty: it forwards any id to its framework).
    pub envs: Vec<String>,
    /// The worker process that hosts it.
    #[serde(default)]
    pub host: Host,
}

type Cached = Result<&'static [AdapterInfo], (String, String)>;

static CATALOG: Mutex<Option<Cached>> = Mutex::new(None);
static NATIVE: Mutex<Option<Cached>> = Mutex::new(None);

/// Catalogs with a client's user adapters, most recent last. Bounded, so a daemon that
/// serves many distinct sets asks again rather than growing.
static WITH_USER: Mutex<Vec<(UserAdapters, Arc<[AdapterInfo]>)>> = Mutex::new(Vec::new());
const WITH_USER_CAPACITY: usize = 16;

/// Forgets the catalog, so the next [`adapters`] call asks the workers again.
pub fn refresh_adapters() {
    *CATALOG.lock().unwrap_or_else(|e| e.into_inner()) = None;
    WITH_USER.lock().unwrap_or_else(|e| e.into_inner()).clear();
}

/// Every adapter, asked of the worker binary and the Python worker once per process.
pub fn adapters() -> Result<&'static [AdapterInfo], HubError> {
    let mut cached = CATALOG.lock().unwrap_or_else(|e| e.into_inner());
    let result = cached.get_or_insert_with(|| {
        let mut list = native_cached()?.to_vec();
        list.extend(python(&UserAdapters::default()));
        // Leaked once per (re)load: the catalog is small and reloaded only on registration.
        Ok(&*Box::leak(list.into_boxed_slice()))
    });
    unpack(result)
}

/// Every adapter, with `user`'s adapters hosted beside this process's own (the catalog of
/// [`adapters`] when `user` is empty).
pub(crate) fn adapters_with(user: &UserAdapters) -> Result<Arc<[AdapterInfo]>, HubError> {
    if user.is_empty() {
        return Ok(adapters()?.into());
    }
    let mut cached = WITH_USER.lock().unwrap_or_else(|e| e.into_inner());
    if let Some((_, list)) = cached.iter().find(|(key, _)| key == user) {
        return Ok(list.clone());
    }
    let mut list = native_adapters()?.to_vec();
    list.extend(python(user));
    let list: Arc<[AdapterInfo]> = list.into();
    if cached.len() == WITH_USER_CAPACITY {
        cached.remove(0);
    }
    cached.push((user.clone(), list.clone()));
    Ok(list)
}

/// The adapters of the Rust worker only: a few milliseconds to ask, where starting Python
/// to ask it takes a few hundred, so sessions of native envs never wait for Python.
pub fn native_adapters() -> Result<&'static [AdapterInfo], HubError> {
    unpack(&native_cached())
}

fn native_cached() -> Cached {
    let mut cached = NATIVE.lock().unwrap_or_else(|e| e.into_inner());
    cached
        .get_or_insert_with(|| Ok(&*Box::leak(native()?.into_boxed_slice())))
        .clone()
}

fn unpack(result: &Cached) -> Result<&'static [AdapterInfo], HubError> {
    match result {
        Ok(list) => Ok(list),
        Err((path, reason)) => Err(HubError::WorkerBinary {
            path: path.clone(),
            reason: reason.clone(),
        }),
    }
}

fn native() -> Result<Vec<AdapterInfo>, (String, String)> {
    let path = worker_binary();
    let shown = path.display().to_string();
    let out = std::process::Command::new(&path)
        .arg("describe")
        .output()
        .map_err(|e| (shown.clone(), e.to_string()))?;
    if !out.status.success() {
        // Typically the loader failing on a missing library: say which.
        return Err((
            shown,
            format!(
                "`describe` exited with {}: {}",
                out.status,
                last_line(&out.stderr)
            ),
        ));
    }
    serde_json::from_slice(&out.stdout)
        .map_err(|e| (shown, format!("unreadable `describe` output: {e}")))
}

fn last_line(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes)
        .lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .unwrap_or("")
        .to_string()
}

/// The Python-hosted adapters (with `user`'s); when the interpreter cannot describe them,
/// the built-in ones are listed as unavailable with the reason.
fn python(user: &UserAdapters) -> Vec<AdapterInfo> {
    let python = python_host::python_interpreter();
    let out = python_host::worker_command(user).arg("describe").output();
    let failure = match out {
        Ok(out) if out.status.success() => {
            match serde_json::from_slice::<Vec<AdapterInfo>>(&out.stdout) {
                Ok(mut list) => {
                    for a in &mut list {
                        a.host = Host::Python;
                    }
                    return list;
                }
                Err(e) => format!("unreadable `describe` output: {e}"),
            }
        }
        Ok(out) => format!("exited with {}: {}", out.status, last_line(&out.stderr)),
        Err(e) => e.to_string(),
    };
    tracing::debug!(python = %python.display(), %failure, "no Python-hosted adapters");
    python_host::BUILTIN
        .iter()
        .map(|(name, framework)| AdapterInfo {
            name: name.to_string(),
            frameworks: vec![framework.to_string()],
            requires: vec!["python".into(), "envhub (Python package)".into()],
            description: format!("{framework} envs hosted in a Python worker"),
            availability: Availability::Unavailable {
                reason: format!(
                    "`{} -m envhub.worker describe` failed: {failure}",
                    python.display()
                ),
                hint: "run `make py-install`, or point ENVHUB_PYTHON (or `python:` in envhub.yaml) at an interpreter with the `envhub` package".into(),
            },
            envs: vec![],
            host: Host::Python,
        })
        .collect()
}

/// How the adapter `name` is hosted, among this process's adapters and `user`'s (native if
/// unknown).
pub(crate) fn host_of(name: &str, user: &UserAdapters) -> Host {
    let find = |list: &[AdapterInfo]| list.iter().find(|a| a.name == name).map(|a| a.host);
    native_adapters()
        .ok()
        .and_then(find)
        .or_else(|| adapters_with(user).ok().and_then(|list| find(&list)))
        .unwrap_or_default()
}
