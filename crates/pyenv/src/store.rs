//! The cache folder of environments: building one, finding it ready, listing and removing.
//!
//! Layout of `<root>`: `<name>-<key>/` a ready venv (its `envhub-env.json` manifest written
//! before the folder got its name), `<name>-<key>.lock` its build lock, `.tmp-<name>-<key>-*`
//! a build in progress or one that was interrupted (cleared by the next build of that key),
//! `.installs/<hash>/` one install's overlay (see [`Store::overlay`]). A build happens in
//! the temporary folder and is renamed into place only once everything succeeded, so nothing
//! half-installed is ever found ready.

use crate::error::{PyEnvError, io};
use crate::hold;
use crate::interpreter::{self, Interpreter};
use crate::lock;
use crate::uv;
use envhub_catalog::{
    EnvLock, Locking, PythonEnvSpec, fnv1a64, package_name, parse_version, valid_name,
};
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashSet};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

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

/// Which stored environments [`Store::prune`] removes: any that one of the rules selects.
#[derive(Clone, Debug, Default)]
pub struct PruneRule {
    /// Those unused (no session, no build) for this long.
    pub unused_for: Option<Duration>,
    /// Those whose folder is not one of these (the folders the registries' environments
    /// resolve to); `None`: not this rule.
    pub named: Option<Vec<PathBuf>>,
    /// Then the least recently used, until the cache uses at most this much disk.
    pub max_bytes: Option<u64>,
}

/// What [`Store::prune`] did.
#[derive(Clone, Debug, Default)]
pub struct Pruned {
    /// The folders removed (or to remove), with the disk each used.
    pub removed: Vec<(PathBuf, u64)>,
    /// The folders kept because running workers hold them, with their pids.
    pub in_use: Vec<(PathBuf, Vec<u32>)>,
    /// Disk the environments left use together.
    pub left_bytes: u64,
}

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

/// An environment found in the cache folder.
#[derive(Clone, Debug)]
pub struct Stored {
    /// Its folder's name (`metaworld-2b38c1c44ecc8a00`).
    pub dir_name: String,
    /// Its folder.
    pub dir: PathBuf,
    /// Its manifest, when it is ready.
    pub manifest: Option<Manifest>,
    /// Disk it uses: allocated blocks, each hard-linked file once (most are links into uv's
    /// cache, which they share with it and with other venvs).
    pub size_bytes: u64,
    /// When a hub last used it (or it was built).
    pub last_use: Option<SystemTime>,
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

    /// Resolves `spec` to its key, folder and base interpreter, without building anything.
    pub fn plan(&self, name: &str, spec: &PythonEnvSpec) -> Result<Plan, PyEnvError> {
        let invalid = |message: String| PyEnvError::InvalidSpec {
            name: name.to_string(),
            message,
        };
        if !valid_name(name) {
            return Err(invalid(format!(
                "`{name}` is not a valid name; use letters, digits, `-`, `_` and `.`"
            )));
        }
        spec.validate().map_err(invalid)?;
        let (base, version) = self.base_and_version(name, spec)?;
        let platform = uv::platform();
        let locked = self.locked_pins(name, spec, &version, &platform)?;
        let mut context = format!("platform {platform}\n");
        for pin in locked.iter().flatten() {
            context.push_str(&format!("locked {pin}\n"));
        }
        context.push_str(&uv::settings());
        let key = spec.key(&version, &self.extra_requirements, &context);
        Ok(Plan {
            name: name.to_string(),
            dir: self.root.join(format!("{name}-{key}")),
            key,
            base,
            requirements: spec.full_requirements(&self.extra_requirements),
            no_deps: spec.no_deps_sorted(),
            env: spec.env.clone(),
            platform,
            locked,
            uv_args: spec.uv_args(),
        })
    }

