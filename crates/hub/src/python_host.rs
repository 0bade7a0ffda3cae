//! Python-hosted adapters: which interpreter runs them, and how it is started.
//!
//! Simulators that only exist in Python run in `python -m envhub.worker` processes (see the
//! `envhub._envhub` bindings for why a Python process rather than CPython embedded in
//! `envhub-worker`). The hub asks that module what it hosts (`describe`), as it asks the
//! Rust worker binary, and starts it with `serve --job` for the adapters it reported.

use crate::env_vars::{ENVHUB_ADAPTERS, ENVHUB_PYTHON, ENVHUB_WORKER_PROTOCOL};
use envhub_protocol::HubError;
/// User adapters beyond this hub's own, as they travel to a daemon.
pub(crate) use envhub_protocol::daemon::UserAdapters;
use envhub_shm::{ReadySpec, WorkerIdentity, WorkerPython};
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
/// It runs in the provisioned environment `env` (see [`provisioned_command`]), or in the
/// hub's interpreter.
pub(crate) fn worker_command_in(
    env: Option<&envhub_shm::WorkerPython>,
    extra: &UserAdapters,
) -> Command {
    let adapters = unique(own_adapters().into_iter().chain(extra.adapters.clone()));
    let mut cmd = match env {
        Some(env) => provisioned_command(env, &adapters, extra),
        None => {
            let mut cmd = Command::new(python_interpreter());
            cmd.arg("-m").arg("envhub.worker");
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
    };
    if !adapters.is_empty() {
        cmd.env(ENVHUB_ADAPTERS, adapters.join(","));
    }
    // The worker refuses to serve a hub that speaks another protocol.
    cmd.env(
        ENVHUB_WORKER_PROTOCOL,
        envhub_shm::WORKER_PROTOCOL.to_string(),
    );
    cmd
}

/// Variables of the hub's own Python set-up that would make a suite's worker import other
/// packages than its environment's (a ROS or conda `PYTHONPATH`, an activated venv).
const HUB_PYTHON_VARS: &[&str] = &["PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV", "PYTHONUSERBASE"];

/// The worker in a provisioned environment ([`in_environment`]). It starts through
/// [`bootstrap`] rather than
/// `-m`, which would put the current folder first on `sys.path` (`-P` exists only from 3.11).
fn provisioned_command(
    env: &envhub_shm::WorkerPython,
    adapters: &[String],
    extra: &UserAdapters,
) -> Command {
    let mut cmd = in_environment(env);
    // User adapters' folders go after the venv's own packages: they can add modules, never
    // shadow the suite's pins.
    let mut after = Vec::new();
    if !adapters.is_empty() {
        after.extend(user_adapters_of_this_process().pythonpath);
        after.extend(extra.pythonpath.iter().cloned());
    }
    cmd.arg("-c").arg(bootstrap(env, &unique(after)));
    cmd
}

/// A program run in a provisioned environment by `envhub env run` (a policy, a user's
/// script): its interpreter with `args`, as [`provisioned_command`] sets it up, with this
/// install's overlay as `PYTHONPATH`, so it imports this install's `envhub` (after the
/// script's folder or, with `-m`, the current one, as Python does).
pub(crate) fn environment_program(
    env: &envhub_shm::WorkerPython,
    args: &[std::ffi::OsString],
) -> Command {
    let mut cmd = in_environment(env);
    if let Ok(joined) = std::env::join_paths(&env.sys_path) {
        cmd.env("PYTHONPATH", joined);
    }
    cmd.args(args);
    cmd
}

/// The environment's interpreter, with none of the hub's Python variables, as if its venv
/// were activated (`VIRTUAL_ENV`, its `bin/` first on `PATH`), then the variables the
/// environment declares.
fn in_environment(env: &envhub_shm::WorkerPython) -> Command {
    let mut cmd = Command::new(&env.interpreter);
    for var in HUB_PYTHON_VARS {
        cmd.env_remove(var);
    }
    if let Some(venv) = env.interpreter.parent().and_then(|bin| bin.parent()) {
        cmd.env("VIRTUAL_ENV", venv);
        let path = std::env::var_os("PATH")
            .map(|v| std::env::split_paths(&v).collect::<Vec<_>>())
            .unwrap_or_default();
        if let Ok(joined) =
            std::env::join_paths(unique(std::iter::once(venv.join("bin")).chain(path)))
        {
            cmd.env("PATH", joined);
        }
    }
    cmd.envs(&env.env);
    cmd
}

/// The program a provisioned environment's worker starts with: `sys.path` without the
/// current folder (which `-c` puts first), the environment's `sys_path` (this install's
/// overlay) before everything and `after` after; a serving worker then holds the
/// environment (a shared `flock` on its `hold` file, for its whole life) or says it was
/// removed; then `envhub.worker` runs as `python -m` would (its arguments follow the program).
fn bootstrap(env: &envhub_shm::WorkerPython, after: &[PathBuf]) -> String {
    let list = |paths: &[PathBuf]| {
        let texts: Vec<&str> = paths.iter().filter_map(|p| p.to_str()).collect();
        serde_json::to_string(&texts).expect("strings serialize")
    };
    let text = |s: &str| serde_json::to_string(s).expect("strings serialize");
    let hold = env
        .hold
        .as_ref()
        .and_then(|h| h.to_str())
        .map_or("None".to_string(), text);
    format!(
        "import sys\n\
         if sys.path and sys.path[0] == '': del sys.path[0]\n\
         sys.path[:0] = {front}\n\
         sys.path += {after}\n\
         hold = {hold}\n\
         if hold is not None and sys.argv[1:2] == ['serve']:\n\
         \x20   import fcntl, json, os\n\
         \x20   try:\n\
         \x20       fd = os.open(hold, os.O_RDONLY)\n\
         \x20       fcntl.flock(fd, fcntl.LOCK_SH)\n\
         \x20       if not os.path.exists(hold): raise FileNotFoundError(2, 'removed', hold)\n\
         \x20   except OSError as e:\n\
         \x20       print(json.dumps({{'error': {gone} + ' (' + str(e) + ')'}}), flush=True)\n\
         \x20       sys.exit(0)\n\
         import runpy\n\
         runpy.run_module('envhub.worker', run_name='__main__', alter_sys=True)\n",
        front = list(&env.sys_path),
        after = list(after),
        hold = hold,
        gone = text(&removed_message(env)),
    )
}

/// What a session says when its environment was removed under it (`envhub env remove
/// --force`).
pub(crate) fn removed_message(env: &envhub_shm::WorkerPython) -> String {
    let dir = env
        .interpreter
        .parent()
        .and_then(|bin| bin.parent())
        .unwrap_or(&env.interpreter);
    format!(
        "python env `{0}` was removed while this session used it (`{1}` is gone)\nhint: `envhub env sync {0}` builds it again; then make the env again",
        env.name,
        dir.display()
    )
}

/// The Python-hosted adapters built into the `envhub` package (`envhub.worker.hosted.BUILTIN`) and
/// their frameworks, reported unavailable when the interpreter cannot describe them: a
/// suite whose worker cannot start then says why, not that its framework is unknown.
pub(crate) const BUILTIN: &[(&str, &[&str])] = &[
    ("gymnasium", &["gymnasium"]),
    ("maniskill", &["maniskill"]),
    ("libero", &["libero"]),
    ("isaac_lab", &["isaac_lab"]),
    ("metaworld", &["metaworld", "meta_world"]),
    ("robosuite", &["robosuite"]),
    ("dm_control", &["dm_control", "dmc", "shimmy"]),
    ("myosuite", &["myosuite"]),
    ("env_fns", &["env_fns"]),
];

/// A worker in a provisioned environment must speak this hub's protocol and run this
/// install's `envhub` package (the one its overlay leads to); anything else would be
/// another install's code behind this hub's shared memory.
pub(crate) fn check_identity(env: &WorkerPython, spec: &ReadySpec) -> Result<(), HubError> {
    let ours = WorkerIdentity::current(std::env::current_exe().unwrap_or_default());
    let refused = |message: String| HubError::PythonEnv {
        name: env.name.clone(),
        message: format!(
            "the worker in python env `{}` {message}\nhint: a `PYTHONPATH` its `env:` declares may lead to another envhub; else rebuild it (`envhub env remove {0}`, then `envhub env sync {0}`)",
            env.name
        ),
    };
    let Some(worker) = &spec.worker else {
        return Err(refused(format!(
            "reports no worker protocol: it runs an envhub older than this hub (protocol {}, envhub {})",
            ours.protocol, ours.version
        )));
    };
    if worker.protocol != ours.protocol {
        return Err(refused(format!(
            "speaks worker protocol {} (envhub {} at `{}`), this hub speaks {} (envhub {} at `{}`)",
            worker.protocol,
            worker.version,
            worker.module.display(),
            ours.protocol,
            ours.version,
            env.package.as_ref().unwrap_or(&ours.module).display()
        )));
    }
    let same = |a: &std::path::Path, b: &std::path::Path| {
        a == b
            || a.canonicalize()
                .ok()
                .is_some_and(|a| b.canonicalize().ok() == Some(a))
    };
    match &env.package {
        Some(package) if !same(package, &worker.module) => Err(refused(format!(
            "runs envhub from `{}`, not this hub's `{}`",
            worker.module.display(),
            package.display()
        ))),
        _ => Ok(()),
    }
}

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

    #[test]
    fn a_provisioned_worker_gets_its_environments_variables_and_none_of_the_hubs() {
        let env = envhub_shm::WorkerPython {
            name: "suite".into(),
            interpreter: "/cache/suite-0123/bin/python".into(),
            env: [("MUJOCO_GL".to_string(), "egl".to_string())].into(),
            sys_path: vec!["/cache/.installs/00aa".into()],
            package: None,
            hold: Some("/cache/suite-0123/envhub-env.json".into()),
        };
        let cmd = worker_command_in(Some(&env), &UserAdapters::default());
        let var = |name: &str| {
            cmd.get_envs()
                .find(|(k, _)| *k == OsStr::new(name))
                .map(|(_, v)| v.map(|v| v.to_string_lossy().into_owned()))
        };
        for removed in ["PYTHONPATH", "PYTHONHOME", "PYTHONUSERBASE"] {
            assert_eq!(var(removed), Some(None), "{removed}");
        }
        assert_eq!(var("VIRTUAL_ENV"), Some(Some("/cache/suite-0123".into())));
        assert!(
            var("PATH")
                .unwrap()
                .unwrap()
                .starts_with("/cache/suite-0123/bin:")
        );
        assert_eq!(var("MUJOCO_GL"), Some(Some("egl".into())));
        // `-c` with a program that drops the current folder, not `-m`.
        let args: Vec<String> = cmd
            .get_args()
            .map(|a| a.to_string_lossy().into_owned())
            .collect();
        assert_eq!(args[0], "-c", "{args:?}");
        assert!(args[1].contains(r#"sys.path[:0] = ["/cache/.installs/00aa"]"#));
        assert!(
            args[1].contains("del sys.path[0]") && args[1].contains("envhub.worker"),
            "{}",
            args[1]
        );
    }
}
