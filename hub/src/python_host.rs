//! Python-hosted adapters: which interpreter runs them, and how it is started.
//!
//! Simulators that only exist in Python run in `python -m envhub.worker` processes (see the
//! `envhub._envhub` bindings for why a Python process rather than CPython embedded in
//! `envhub-worker`). The hub asks that module what it hosts (`describe`), as it asks the
//! Rust worker binary, and starts it with `serve --job` for the adapters it reported.

use crate::env_vars::{ENVHUB_ADAPTERS, ENVHUB_PYTHON};
/// User adapters beyond this hub's own, as they travel to a daemon.
pub(crate) use envhub_protocol::daemon::UserAdapters;
use std::path::PathBuf;
use std::process::Command;
use std::sync::{Mutex, OnceLock};

/// The interpreter an embedding program runs in (the Python module sets `sys.executable`).
static DEFAULT: OnceLock<PathBuf> = OnceLock::new();

type Configured = (Option<PathBuf>, Vec<String>);

/// Set from the hub config (`python:` and `adapters:`); read from the discovered config on
/// first use when no hub was built from settings (a hub over an explicit registry).
static CONFIGURED: Mutex<Option<Configured>> = Mutex::new(None);

fn configured() -> Configured {
    CONFIGURED
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .get_or_insert_with(|| match crate::settings::Settings::discover(None) {
            Ok(s) => (s.python, s.adapters),
            Err(_) => (None, Vec::new()),
        })
        .clone()
}

/// Sets the interpreter used when neither `ENVHUB_PYTHON` nor the config names one (the
/// Python package passes its own). The first call wins; returns whether this one did.
pub fn set_default_python(path: PathBuf) -> bool {
    DEFAULT.set(path).is_ok()
}

/// Applies the config's `python:` interpreter and `adapters:` import paths; returns whether
/// they changed (and the catalog must be asked again).
pub(crate) fn configure(python: Option<PathBuf>, adapters: Vec<String>) -> bool {
    let mut configured = CONFIGURED.lock().unwrap_or_else(|e| e.into_inner());
    let new = Some((python, adapters));
    let changed = *configured != new;
    *configured = new;
    changed
}

/// `ENVHUB_PYTHON`, else the config's `python:`, else the embedding program's interpreter,
/// else `.venv/bin/python` in the current directory or the nearest parent that has one, else
/// `python3`.
pub fn python_interpreter() -> PathBuf {
    if let Some(p) = std::env::var_os(ENVHUB_PYTHON).filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    if let Some(p) = configured().0 {
        return p;
    }
    if let Some(p) = DEFAULT.get() {
        return p.clone();
    }
    let cwd = std::env::current_dir().unwrap_or_default();
    cwd.ancestors()
        .map(|dir| dir.join(".venv/bin/python"))
        .find(|p| p.is_file())
        .unwrap_or_else(|| PathBuf::from("python3"))
}

/// User adapters beyond this hub's own (its config's `adapters:` and `ENVHUB_ADAPTERS`), which
/// a client sends the daemon with its requests: what a Python worker started by this process
/// would host beyond the built-in adapters, with this process's `PYTHONPATH` and working
/// directory (which `python -m` puts on `sys.path`) made absolute. Empty when there are no
/// user adapters.
pub(crate) fn user_adapters_of_this_process() -> UserAdapters {
    let adapters = own_adapters();
    if adapters.is_empty() {
        return UserAdapters::default();
    }
    let cwd = std::env::current_dir().unwrap_or_default();
    let mut pythonpath: Vec<PathBuf> = std::env::var_os("PYTHONPATH")
        .map(|v| std::env::split_paths(&v).collect())
        .unwrap_or_default();
    pythonpath.push(cwd.clone());
    UserAdapters {
        adapters,
        pythonpath: unique(
            pythonpath
                .into_iter()
                .filter(|p| !p.as_os_str().is_empty())
                .map(|p| cwd.join(p))
                // Sent as JSON text: a folder whose name is not UTF-8 cannot travel.
                .filter(|p| p.to_str().is_some()),
        ),
    }
}

/// This process's user adapters: the config's `adapters:`, then `ENVHUB_ADAPTERS`, each once.
fn own_adapters() -> Vec<String> {
    let mut adapters = configured().1;
    if let Ok(var) = std::env::var(ENVHUB_ADAPTERS) {
        adapters.extend(var.split(',').map(str::trim).map(String::from));
    }
    unique(adapters.into_iter().filter(|s| !s.is_empty()))
}

fn unique<T: PartialEq>(items: impl IntoIterator<Item = T>) -> Vec<T> {
    let mut out = Vec::new();
    for item in items {
        if !out.contains(&item) {
            out.push(item);
        }
    }
    out
}

/// `python -m envhub.worker`, hosting this process's user adapters and `extra` ones (a
/// daemon's client's) in `ENVHUB_ADAPTERS`, with `extra`'s folders first on `PYTHONPATH`.
/// It runs in the provisioned environment `env` (its interpreter and variables), or in the
/// hub's interpreter.
pub(crate) fn worker_command_in(
    env: Option<&envhub_shm::WorkerPython>,
    extra: &UserAdapters,
) -> Command {
    let mut cmd = match env {
        Some(env) => {
            let mut cmd = Command::new(&env.interpreter);
            cmd.envs(&env.env);
            cmd
        }
        None => Command::new(python_interpreter()),
    };
    cmd.arg("-m").arg("envhub.worker");
    let adapters = unique(own_adapters().into_iter().chain(extra.adapters.clone()));
    if !adapters.is_empty() {
        cmd.env(ENVHUB_ADAPTERS, adapters.join(","));
    }
    if !extra.pythonpath.is_empty() {
        let own = std::env::var_os("PYTHONPATH")
            .map(|v| std::env::split_paths(&v).collect::<Vec<_>>())
            .unwrap_or_default();
        let all = unique(extra.pythonpath.iter().cloned().chain(own));
        if let Ok(joined) = std::env::join_paths(all) {
            cmd.env("PYTHONPATH", joined);
        }
    }
    cmd
}

/// The Python-hosted adapters built into the `envhub` package, reported unavailable when
/// the interpreter cannot describe them (so `envhub adapters` still says why).
pub(crate) const BUILTIN: &[(&str, &str)] = &[
    ("gymnasium", "gymnasium"),
    ("maniskill", "maniskill"),
    ("libero", "libero"),
    ("isaac_lab", "isaac_lab"),
    ("env_fns", "env_fns"),
];

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::OsStr;

    #[test]
    fn worker_command_hosts_a_clients_adapters_with_their_folders_first() {
        let extra = UserAdapters {
            adapters: vec!["client_sim:ClientAdapter".into()],
            pythonpath: vec!["/client/dir".into()],
        };
        let cmd = worker_command_in(None, &extra);
        let env = |name: &str| {
            cmd.get_envs()
                .find(|(k, _)| *k == OsStr::new(name))
                .and_then(|(_, v)| v)
                .and_then(OsStr::to_str)
                .unwrap_or_default()
                .to_string()
        };
        assert!(
            env(ENVHUB_ADAPTERS)
                .split(',')
                .any(|a| a == "client_sim:ClientAdapter"),
            "{}",
            env(ENVHUB_ADAPTERS)
        );
        assert!(env("PYTHONPATH").starts_with("/client/dir"));
        // Nothing extra: the worker inherits this process's PYTHONPATH untouched.
        let plain = worker_command_in(None, &UserAdapters::default());
        assert!(!plain.get_envs().any(|(k, _)| k == OsStr::new("PYTHONPATH")));
    }
}
