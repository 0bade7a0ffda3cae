//! Providing a registry entry's Python environment to its workers: found ready in the cache,
//! or built on first need (see `envhub-pyenv`), as the user's policy and a remote hub's
//! operator allow.
//!
//! Automatic by default on the user's own machine: the first `make` of a suite then takes
//! the install's minutes once (with a progress line), where an explicit step would instead
//! fail with a hint to run it — and `envhub env sync` prebuilds when that is wanted, for
//! CI images or before going offline. `ENVHUB_PROVISION=explicit` turns the automatic builds
//! off. A hub serving remote clients builds for them only with `envhub serve
//! --allow-provision`: installing packages is its operator's decision.

use crate::env_vars::{
    ENVHUB_PROVISION, ENVHUB_PYENV_DIR, ENVHUB_PYENV_WAIT, ENVHUB_PYTHON_INSTALL, ENVHUB_UV,
};
use envhub_catalog::EnvEntry;
use envhub_catalog::Registry;
use envhub_protocol::HubError;
use envhub_pyenv::{PythonEnvSpec, Store};
use envhub_shm::WorkerPython;
use std::path::PathBuf;
use std::sync::OnceLock;
use std::time::Duration;

/// What every environment gets besides its own requirements (unless it pins them itself):
/// what envhub's Python package imports (`pyproject.toml`'s dependencies, unpinned so a
/// suite's own pins decide).
const WORKER_REQUIREMENTS: &[&str] = &["numpy", "gymnasium"];

/// The cache folder: `ENVHUB_PYENV_DIR`, else `$XDG_CACHE_HOME/envhub/pyenvs`, else
/// `~/.cache/envhub/pyenvs`; never a predictable name in the shared temporary folder, where
/// another user could plant the environments a suite's workers run.
pub fn cache_dir() -> Result<PathBuf, String> {
    let var = |name: &str| {
        std::env::var_os(name)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    if let Some(dir) = var(ENVHUB_PYENV_DIR) {
        return Ok(dir);
    }
    let cache = var("XDG_CACHE_HOME")
        .or_else(|| var("HOME").map(|h| h.join(".cache")))
        .ok_or_else(|| {
            format!(
                "no folder for Python environments: `{ENVHUB_PYENV_DIR}`, `XDG_CACHE_HOME` and `HOME` are all unset\nhint: set `{ENVHUB_PYENV_DIR}` to a folder of your own"
            )
        })?;
    Ok(cache.join("envhub").join("pyenvs"))
}

/// Whether environments are built on first need here (`ENVHUB_PROVISION`, default `auto`).
pub fn automatic() -> bool {
    match std::env::var(ENVHUB_PROVISION) {
        Ok(v) if v.trim() == "explicit" => false,
        Ok(v) if !v.trim().is_empty() && v.trim() != "auto" => {
            tracing::warn!(
                "ignoring {ENVHUB_PROVISION}=`{v}`: valid values are `auto` and `explicit`"
            );
            true
        }
        _ => true,
    }
}

/// The store of this process, set up once: uv found, envhub's package located.
pub fn store() -> Result<&'static Store, String> {
    static STORE: OnceLock<Result<Store, String>> = OnceLock::new();
    STORE.get_or_init(make_store).as_ref().map_err(Clone::clone)
}