    /// The pins of `spec`'s lock for `platform`; `None` where its registry has no lock
    /// file; an error naming the fix where the lock does not fit the declaration.
    fn locked_pins(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
        version: &str,
        platform: &str,
    ) -> Result<Option<Vec<String>>, PyEnvError> {
        let refused = |message: String| PyEnvError::Lock {
            name: name.to_string(),
            message,
        };
        let (file, lock) = match &spec.lock {
            Locking::Unlocked => return Ok(None),
            Locking::Missing { file } => {
                return Err(refused(format!(
                    "is not in the lock file `{file}`: it was added to the registry without relocking\nhint: `envhub env lock {name}` resolves it (then commit the lock file)"
                )));
            }
            Locking::Locked { file, lock } => (file, lock),
        };
        let declared = spec.declaration_hash(&self.extra_requirements);
        if lock.declaration != declared {
            return Err(refused(format!(
                "its declaration in the registry changed since it was locked (the lock file `{file}` was made from declaration {}, the registry's is {declared})\nhint: `envhub env lock {name}` resolves it again (then commit the lock file)",
                lock.declaration
            )));
        }
        if lock.python != version {
            return Err(refused(format!(
                "the lock file `{file}` is for Python {}, but it would be built on Python {version} (the hub's interpreter's version, as it names none)\nhint: name `python: \"{}\"` in its declaration, or `envhub env lock {name}` with this interpreter",
                lock.python, lock.python
            )));
        }
        match lock.platforms.get(platform) {
            Some(pins) => Ok(Some(pins.clone())),
            None => Err(refused(format!(
                "the lock file `{file}` has no pins for this platform, {platform} (it has {})\nhint: `envhub env lock {name} --platform {platform}` adds them (then commit the lock file)",
                if lock.platforms.is_empty() {
                    "none".to_string()
                } else {
                    lock.platforms
                        .keys()
                        .cloned()
                        .collect::<Vec<_>>()
                        .join(", ")
                }
            ))),
        }
    }

    /// The interpreter to base `spec` on and its version as the key names it (as the
    /// registry writes it, else the hub's interpreter's major.minor).
    fn base_and_version(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
    ) -> Result<(PathBuf, String), PyEnvError> {
        let invalid = |message: String| PyEnvError::InvalidSpec {
            name: name.to_string(),
            message,
        };
        Ok(match &spec.python {
            Some(requested) => {
                let path = self.find_python(name, requested)?;
                (path, requested.trim().to_string())
            }
            None => {
                let version = self
                    .default_version
                    .get_or_init(|| interpreter::version_of(&self.default_python))
                    .clone()
                    .ok_or_else(|| {
                        invalid(format!(
                            "cannot run the hub's interpreter `{}` to learn its version; name one with `python:`",
                            self.default_python.display()
                        ))
                    })?;
                let (major, minor, _) = parse_version(&version).expect("checked by version_of");
                (self.default_python.clone(), format!("{major}.{minor}"))
            }
        })
    }

    /// How `spec` stands against its lock, in a word or three for `envhub env list`:
    /// `unlocked`, `locked`, `stale` (declaration changed), `not in lock`,
    /// `no pins for <platform>`, `locked for Python <version>`.
    pub fn lock_state(&self, name: &str, spec: &PythonEnvSpec) -> String {
        let lock = match &spec.lock {
            Locking::Unlocked => return "unlocked".into(),
            Locking::Missing { .. } => return "not in lock".into(),
            Locking::Locked { lock, .. } => lock,
        };
        if lock.declaration != spec.declaration_hash(&self.extra_requirements) {
            return "stale".into();
        }
        let version = match &spec.python {
            Some(v) => v.trim().to_string(),
            None => match self.base_and_version(name, spec) {
                Ok((_, v)) => v,
                Err(_) => lock.python.clone(),
            },
        };
        let platform = uv::platform();
        if lock.python != version {
            format!("locked for Python {}", lock.python)
        } else if !lock.platforms.contains_key(&platform) {
            format!("no pins for {platform}")
        } else {
            "locked".into()
        }
    }

    /// Resolves `spec` with uv's resolver (`uv pip compile`) for each of `platforms` (uv's
    /// target names): its lock entry. Needs no interpreter of its version on this machine
    /// unless an sdist must be built to learn its dependencies.
    pub fn lock(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
        platforms: &[String],
    ) -> Result<EnvLock, PyEnvError> {
        spec.validate().map_err(|message| PyEnvError::InvalidSpec {
            name: name.to_string(),
            message,
        })?;
        let version = match &spec.python {
            Some(requested) => requested.trim().to_string(),
            None => self.base_and_version(name, spec)?.1,
        };
        let requirements = spec.full_requirements(&self.extra_requirements);
        let no_deps = spec.no_deps_sorted();
        // Outside the cache folder, where `list` and `prune` would take it for a build; a
        // fresh folder of a random name in this user's private folder, which no one else
        // can have made first or enter.
        let private = envhub_core::private_dir::runtime_dir("scratch")
            .map_err(std::io::Error::other)
            .map_err(io(
                name,
                "make a private folder for",
                Path::new("lock scratch"),
            ))?;
        let scratch = envhub_core::private_dir::fresh_dir(&private, &format!("lock-{name}-"))
            .map_err(io(name, "create a scratch folder in", &private))?;
        let result = (|| {
            let mut locked = EnvLock {
                declaration: spec.declaration_hash(&self.extra_requirements),
                python: version.clone(),
                platforms: BTreeMap::new(),
            };
            for platform in platforms {
                let mut pins = self.compile(
                    name,
                    spec,
                    &scratch,
                    &version,
                    platform,
                    &requirements,
                    false,
                )?;
                if !no_deps.is_empty() {
                    let bare =
                        self.compile(name, spec, &scratch, &version, platform, &no_deps, true)?;
                    // Installed after the others, so their version wins.
                    let names: Vec<String> = bare.iter().map(|p| package_name(p)).collect();
                    pins.retain(|p| !names.contains(&package_name(p)));
                    pins.extend(bare);
                }
                pins.sort();
                pins.dedup();
                locked.platforms.insert(platform.clone(), pins);
            }
            Ok(locked)
        })();
        let _ = std::fs::remove_dir_all(&scratch);
        result
    }

