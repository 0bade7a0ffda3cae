//! The cache folder of environments: building one, finding it ready, listing and removing.
//!
//! Layout of `<root>`: `<name>-<key>/` a ready venv (its `envhub-env.json` manifest written
//! before the folder got its name), `<name>-<key>.lock` its build lock, `.tmp-<name>-<key>-*`
//! a build in progress or one that was interrupted (cleared by the next build of that key),
//! `.installs/<hash>/` one install's overlay (see [`Store::overlay`]). A build happens in
//! the temporary folder and is renamed into place only once everything succeeded, so nothing
//! half-installed is ever found ready.
//!
//! This file holds the store's types and its front door ([`Store::ensure`]: plan, find ready
//! or build under the lock); each step lives in a module of its own, one concept each:
//! `plan` (a declaration to its key, folder and interpreter), `locking` (resolving a
//! declaration into its lock entry), `build` (a venv built in a temporary folder), `overlay`
//! (the folder through which workers import this install's `envhub`) and `housekeeping`
//! (list, remove, prune).

mod build;
mod housekeeping;
mod locking;
mod overlay;
mod plan;

pub use housekeeping::{PruneRule, Pruned, Stored};

use crate::error::{PyEnvError, io};
use crate::interpreter::{self, Interpreter};
use crate::lock;
use envhub_catalog::PythonEnvSpec;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// The manifest of a ready environment (`envhub-env.json` in its folder).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Its name in the registry.
    pub name: String,
    /// The key (hash of the Python version and requirements).
    pub key: String,
    /// Full version of its interpreter (`3.10.13`).
    pub python_version: String,
    /// The interpreter it is based on.
    pub base_interpreter: PathBuf,
    /// Everything installed on request: the spec's requirements and the worker's.
    pub requirements: Vec<String>,
    /// Installed after them without their dependencies.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub no_deps: Vec<String>,
    /// What everything resolved to (`uv pip freeze`: `name==version`, sorted): what an
    /// unpinned requirement became on this machine, that day.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub resolved: Vec<String>,
    /// The platform it was built for (uv's name, `x86_64-unknown-linux-gnu`).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub platform: String,
    /// The lock's pins it was built from exactly (empty: its registry has no lock).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub locked: Vec<String>,
    /// When it was built (seconds since the Unix epoch).
    pub created_unix: u64,
    /// How long building it took.
    pub install_seconds: f64,
}

const MANIFEST: &str = "envhub-env.json";
const LAST_USE: &str = ".envhub-last-use";
/// The folder of the installs' overlays in the cache folder.
const INSTALLS: &str = ".installs";

/// An environment ready to run workers.
#[derive(Clone, Debug, PartialEq)]
pub struct PythonEnv {
    /// Its name.
    pub name: String,
    /// Its key.
    pub key: String,
    /// The venv.
    pub dir: PathBuf,
    /// Its interpreter (`<dir>/bin/python`).
    pub python: PathBuf,
    /// Variables its workers run with.
    pub env: BTreeMap<String, String>,
    /// Whether this call built it (false: it was ready, or another process built it).
    pub built: bool,
}

impl PythonEnv {
    /// The file each of its running workers holds a shared `flock` on (its manifest), so
    /// that [`Store::remove`] can tell it is in use.
    pub fn hold(&self) -> PathBuf {
        self.dir.join(MANIFEST)
    }
}

/// What an environment resolves to before it is built: its key, folder and base interpreter.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Its name.
    pub name: String,
    /// Its key.
    pub key: String,
    /// Where it is (or will be).
    pub dir: PathBuf,
    /// The interpreter to base it on.
    pub base: PathBuf,
    /// Everything to install.
    pub requirements: Vec<String>,
    /// Installed after `requirements`, without their dependencies.
    pub no_deps: Vec<String>,
    /// Variables for its workers.
    pub env: BTreeMap<String, String>,
    /// The platform it is for (uv's name, `x86_64-unknown-linux-gnu`).
    pub platform: String,
    /// Its lock's pins for this platform, installed exactly (`uv pip sync`); `None`: its
    /// registry file has no lock, and `requirements` are resolved when it is built.
    pub locked: Option<Vec<String>>,
    /// uv's options from the declaration (index URLs, torch backend).
    pub uv_args: Vec<String>,
}

/// Builds environments into a cache folder with uv and finds them there.
#[derive(Debug)]
pub struct Store {
    root: PathBuf,
    uv: PathBuf,
    default_python: PathBuf,
    extra_requirements: Vec<String>,
    packages: Vec<PathBuf>,
    lock_wait: Duration,
    progress: bool,
    from_pyenv: OnceLock<Vec<Interpreter>>,
    from_uv: OnceLock<Vec<Interpreter>>,
    merged: OnceLock<Vec<Interpreter>>,
    default_version: OnceLock<Option<String>>,
    overlay: OnceLock<PathBuf>,
    python_install: bool,
    qualified: std::sync::Mutex<std::collections::HashMap<PathBuf, bool>>,
}