fn make_store() -> Result<Store, String> {
    let python = crate::python_host::python_interpreter();
    let explicit = std::env::var_os(ENVHUB_UV)
        .filter(|v| !v.is_empty())
        .map(PathBuf::from);
    let uv = envhub_pyenv::find_uv(explicit.as_deref(), Some(&python)).map_err(|searched| {
        format!(
            "no `uv` found (looked at {searched})\nhint: `pip install uv` into the hub's interpreter (`make venv` does), or set {ENVHUB_UV} to its path"
        )
    })?;
    let package = envhub_package(&python).ok_or_else(|| {
        format!(
            "cannot locate envhub's Python package through `{}`, to make it importable in the suite's environment\nhint: run `make py-install` (or `pip install envhub`), or point ENVHUB_PYTHON at an interpreter that has it",
            python.display()
        )
    })?;
    let wait = std::env::var(ENVHUB_PYENV_WAIT)
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|s| s.is_finite() && *s >= 0.0)
        .map_or(Duration::from_secs(900), Duration::from_secs_f64);
    let install = match std::env::var(ENVHUB_PYTHON_INSTALL) {
        Ok(v) if !v.trim().is_empty() => matches!(v.trim(), "1" | "true" | "yes"),
        _ => crate::settings::Settings::discover(None).is_ok_and(|s| s.python_install),
    };
    Ok(Store::new(cache_dir()?, uv, python)
        .with_python_install(install)
        .with_extra_requirements(WORKER_REQUIREMENTS.iter().map(|s| s.to_string()).collect())
        .with_packages(vec![package])
        .with_lock_wait(wait))
}

/// The folder of the `envhub` package this code belongs to: the one holding the `_envhub`
/// extension it runs in (a hub inside a Python client), or beside this binary
/// (`envhub/bin/envhub`), else where `python` imports it from.
fn envhub_package(python: &std::path::Path) -> Option<PathBuf> {
    let is_package = |dir: &std::path::Path| {
        dir.join("worker").join("__main__.py").is_file() && dir.join("__init__.py").is_file()
    };
    if let Some(package) = loaded_from().as_deref().and_then(std::path::Path::parent)
        && is_package(package)
    {
        return Some(package.to_path_buf());
    }
    let exe = std::env::current_exe().ok()?;
    if let Some(package) = exe.parent().and_then(|bin| bin.parent())
        && is_package(package)
    {
        return Some(package.to_path_buf());
    }
    let out = std::process::Command::new(python)
        .args([
            "-c",
            "import importlib.util as u; s = u.find_spec('envhub'); print(s.submodule_search_locations[0])",
        ])
        .output()
        .ok()?;
    let path = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim());
    (out.status.success() && is_package(&path)).then_some(path)
}

/// The file this code was loaded from: the `_envhub` extension when the hub runs in a
/// Python client (whose own `envhub` is the one its workers must run, whatever another
/// interpreter would import), else the executable.
fn loaded_from() -> Option<PathBuf> {
    use std::os::unix::ffi::OsStrExt;
    // SAFETY: `dladdr` only reads the address and fills `info`; `dli_fname` then points to
    // a NUL-terminated string owned by the loader, valid while the object stays loaded.
    unsafe {
        let mut info: libc::Dl_info = std::mem::zeroed();
        let here = loaded_from as *const libc::c_void;
        if libc::dladdr(here, &mut info) == 0 || info.dli_fname.is_null() {
            return None;
        }
        let name = std::ffi::CStr::from_ptr(info.dli_fname);
        Some(PathBuf::from(std::ffi::OsStr::from_bytes(name.to_bytes())))
    }
}

/// The environment `entry` runs in, if any: its name and spec.
pub fn env_of<'a>(
    registry: &'a Registry,
    entry: &'a EnvEntry,
) -> Option<(&'a str, &'a PythonEnvSpec)> {
    let envs = registry.python_envs();
    let name = envs.name_for(entry)?;
    Some((name, envs.get(name)?))
}

/// Whether the environment is built and ready (`None`: the store cannot be set up).
pub fn is_ready(name: &str, spec: &PythonEnvSpec) -> Result<bool, String> {
    let store = store()?;
    let plan = store.plan(name, spec).map_err(|e| e.to_string())?;
    Ok(store.ready(&plan).is_some())
}