    /// One `uv pip compile` of `requirements` for `platform`: `name==version` pins.
    #[allow(clippy::too_many_arguments)]
    fn compile(
        &self,
        name: &str,
        spec: &PythonEnvSpec,
        scratch: &Path,
        version: &str,
        platform: &str,
        requirements: &[String],
        no_deps: bool,
    ) -> Result<Vec<String>, PyEnvError> {
        let tag = if no_deps { "no-deps" } else { "requirements" };
        let input = scratch.join(format!("{tag}.in"));
        let output = scratch.join(format!("{tag}-{platform}.txt"));
        let text: String = requirements.iter().map(|r| format!("{r}\n")).collect();
        std::fs::write(&input, text).map_err(io(name, "write", &input))?;
        let mut compile = Command::new(&self.uv);
        compile
            .args(["pip", "compile", "--quiet", "--no-header", "--no-annotate"])
            .args(["--python-version", version, "--python-platform", platform])
            .args(spec.uv_args());
        if no_deps {
            compile.arg("--no-deps");
        }
        compile.arg(&input).arg("-o").arg(&output);
        let show = self.progress;
        uv::run(compile, Duration::from_secs(10), |elapsed| {
            if show {
                eprintln!(
                    "envhub: python env `{name}`: resolving for {platform} ({} s)",
                    elapsed.as_secs()
                );
            }
        })
        .map_err(|uv::Failed(message)| PyEnvError::Install {
            name: name.to_string(),
            stage: format!("`uv pip compile` for {platform}, Python {version}"),
            packages: uv::named_packages(&message, requirements),
            message,
        })?;
        let text = std::fs::read_to_string(&output).map_err(io(name, "read", &output))?;
        Ok(pins_of(&text))
    }

    /// The newest CPython (default build) matching `requested`: pyenv's, then those uv
    /// finds, each asked what it is; else, where allowed, one uv installs.
    fn find_python(&self, name: &str, requested: &str) -> Result<PathBuf, PyEnvError> {
        let matching = |list: &[Interpreter]| {
            let mut found: Vec<Interpreter> = list
                .iter()
                .filter(|i| version_matches(&i.version, requested))
                .cloned()
                .collect();
            found.sort_by_key(|i| std::cmp::Reverse(parse_version(&i.version)));
            found.into_iter().find(|i| self.qualifies(i))
        };
        if let Some(found) =
            matching(self.pyenv_interpreters()).or_else(|| matching(self.uv_interpreters()))
        {
            return Ok(found.path);
        }
        let not_found = |tried: String| PyEnvError::PythonNotFound {
            name: name.to_string(),
            requested: requested.trim().to_string(),
            present: interpreter::describe(self.interpreters()),
            tried,
        };
        if !self.python_install {
            return Err(not_found(String::new()));
        }
        if self.progress {
            eprintln!("envhub: python env `{name}`: asking uv to install CPython {requested}");
        }
        match interpreter::install_with_uv(&self.uv, requested.trim()) {
            Ok(path)
                if interpreter::version_of(&path).is_some_and(|v| {
                    version_matches(&v, requested) && interpreter::qualifies(&path, &v)
                }) =>
            {
                Ok(path)
            }
            Ok(path) => Err(not_found(format!(
                "; uv installed `{}`, which is not a CPython {requested} of the default build",
                path.display()
            ))),
            Err(message) => Err(not_found(format!(
                "; `uv python install {requested}` failed: {}",
                last_lines(&message, 4)
            ))),
        }
    }

