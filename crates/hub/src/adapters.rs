//! The adapter catalog: which adapters exist, what they run, whether they can run here.
//!
//! The hub links no simulator, so it asks the worker binary (`envhub-worker describe`) and
//! the Python worker (`python -m envhub.worker describe`) once per process and keeps the
//! answer; [`refresh_adapters`] asks again (after a Python adapter is registered). A hub
//! daemon also describes each client's own user adapters, once per distinct set.
//!
//! A `describe` that hangs (an adapter module that blocks at import) is killed after
//! `ENVHUB_DESCRIBE_TIMEOUT`, and the catalog says which command hung and for how long. No
//! lock is held while a worker is asked, so callers that need another catalog, or one already
//! known, never wait behind it.

use crate::bounded::{self, RunError};
use crate::env_vars::{ENVHUB_ADAPTERS, ENVHUB_DESCRIBE_TIMEOUT, ENVHUB_TEST_ADAPTERS};
use crate::python_host::{self, UserAdapters};
use crate::worker_binary::worker_binary;
use envhub_core::Availability;
use envhub_protocol::HubError;
use envhub_shm::WorkerPython;
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex};
use std::time::Duration;

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
    /// The render modes its envs draw (empty: none), where it declares them; `None` for an
    /// adapter that forwards the mode to its framework, which decides (the Python-hosted
    /// ones).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_modes: Option<Vec<String>>,
}

type Cached = Result<Arc<[AdapterInfo]>, (String, String)>;

/// A value computed at most once per generation, without holding the lock while computing:
/// asking a worker takes up to [`describe_timeout`], and callers that want an answer already
/// known (or another catalog) must not wait behind it. Callers that ask at the same time each
/// compute; the first to finish fills the cache, and the others use what it stored.
struct Cache<T> {
    state: Mutex<(Option<T>, u64)>,
}