/// The interpreter and variables `entry`'s workers run with: `None` for an entry that runs in
/// the hub's interpreter; else its environment, built first when `may_build` (else an error
/// that says how to build it).
pub(crate) fn worker_python(
    registry: &Registry,
    entry: &EnvEntry,
    may_build: bool,
    refused_hint: &str,
) -> Result<Option<WorkerPython>, HubError> {
    let Some((name, spec)) = env_of(registry, entry) else {
        return Ok(None);
    };
    let failed = |message: String| HubError::PythonEnv {
        name: name.to_string(),
        message,
    };
    let store = store().map_err(|why| {
        failed(format!(
            "cannot provide python env `{name}` for `{}`: {why}",
            entry.id
        ))
    })?;
    let env = if may_build {
        store
            .ensure(name, spec)
            .map_err(|e| failed(format!("{e:#}")))?
    } else {
        let plan = store.plan(name, spec).map_err(|e| failed(e.to_string()))?;
        let env = store.ready(&plan).ok_or_else(|| {
            failed(format!(
                "python env `{name}` (for `{}`) is not provisioned\nhint: {refused_hint}",
                entry.id
            ))
        })?;
        store.used(&env);
        env
    };
    as_run(store, env)
        .map(Some)
        .map_err(|e| failed(e.to_string()))
}

/// How this install's processes run in a built environment: its interpreter and variables,
/// and this install's own way into the venv (its overlay, never a link another install
/// re-points).
fn as_run(
    store: &Store,
    env: envhub_pyenv::PythonEnv,
) -> Result<WorkerPython, envhub_pyenv::PyEnvError> {
    let overlay = store.overlay(&env.name)?;
    Ok(WorkerPython {
        sys_path: vec![overlay],
        package: store.packages().first().cloned(),
        hold: Some(env.hold()),
        name: env.name,
        interpreter: env.python,
        env: env.env,
    })
}

/// A program of this install run in the catalog's Python environment `name` (`envhub env
/// run`), built first where it is not: its command, and the environment it runs in.
pub fn program_in(
    registry: &Registry,
    name: &str,
    args: &[std::ffi::OsString],
) -> Result<(std::process::Command, WorkerPython), String> {
    let env = named_env(registry, name)?;
    Ok((crate::python_host::environment_program(&env, args), env))
}

/// The catalog's declaration of the Python environment `name`, or an error naming those
/// it declares.
pub fn declared<'a>(registry: &'a Registry, name: &str) -> Result<&'a PythonEnvSpec, String> {
    let all = registry.python_envs().all();
    all.get(name).ok_or_else(|| {
        let known: Vec<&str> = all.keys().map(String::as_str).collect();
        format!(
            "no python env `{name}` in the catalog (defined: {})\nhint: `envhub env list` shows them",
            if known.is_empty() { "none".to_string() } else { known.join(", ") }
        )
    })
}

fn named_env(registry: &Registry, name: &str) -> Result<WorkerPython, String> {
    let spec = declared(registry, name)?;
    let store = store()?;
    let env = store.ensure(name, spec).map_err(|e| format!("{e:#}"))?;
    as_run(store, env).map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_builtin_catalogs_environments_ship_locked_for_linux() {
        let extra: Vec<String> = WORKER_REQUIREMENTS.iter().map(|s| s.to_string()).collect();
        let registry = Registry::builtin();
        assert!(!registry.python_envs().all().is_empty());
        for (name, spec) in registry.python_envs().all() {
            let envhub_pyenv::Locking::Locked { lock, .. } = &spec.lock else {
                panic!(
                    "python env `{name}` is not in configs/env_registry.lock.yaml: run `envhub env lock {name}` from the checkout"
                );
            };
            assert_eq!(
                lock.declaration,
                spec.declaration_hash(&extra),
                "python env `{name}` changed since it was locked: run `envhub env lock {name}` from the checkout"
            );
            for platform in ["x86_64-unknown-linux-gnu", "aarch64-unknown-linux-gnu"] {
                let pins = &lock.platforms[platform];
                assert!(pins.iter().all(|p| p.contains("==")), "{name} {platform}");
            }
        }
    }

    #[test]
    fn the_worker_needs_what_pyproject_lists() {
        let pyproject = include_str!("../../../python/pyproject.toml");
        for need in WORKER_REQUIREMENTS {
            assert!(
                pyproject.contains(&format!("\"{need}")),
                "`{need}` is not a dependency in python/pyproject.toml: keep WORKER_REQUIREMENTS in step"
            );
        }
    }
}