    /// Whether `i` is what it says and envhub can use it (asked once per interpreter).
    fn qualifies(&self, i: &Interpreter) -> bool {
        let mut known = self.qualified.lock().unwrap_or_else(|e| e.into_inner());
        *known
            .entry(i.path.clone())
            .or_insert_with(|| interpreter::qualifies(&i.path, &i.version))
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

    /// Every environment folder in the cache, ready or not, by name.
    pub fn list(&self) -> Vec<Stored> {
        let Ok(read) = std::fs::read_dir(&self.root) else {
            return Vec::new();
        };
        let mut found: Vec<Stored> = read
            .flatten()
            .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
            .filter(|e| e.file_name() != INSTALLS)
            .map(|e| {
                let dir = e.path();
                Stored {
                    dir_name: e.file_name().to_string_lossy().into_owned(),
                    manifest: read_manifest(&dir),
                    size_bytes: disk_usage(&dir, &mut HashSet::new()),
                    last_use: std::fs::metadata(dir.join(LAST_USE))
                        .and_then(|m| m.modified())
                        .ok(),
                    dir,
                }
            })
            .collect();
        found.sort_by(|a, b| a.dir_name.cmp(&b.dir_name));
        found
    }

    /// Removes every stored folder of the environment `name` (or the one folder named
    /// `name`), builds in progress excepted; returns the folders removed. A folder that
    /// running workers hold (see [`PythonEnv::hold`]) is refused with their pids, unless
    /// `force`: then they lose it under them (a restart says it was removed).
    pub fn remove(&self, name: &str, force: bool) -> Result<Vec<PathBuf>, PyEnvError> {
        let stored = self.list();
        let matching: Vec<&Stored> = stored
            .iter()
            .filter(|s| {
                s.dir_name == name
                    || s.manifest.as_ref().is_some_and(|m| m.name == name)
                    || (s.dir_name.starts_with(".tmp-")
                        && s.dir_name[5..].starts_with(&format!("{name}-")))
            })
            .collect();
        if matching.is_empty() {
            let mut known: Vec<String> = stored
                .iter()
                .filter_map(|s| s.manifest.as_ref().map(|m| m.name.clone()))
                .collect();
            known.dedup();
            return Err(PyEnvError::NotStored {
                name: name.to_string(),
                root: self.root.clone(),
                known,
            });
        }
        if !force {
            for s in &matching {
                if let Some(pids) = self.held(s)? {
                    return Err(in_use(name, &s.dir, &pids));
                }
            }
        }
        let mut removed = Vec::new();
        for s in matching {
            // Not while it is being built: its builder holds the lock (`<name>-<key>.lock`).
            let stem = match &s.manifest {
                Some(m) => format!("{}-{}", m.name, m.key),
                None => {
                    let rest = s.dir_name.trim_start_matches(".tmp-");
                    rest.rsplitn(3, '-').nth(2).unwrap_or(rest).to_string()
                }
            };
            let lock_path = self.root.join(format!("{stem}.lock"));
            let _lock = lock::acquire(name, &lock_path, Duration::ZERO, |_| {})?;
            // Held while it goes: a worker starting meanwhile waits, then finds it gone.
            let _hold = match hold::exclusive(&s.dir.join(MANIFEST)) {
                Ok(Some(Ok(hold))) => Some(hold),
                Ok(Some(Err(pids))) if !force => return Err(in_use(name, &s.dir, &pids)),
                _ => None,
            };
            self.remove_dir(name, s)?;
            removed.push(s.dir.clone());
        }
        Ok(removed)
    }

    /// The pids of the running workers that hold `stored` (`Some(empty)`: held by processes
    /// that cannot be told), or `None` when none does.
    fn held(&self, stored: &Stored) -> Result<Option<Vec<u32>>, PyEnvError> {
        let path = stored.dir.join(MANIFEST);
        match hold::exclusive(&path) {
            Ok(Some(Err(pids))) => Ok(Some(pids)),
            Ok(_) => Ok(None),
            Err(e) => Err(io(&stored.dir_name, "open", &path)(e)),
        }
    }

    fn remove_dir(&self, name: &str, s: &Stored) -> Result<(), PyEnvError> {
        let trash = self.root.join(format!(
            ".trash-{}-{}",
            s.dir_name.trim_start_matches('.'),
            std::process::id()
        ));
        std::fs::rename(&s.dir, &trash).map_err(io(name, "remove", &s.dir))?;
        std::fs::remove_dir_all(&trash).map_err(io(name, "remove", &trash))
    }

    /// Removes, of the stored environments, those `rule` selects — never one that running
    /// workers hold — and says what it removed or would remove (`dry_run`).
    pub fn prune(&self, rule: &PruneRule, dry_run: bool) -> Result<Pruned, PyEnvError> {
        let stored: Vec<Stored> = self
            .list()
            .into_iter()
            .filter(|s| !s.dir_name.starts_with('.'))
            .collect();
        let now = SystemTime::now();
        let mut pruned = Pruned::default();
        let mut left: Vec<&Stored> = Vec::new();
        for s in &stored {
            if let Some(pids) = self.held(s)? {
                pruned.in_use.push((s.dir.clone(), pids));
                continue;
            }
            let unused = rule.unused_for.is_some_and(|limit| {
                s.last_use
                    .and_then(|t| now.duration_since(t).ok())
                    .is_none_or(|age| age >= limit)
            });
            let unnamed = rule
                .named
                .as_ref()
                .is_some_and(|named| !named.contains(&s.dir));
            if unused || unnamed {
                pruned.removed.push((s.dir.clone(), s.size_bytes));
            } else {
                left.push(s);
            }
        }
        if let Some(budget) = rule.max_bytes {
            // The least recently used go first, until what is left fits.
            left.sort_by_key(|s| s.last_use);
            let kept_in_use: Vec<PathBuf> = pruned.in_use.iter().map(|(d, _)| d.clone()).collect();
            while disk_usage_of(
                left.iter()
                    .map(|s| s.dir.as_path())
                    .chain(kept_in_use.iter().map(PathBuf::as_path)),
            ) > budget
                && !left.is_empty()
            {
                let s = left.remove(0);
                pruned.removed.push((s.dir.clone(), s.size_bytes));
            }
        }
        if !dry_run {
            for (dir, _) in &pruned.removed {
                let s = stored.iter().find(|s| &s.dir == dir).expect("listed");
                let name = s
                    .manifest
                    .as_ref()
                    .map_or(s.dir_name.as_str(), |m| m.name.as_str());
                let _hold = match hold::exclusive(&dir.join(MANIFEST)) {
                    Ok(Some(Err(pids))) => return Err(in_use(name, dir, &pids)),
                    Ok(Some(Ok(hold))) => Some(hold),
                    _ => None,
                };
                self.remove_dir(name, s)?;
            }
        }
        pruned.left_bytes = disk_usage_of(
            stored
                .iter()
                .filter(|s| !pruned.removed.iter().any(|(d, _)| d == &s.dir))
                .map(|s| s.dir.as_path()),
        );
        Ok(pruned)
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

    /// This install's overlay: the folder its workers put first on `sys.path`, holding one
    /// link per package (`envhub` → this install's package folder) and nothing else. Keyed
    /// by the packages' paths, so each install (a checkout, a wheel) has its own, and none
    /// re-points a link another one's workers follow. In `<root>/.installs/`, or, where the
    /// cache is read-only, in a folder only this user can write.
    pub fn overlay(&self, name: &str) -> Result<PathBuf, PyEnvError> {
        if let Some(dir) = self.overlay.get() {
            return Ok(dir.clone());
        }
        let text: String = self
            .packages
            .iter()
            .map(|p| format!("{}\n", p.display()))
            .collect();
        let key = format!("{:016x}", fnv1a64(text.as_bytes()));
        let in_cache = self.root.join(INSTALLS).join(&key);
        let dir = match fill_overlay(&in_cache, &self.packages) {
            Ok(()) => in_cache,
            Err(e) => {
                let base = private_folder().map_err(io(
                    name,
                    "make a private folder for",
                    Path::new("the overlay"),
                ))?;
                let elsewhere = base.join(&key);
                tracing::debug!(
                    "cannot make the overlay `{}` ({e}); using `{}`",
                    in_cache.display(),
                    elsewhere.display()
                );
                fill_overlay(&elsewhere, &self.packages).map_err(io(
                    name,
                    "make the overlay folder",
                    &elsewhere,
                ))?;
                elsewhere
            }
        };
        Ok(self.overlay.get_or_init(|| dir).clone())
    }

    fn clear_leftovers(&self, plan: &Plan) -> Result<(), PyEnvError> {
        let prefix = format!(".tmp-{}-{}-", plan.name, plan.key);
        for entry in std::fs::read_dir(&self.root)
            .map_err(io(&plan.name, "read", &self.root))?
            .flatten()
        {
            let file_name = entry.file_name();
            let file_name = file_name.to_string_lossy();
            if file_name.starts_with(&prefix) || file_name.starts_with(".trash-") {
                tracing::info!(folder = %file_name, "removing an interrupted build");
                let _ = std::fs::remove_dir_all(entry.path());
            }
        }
        if plan.dir.exists() {
            // Built for other requirements under the same key, or damaged: rebuilt.
            std::fs::remove_dir_all(&plan.dir).map_err(io(&plan.name, "remove", &plan.dir))?;
        }
        Ok(())
    }

    fn build(&self, plan: &Plan) -> Result<PythonEnv, PyEnvError> {
        let name = &plan.name;
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or_default()
            .subsec_nanos();
        let tmp = self.root.join(format!(
            ".tmp-{name}-{}-{}-{nanos}",
            plan.key,
            std::process::id()
        ));
        let start = Instant::now();
        if self.progress {
            eprintln!(
                "envhub: building python env `{name}` ({} requirements, on `{}`) into `{}`; this can take minutes",
                plan.requirements.len(),
                plan.base.display(),
                plan.dir.display()
            );
        }
        let result = self.build_in(plan, &tmp, start);
        if result.is_err() {
            let _ = std::fs::remove_dir_all(&tmp);
        }
        result?;
        std::fs::rename(&tmp, &plan.dir).map_err(io(name, "rename into place", &tmp))?;
        if self.progress {
            eprintln!(
                "envhub: python env `{name}` ready in {:.1} s",
                start.elapsed().as_secs_f64()
            );
        }
        Ok(PythonEnv {
            name: name.clone(),
            key: plan.key.clone(),
            python: plan.dir.join("bin").join("python"),
            dir: plan.dir.clone(),
            env: plan.env.clone(),
            built: true,
        })
    }

    fn build_in(&self, plan: &Plan, tmp: &Path, start: Instant) -> Result<(), PyEnvError> {
        let name = &plan.name;
        let failed = |stage: &str, message: String| PyEnvError::Install {
            name: name.clone(),
            stage: stage.to_string(),
            packages: uv::named_packages(&message, &plan.requirements),
            message,
        };
        let every = Duration::from_secs(10);
        let progress = |stage: &'static str| {
            let show = self.progress;
            move |elapsed: Duration| {
                if show {
                    eprintln!(
                        "envhub: python env `{name}`: {stage} ({} s)",
                        elapsed.as_secs()
                    );
                }
            }
        };
        let mut venv = Command::new(&self.uv);
        venv.args([
            "venv",
            "--quiet",
            "--relocatable",
            "--no-python-downloads",
            "--python",
        ])
        .arg(&plan.base)
        .arg(tmp);
        uv::run(venv, every, progress("creating the venv")).map_err(|uv::Failed(m)| {
            PyEnvError::Install {
                name: name.clone(),
                stage: "`uv venv`".into(),
                packages: format!("its interpreter `{}`", plan.base.display()),
                message: m,
            }
        })?;
        let python = tmp.join("bin").join("python");
        if let Some(pins) = &plan.locked {
            // Exactly the lock: `uv pip sync` installs what it lists and nothing else (no
            // resolution, no dependency it does not list), and removes anything else.
            let file = tmp.join("envhub-lock.txt");
            let text: String = pins.iter().map(|p| format!("{p}\n")).collect();
            std::fs::write(&file, text).map_err(io(name, "write", &file))?;
            let mut sync = Command::new(&self.uv);
            sync.args(["pip", "sync", "--quiet", "--python"])
                .arg(&python)
                .args(&plan.uv_args)
                .arg(&file);
            uv::run(sync, every, progress("installing the lock"))
                .map_err(|uv::Failed(m)| failed("`uv pip sync` of the lock", m))?;
        } else {
            let mut install = Command::new(&self.uv);
            install
                .args(["pip", "install", "--quiet", "--python"])
                .arg(&python)
                .args(&plan.uv_args)
                .args(&plan.requirements);
            uv::run(install, every, progress("installing"))
                .map_err(|uv::Failed(m)| failed("`uv pip install`", m))?;
            if !plan.no_deps.is_empty() {
                let mut bare = Command::new(&self.uv);
                bare.args(["pip", "install", "--quiet", "--no-deps", "--python"])
                    .arg(&python)
                    .args(&plan.uv_args)
                    .args(&plan.no_deps);
                uv::run(bare, every, progress("installing without dependencies"))
                    .map_err(|uv::Failed(m)| failed("`uv pip install --no-deps`", m))?;
            }
        }
        if !self.packages.is_empty() {
            let overlay = self.overlay(name)?;
            let modules: Vec<String> = self
                .packages
                .iter()
                .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
                .collect();
            let mut check = Command::new(&python);
            // As its workers will: through this install's overlay.
            check.arg("-c").arg(format!(
                "import sys; sys.path.insert(0, {:?}); import {}",
                overlay.display().to_string(),
                modules.join(", ")
            ));
            uv::run(check, every, |_| {}).map_err(|uv::Failed(m)| {
                failed(
                    "importing envhub's worker package in the new env",
                    last_lines(&m, 6),
                )
            })?;
        }
        let mut freeze = Command::new(&self.uv);
        freeze.args(["pip", "freeze", "--python"]).arg(&python);
        let frozen =
            uv::run(freeze, every, |_| {}).map_err(|uv::Failed(m)| failed("`uv pip freeze`", m))?;
        let mut resolved: Vec<String> = frozen
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty())
            .map(String::from)
            .collect();
        resolved.sort();
        if let Some(pins) = &plan.locked {
            let normal = |list: &[String]| -> Vec<String> {
                let mut out: Vec<String> = list.iter().map(|p| normal_pin(p)).collect();
                out.sort();
                out
            };
            let (want, got) = (normal(pins), normal(&resolved));
            if want != got {
                let missing: Vec<&String> = want.iter().filter(|p| !got.contains(p)).collect();
                let extra: Vec<&String> = got.iter().filter(|p| !want.contains(p)).collect();
                return Err(failed(
                    "checking the venv against the lock",
                    format!(
                        "installed packages differ from the lock: missing {missing:?}, not in the lock {extra:?}"
                    ),
                ));
            }
        }
        let manifest = Manifest {
            name: name.clone(),
            key: plan.key.clone(),
            python_version: interpreter::version_of(&python).unwrap_or_default(),
            base_interpreter: plan.base.clone(),
            requirements: plan.requirements.clone(),
            no_deps: plan.no_deps.clone(),
            resolved,
            platform: plan.platform.clone(),
            locked: plan.locked.clone().unwrap_or_default(),
            created_unix: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .unwrap_or_default()
                .as_secs(),
            install_seconds: start.elapsed().as_secs_f64(),
        };
        let path = tmp.join(MANIFEST);
        let text = serde_json::to_string_pretty(&manifest).expect("a manifest serializes");
        std::fs::write(&path, text).map_err(io(name, "write", &path))
    }
}

