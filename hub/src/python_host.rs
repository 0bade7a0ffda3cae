//! Python-hosted adapters: which interpreter runs them, and how it is started.
//!
//! Simulators that only exist in Python run in `python -m envhub.worker` processes (see the
//! `envhub._envhub` bindings for why a Python process rather than CPython embedded in
//! `envhub-worker`). The hub asks that module what it hosts (`describe`), as it asks the
//! Rust worker binary, and starts it with `serve --job` for the adapters it reported.

use crate::env_vars::{ENVHUB_ADAPTERS, ENVHUB_PYTHON};
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

/// `python -m envhub.worker`, with the user adapters of the config and of `ENVHUB_ADAPTERS`
/// passed on in `ENVHUB_ADAPTERS`.
pub(crate) fn worker_command() -> Command {
    let mut cmd = Command::new(python_interpreter());
    cmd.arg("-m").arg("envhub.worker");
    let mut adapters = configured().1;
    if let Ok(var) = std::env::var(ENVHUB_ADAPTERS) {
        adapters.extend(
            var.split(',')
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .map(String::from),
        );
    }
    if !adapters.is_empty() {
        adapters.dedup();
        cmd.env(ENVHUB_ADAPTERS, adapters.join(","));
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
];