impl<T: Clone> Cache<T> {
    const fn new() -> Cache<T> {
        Cache {
            state: Mutex::new((None, 0)),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, (Option<T>, u64)> {
        self.state.lock().unwrap_or_else(|e| e.into_inner())
    }

    fn get_or_compute(&self, compute: impl FnOnce() -> T) -> T {
        let generation = {
            let state = self.lock();
            if let Some(value) = &state.0 {
                return value.clone();
            }
            state.1
        };
        let value = compute();
        let mut state = self.lock();
        if state.1 != generation {
            // Cleared meanwhile: this answer may predate what cleared it; do not keep it.
            return value;
        }
        state.0.get_or_insert(value).clone()
    }

    fn clear(&self) {
        let mut state = self.lock();
        state.0 = None;
        state.1 += 1;
    }
}

static CATALOG: Cache<Cached> = Cache::new();
static NATIVE: Cache<Result<Native, (String, String)>> = Cache::new();

/// The Rust worker's adapters: those users see, and its test adapters (`null`), which the
/// catalog lists only with `ENVHUB_TEST_ADAPTERS=1` but which run whenever a job names one
/// (`envhub bench`), without asking Python whether it hosts them.
#[derive(Clone)]
struct Native {
    shown: Arc<[AdapterInfo]>,
    testing: Arc<[AdapterInfo]>,
}

impl Native {
    /// The adapter `name`, shown or for testing.
    fn find(&self, name: &str) -> Option<&AdapterInfo> {
        self.shown
            .iter()
            .chain(self.testing.iter())
            .find(|a| a.name == name)
    }
}

/// One entry of `envhub-worker describe`, which marks test adapters.
#[derive(Deserialize)]
struct Described {
    #[serde(flatten)]
    info: AdapterInfo,
    #[serde(default)]
    testing: bool,
}

/// Catalogs with a client's user adapters, most recent last. Bounded, so a daemon that
/// serves many distinct sets asks again rather than growing.
static WITH_USER: Cache<Vec<(UserAdapters, Arc<[AdapterInfo]>)>> = Cache::new();
const WITH_USER_CAPACITY: usize = 16;

/// How long a `describe` may take before it is killed and reported as hung
/// (`ENVHUB_DESCRIBE_TIMEOUT`, seconds; default 30).
fn describe_timeout() -> Duration {
    envhub_session::seconds_from_env(ENVHUB_DESCRIBE_TIMEOUT, Duration::from_secs(30))
}

/// Forgets the catalog, so the next [`adapters`] call asks the workers again.
pub fn refresh_adapters() {
    CATALOG.clear();
    WITH_USER.clear();
    IN_ENVS.lock().unwrap_or_else(|e| e.into_inner()).clear();
}

/// Catalogs of the Python worker in provisioned environments, by environment and user
/// adapters (bounded as [`WITH_USER`]).
type InEnv = ((WorkerPython, UserAdapters), Arc<[AdapterInfo]>);
static IN_ENVS: Mutex<Vec<InEnv>> = Mutex::new(Vec::new());

/// The Python-hosted adapters as the provisioned environment `env` hosts them (its own
/// packages decide what is available), with `user`'s; asked once per environment.
pub(crate) fn adapters_in(env: &WorkerPython, user: &UserAdapters) -> Arc<[AdapterInfo]> {
    let key = (env.clone(), user.clone());
    if let Some((_, list)) = IN_ENVS
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .find(|(k, _)| *k == key)
    {
        return list.clone();
    }
    // Asked without the lock held, as for `adapters`.
    let list: Arc<[AdapterInfo]> = python(Some(env), user).into();
    let mut known = IN_ENVS.lock().unwrap_or_else(|e| e.into_inner());
    if known.len() == WITH_USER_CAPACITY {
        known.remove(0);
    }
    known.push((key, list.clone()));
    list
}

/// Every adapter, asked of the worker binary and the Python worker once per process.
pub(crate) fn adapters() -> Result<Arc<[AdapterInfo]>, HubError> {
    unpack(CATALOG.get_or_compute(|| {
        let mut list = native_cached()?.to_vec();
        list.extend(python(None, &UserAdapters::default()));
        Ok(list.into())
    }))
}

/// Every adapter, with `user`'s adapters hosted beside this process's own (the catalog of
/// [`adapters`] when `user` is empty).
pub(crate) fn adapters_with(user: &UserAdapters) -> Result<Arc<[AdapterInfo]>, HubError> {
    if user.is_empty() {
        return adapters();
    }
    let known = |sets: &[(UserAdapters, Arc<[AdapterInfo]>)]| {
        sets.iter()
            .find(|(key, _)| key == user)
            .map(|(_, list)| list.clone())
    };
    let generation = {
        let state = WITH_USER.lock();
        if let Some(list) = state.0.as_deref().and_then(known) {
            return Ok(list);
        }
        state.1
    };
    // Asked without holding the cache's lock, as for `adapters`.
    let mut list = native_adapters()?.to_vec();
    list.extend(python(None, user));
    let list: Arc<[AdapterInfo]> = list.into();
    let mut state = WITH_USER.lock();
    if state.1 != generation {
        return Ok(list); // refreshed meanwhile: not kept, as in `Cache`
    }
    let sets = state.0.get_or_insert_with(Vec::new);
    if let Some(theirs) = known(sets) {
        return Ok(theirs);
    }
    if sets.len() == WITH_USER_CAPACITY {
        sets.remove(0);
    }
    sets.push((user.clone(), list.clone()));
    Ok(list)
}

/// The adapters of the Rust worker only: a few milliseconds to ask, where starting Python
/// to ask it takes a few hundred, so sessions of native envs never wait for Python.
pub(crate) fn native_adapters() -> Result<Arc<[AdapterInfo]>, HubError> {
    unpack(native_cached())
}

fn native_cached() -> Cached {
    let native = NATIVE.get_or_compute(native)?;
    if std::env::var(ENVHUB_TEST_ADAPTERS).is_ok_and(|v| v == "1") {
        return Ok(native
            .shown
            .iter()
            .chain(native.testing.iter())
            .cloned()
            .collect());
    }
    Ok(native.shown)
}

fn unpack(result: Cached) -> Result<Arc<[AdapterInfo]>, HubError> {
    result.map_err(|(path, reason)| HubError::WorkerBinary { path, reason })
}

fn native() -> Result<Native, (String, String)> {
    let path = worker_binary();
    let shown = path.display().to_string();
    let timeout = describe_timeout();
    let mut command = std::process::Command::new(&path);
    // Test adapters too, marked: whether they are shown is this process's choice. The
    // worker finds Gymnasium's MuJoCo assets through the hub's interpreter (the Python
    // client's own, when the hub runs inside it), not whatever `python3` is on PATH.
    command.arg("describe").env(ENVHUB_TEST_ADAPTERS, "1").env(
        crate::env_vars::ENVHUB_PYTHON,
        crate::python_host::python_interpreter(),
    );
    let out = bounded::output_within(&mut command, timeout)
        .map_err(|why| (shown.clone(), format!("`{shown} describe`: {why}")))?;
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
    let described: Vec<Described> = serde_json::from_slice(&out.stdout)
        .map_err(|e| (shown, format!("unreadable `describe` output: {e}")))?;
    let (testing, users): (Vec<Described>, Vec<Described>) =
        described.into_iter().partition(|d| d.testing);
    let infos = |list: Vec<Described>| list.into_iter().map(|d| d.info).collect();
    Ok(Native {
        shown: infos(users),
        testing: infos(testing),
    })
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
fn python(env: Option<&WorkerPython>, user: &UserAdapters) -> Vec<AdapterInfo> {
    let python = env.map_or_else(python_host::python_interpreter, |e| e.interpreter.clone());
    let timeout = describe_timeout();
    let mut command = python_host::worker_command_in(env, user);
    let hosted: Vec<String> = command
        .get_envs()
        .find(|(k, _)| *k == std::ffi::OsStr::new(ENVHUB_ADAPTERS))
        .and_then(|(_, v)| v)
        .map(|v| v.to_string_lossy().split(',').map(String::from).collect())
        .unwrap_or_default();
    let out = bounded::output_within(command.arg("describe"), timeout);
    let hung = matches!(out, Err(RunError::Hung(_)));
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
        Err(why) if hung && !hosted.is_empty() => format!(
            "{why} (it imports the user adapters {}: one of them may block at import)",
            hosted.join(", ")
        ),
        Err(why) => why.to_string(),
    };
    let hint = match env {
        _ if hung => format!(
            "find what blocks with `{} -m envhub.worker describe` (with the same ENVHUB_ADAPTERS and PYTHONPATH); a slow but working import needs a larger {ENVHUB_DESCRIBE_TIMEOUT}",
            python.display()
        ),
        Some(env) => format!(
            "the python env `{0}` cannot start envhub's worker: check the variables its `env:` declares, or rebuild it (`envhub env remove {0}`, then `envhub env sync {0}`)",
            env.name
        ),
        None => "run `make py-install`, or point ENVHUB_PYTHON (or `python:` in envhub.yaml) at an interpreter with the `envhub` package".into(),
    };
    let asked = match env {
        Some(env) => format!(
            "`{} -m envhub.worker describe` in python env `{}`",
            python.display(),
            env.name
        ),
        None => format!("`{} -m envhub.worker describe`", python.display()),
    };
    tracing::debug!(python = %python.display(), %failure, "no Python-hosted adapters");
    python_host::BUILTIN
        .iter()
        .map(|(name, frameworks)| AdapterInfo {
            name: name.to_string(),
            frameworks: frameworks.iter().map(|f| f.to_string()).collect(),
            requires: vec!["python".into(), "envhub (Python package)".into()],
            description: format!("{name} envs hosted in a Python worker"),
            availability: Availability::Unavailable {
                reason: format!("{asked} failed: {failure}"),
                hint: hint.clone(),
            },
            envs: vec![],
            host: Host::Python,
            render_modes: None,
        })
        .collect()
}

/// Whether a session on `route` runs in a Python worker: in a provisioned environment, or
/// through an adapter the Rust worker does not have. Unknown (the Rust worker cannot say)
/// counts as not.
pub(crate) fn hosted_in_python(route: &envhub_protocol::Route) -> bool {
    if route.python.is_some()
        || crate::python_host::BUILTIN
            .iter()
            .any(|(name, _)| *name == route.adapter)
    {
        return true;
    }
    NATIVE
        .get_or_compute(native)
        .is_ok_and(|n| n.find(&route.adapter).is_none())
}

/// How the adapter `name` is hosted, among this process's adapters and `user`'s (native if
/// unknown).
pub(crate) fn host_of(name: &str, user: &UserAdapters) -> Host {
    let native = NATIVE.get_or_compute(native).ok();
    native
        .and_then(|n| n.find(name).map(|a| a.host))
        .or_else(|| {
            adapters_with(user)
                .ok()
                .and_then(|list| list.iter().find(|a| a.name == name).map(|a| a.host))
        })
        .unwrap_or_default()
}