/// The `name==version` lines of a `uv pip compile` output (comments, options and blank
/// lines dropped).
fn pins_of(text: &str) -> Vec<String> {
    let mut pins: Vec<String> = text
        .lines()
        .map(|l| l.split(" #").next().unwrap_or("").trim())
        .filter(|l| !l.is_empty() && !l.starts_with('#') && !l.starts_with('-'))
        .map(String::from)
        .collect();
    pins.sort();
    pins
}

/// A pin with its package name normalized (`PyOpenGL==3.1.10` → `pyopengl==3.1.10`).
fn normal_pin(pin: &str) -> String {
    match pin.split_once("==") {
        Some((name, version)) => format!("{}=={}", package_name(name), version.trim()),
        None => pin.trim().to_string(),
    }
}

fn version_matches(version: &str, requested: &str) -> bool {
    match (parse_version(version), parse_version(requested)) {
        (Some((a, b, c)), Some((x, y, z))) => (a, b) == (x, y) && (z.is_none() || c == z),
        _ => false,
    }
}

fn read_manifest(dir: &Path) -> Option<Manifest> {
    let text = std::fs::read_to_string(dir.join(MANIFEST)).ok()?;
    serde_json::from_str(&text).ok()
}

/// A folder only this user can write, for overlays when the cache is read-only:
/// `installs/` of this user's private folder ([`envhub_core::private_dir`]),
/// made with mode 0700 and refused, naming what is wrong, unless every component of its path
/// is this user's or root's and closed to others' writes (another user could otherwise point
/// the worker's `envhub` at their code).
fn private_folder() -> std::io::Result<PathBuf> {
    envhub_core::private_dir::runtime_dir("installs").map_err(std::io::Error::other)
}