impl Store {
    /// A store in `root`, building with `uv`; environments that name no Python version are
    /// based on `default_python` (the hub's interpreter).
    pub fn new(root: PathBuf, uv: PathBuf, default_python: PathBuf) -> Store {
        Store {
            root,
            uv,
            default_python,
            extra_requirements: Vec::new(),
            packages: Vec::new(),
            lock_wait: Duration::from_secs(900),
            progress: true,
            from_pyenv: OnceLock::new(),
            from_uv: OnceLock::new(),
            merged: OnceLock::new(),
            default_version: OnceLock::new(),
            overlay: OnceLock::new(),
            python_install: false,
            qualified: Default::default(),
        }
    }

    /// Requirements every environment gets besides its own (where it names no such
    /// package): what the linked packages need at import.
    pub fn with_extra_requirements(mut self, extra: Vec<String>) -> Store {
        self.extra_requirements = extra;
        self
    }

    /// Python package folders (`.../envhub`) every environment's workers import, through
    /// this install's [`overlay`](Store::overlay) (and once after a build, as its check).
    pub fn with_packages(mut self, packages: Vec<PathBuf>) -> Store {
        self.packages = packages;
        self
    }

    /// Whether a CPython version that no environment can be based on here is installed by
    /// asking uv (`uv python install`, a download; default false).
    pub fn with_python_install(mut self, install: bool) -> Store {
        self.python_install = install;
        self
    }

    /// How long to wait for another process's build of the same environment.
    pub fn with_lock_wait(mut self, wait: Duration) -> Store {
        self.lock_wait = wait;
        self
    }

    /// Whether to print progress lines on stderr (default true).
    pub fn with_progress(mut self, progress: bool) -> Store {
        self.progress = progress;
        self
    }

    /// The cache folder.
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// The interpreters present on this machine.
    pub fn interpreters(&self) -> &[Interpreter] {
        let all = [self.pyenv_interpreters(), self.uv_interpreters()];
        self.merged.get_or_init(|| interpreter::merged(&all))
    }

    fn pyenv_interpreters(&self) -> &[Interpreter] {
        self.from_pyenv.get_or_init(interpreter::from_pyenv)
    }

    fn uv_interpreters(&self) -> &[Interpreter] {
        self.from_uv.get_or_init(|| interpreter::from_uv(&self.uv))
    }

    /// The environment of `plan` if it is ready (built completely, for these requirements).
    pub fn ready(&self, plan: &Plan) -> Option<PythonEnv> {
        let manifest = read_manifest(&plan.dir)?;
        let python = plan.dir.join("bin").join("python");
        (manifest.requirements == plan.requirements
            && manifest.no_deps == plan.no_deps
            && manifest.locked.as_slice() == plan.locked.as_deref().unwrap_or_default()
            && python.exists())
        .then(|| PythonEnv {
            name: plan.name.clone(),
            key: plan.key.clone(),
            dir: plan.dir.clone(),
            python,
            env: plan.env.clone(),
            built: false,
        })
    }

    /// The environment `name` as `spec` describes it, built first if it is not ready. Two
    /// callers (processes or threads) build it once: the other waits up to the lock wait.
    pub fn ensure(&self, name: &str, spec: &PythonEnvSpec) -> Result<PythonEnv, PyEnvError> {
        let plan = self.plan(name, spec)?;
        if let Some(env) = self.ready(&plan) {
            self.used(&env);
            return Ok(env);
        }
        std::fs::create_dir_all(&self.root).map_err(io(name, "create", &self.root))?;
        let lock_path = self.root.join(format!("{name}-{}.lock", plan.key));
        let progress = self.progress;
        let _lock = lock::acquire(name, &lock_path, self.lock_wait, |holder| {
            tracing::info!(
                env = name,
                holder,
                "waiting for another build of the python env"
            );
            if progress {
                eprintln!(
                    "envhub: waiting for python env `{name}`: another process ({holder}) is building it (up to {} s)",
                    self.lock_wait.as_secs()
                );
            }
        })?;
        if let Some(env) = self.ready(&plan) {
            self.used(&env);
            return Ok(env); // built by the process we waited for
        }
        self.clear_leftovers(&plan)?;
        let mut env = self.build(&plan)?;
        env.built = true;
        self.used(&env);
        Ok(env)
    }

    /// Records that `env` was used, for `prune`. Best effort: a read-only cache (a CI image
    /// built with `envhub env sync`) serves sessions all the same.
    pub fn used(&self, env: &PythonEnv) {
        let now = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
            .as_secs();
        let path = env.dir.join(LAST_USE);
        if let Err(e) = std::fs::write(&path, format!("{now}\n")) {
            tracing::debug!(path = %path.display(), "cannot record the last use: {e}");
        }
    }

    /// The package folders every environment's workers import (envhub's own).
    pub fn packages(&self) -> &[PathBuf] {
        &self.packages
    }
}

fn read_manifest(dir: &Path) -> Option<Manifest> {
    let text = std::fs::read_to_string(dir.join(MANIFEST)).ok()?;
    serde_json::from_str(&text).ok()
}

/// The last `n` lines of `text` (the end of a tool's output, where its error is).
fn last_lines(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}