/// Makes `dir` hold one link per package folder (`envhub` → the package), where it does
/// not already; a link is replaced atomically (made beside it, renamed over it).
fn fill_overlay(dir: &Path, packages: &[PathBuf]) -> std::io::Result<()> {
    for package in packages {
        let Some(file_name) = package.file_name() else {
            continue;
        };
        let link = dir.join(file_name);
        if std::fs::read_link(&link).is_ok_and(|target| &target == package) {
            continue;
        }
        std::fs::create_dir_all(dir)?;
        let tmp = dir.join(format!(
            ".{}-{}.link",
            file_name.to_string_lossy(),
            std::process::id()
        ));
        let _ = std::fs::remove_file(&tmp);
        std::os::unix::fs::symlink(package, &tmp)?;
        std::fs::rename(&tmp, &link)?;
    }
    Ok(())
}

/// Disk used by the files under `dir`: allocated blocks, each file once however many hard
/// links lead to it (`seen`: the files already counted, by device and inode).
fn disk_usage(dir: &Path, seen: &mut HashSet<(u64, u64)>) -> u64 {
    use std::os::unix::fs::MetadataExt;
    let Ok(read) = std::fs::read_dir(dir) else {
        return 0;
    };
    read.flatten()
        .map(|e| match e.metadata() {
            Ok(m) if m.is_dir() => disk_usage(&e.path(), seen),
            Ok(m) if seen.insert((m.dev(), m.ino())) => m.blocks() * 512,
            _ => 0,
        })
        .sum()
}

/// Disk used by all of `dirs` together (a file linked into several counted once).
fn disk_usage_of<'a>(dirs: impl Iterator<Item = &'a Path>) -> u64 {
    let mut seen = HashSet::new();
    dirs.map(|d| disk_usage(d, &mut seen)).sum()
}

fn in_use(name: &str, dir: &Path, pids: &[u32]) -> PyEnvError {
    PyEnvError::InUse {
        name: name.to_string(),
        dir: dir.to_path_buf(),
        pids: if pids.is_empty() {
            "pids unknown".into()
        } else {
            let list: Vec<String> = pids.iter().map(u32::to_string).collect();
            format!("pid {}", list.join(", "))
        },
    }
}

fn last_lines(text: &str, n: usize) -> String {
    let lines: Vec<&str> = text.lines().collect();
    lines[lines.len().saturating_sub(n)..].join("\n")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_lock_state_says_how_a_declaration_fits_its_lock() {
        let store = Store::new("/nonexistent".into(), "uv".into(), "python3".into())
            .with_extra_requirements(vec!["numpy".into()]);
        let mut spec = PythonEnvSpec {
            python: Some("3.11".into()),
            requirements: vec!["mujoco==3.3.0".into()],
            ..Default::default()
        };
        assert_eq!(store.lock_state("s", &spec), "unlocked");
        let mut lock = EnvLock {
            declaration: spec.declaration_hash(&["numpy".into()]),
            python: "3.11".into(),
            platforms: BTreeMap::new(),
        };
        lock.platforms
            .insert(uv::platform(), vec!["mujoco==3.3.0".into()]);
        let locked = |lock: &EnvLock| Locking::Locked {
            file: "s.lock.yaml".into(),
            lock: lock.clone(),
        };
        spec.lock = locked(&lock);
        assert_eq!(store.lock_state("s", &spec), "locked");
        // The worker's requirements are part of what was locked.
        let bare = Store::new("/nonexistent".into(), "uv".into(), "python3".into());
        assert_eq!(bare.lock_state("s", &spec), "stale");
        let mut other = lock.clone();
        other.platforms = [("riscv64-unknown-linux".to_string(), vec![])].into();
        spec.lock = locked(&other);
        assert_eq!(
            store.lock_state("s", &spec),
            format!("no pins for {}", uv::platform())
        );
        let mut older = lock.clone();
        older.python = "3.10".into();
        spec.lock = locked(&older);
        assert_eq!(store.lock_state("s", &spec), "locked for Python 3.10");
        spec.lock = Locking::Missing {
            file: "s.lock.yaml".into(),
        };
        assert_eq!(store.lock_state("s", &spec), "not in lock");
        spec.lock = locked(&lock);
        spec.requirements.push("packaging".into());
        assert_eq!(store.lock_state("s", &spec), "stale");
    }

    #[test]
    fn compile_output_becomes_pins() {
        let text = "# header\nmujoco==3.3.0\n    # via metaworld\n--index-url https://x\n\nabsl-py==2.5.1  # comment\n";
        assert_eq!(pins_of(text), ["absl-py==2.5.1", "mujoco==3.3.0"]);
        assert_eq!(normal_pin("PyOpenGL==3.1.10"), "pyopengl==3.1.10");
    }

    #[test]
    fn disk_usage_counts_a_hard_linked_file_once() {
        let dir = std::env::temp_dir().join(format!("envhub-du-test-{}", std::process::id()));
        let (a, b) = (dir.join("a"), dir.join("b"));
        std::fs::create_dir_all(&a).unwrap();
        std::fs::create_dir_all(&b).unwrap();
        std::fs::write(a.join("data"), vec![1u8; 1 << 20]).unwrap();
        std::fs::hard_link(a.join("data"), a.join("again")).unwrap();
        std::fs::hard_link(a.join("data"), b.join("data")).unwrap();
        let one = disk_usage(&a, &mut HashSet::new());
        assert!((1 << 20..(1 << 20) + 65_536).contains(&one), "{one}");
        assert_eq!(disk_usage_of([a.as_path(), b.as_path()].into_iter()), one);
        assert_eq!(disk_usage(&b, &mut HashSet::new()), one);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
