//! Why a Python environment could not be provided.

use std::path::PathBuf;

/// An error building, finding or removing a Python environment. Every variant names the
/// environment; install errors carry uv's own message.
#[derive(Debug, thiserror::Error)]
pub enum PyEnvError {
    /// No `uv` executable was found.
    #[error(
        "cannot build python env `{name}`: no `uv` found (looked at {searched})\nhint: `pip install uv` into the hub's interpreter (`make venv` does), or set ENVHUB_UV to its path"
    )]
    UvNotFound {
        /// The environment.
        name: String,
        /// Where it was looked for.
        searched: String,
    },
    /// The requested CPython version is not installed on this machine.
    #[error(
        "python env `{name}` wants CPython {requested} (the default build: not free-threaded, not PyPy), which is not on this machine (present: {present}){tried}\nhint: `uv python install {requested}` installs it (or let envhub ask uv to: `python_install: true` in envhub.yaml, or ENVHUB_PYTHON_INSTALL=1), or change `python:` to a present version"
    )]
    PythonNotFound {
        /// The environment.
        name: String,
        /// The version asked for.
        requested: String,
        /// The versions found, with their paths.
        present: String,
        /// What asking uv to install it said (empty: it was not asked).
        tried: String,
    },
    /// The spec is not valid.
    #[error("python env `{name}`: {message}")]
    InvalidSpec {
        /// The environment.
        name: String,
        /// What is wrong.
        message: String,
    },
    /// Its lock does not fit: made from another declaration, for other platforms, or
    /// missing from its registry file's lock file.
    #[error("python env `{name}`: {message}")]
    Lock {
        /// The environment.
        name: String,
        /// What does not fit, with the fix.
        message: String,
    },
    /// `uv venv` or `uv pip install` failed.
    #[error(
        "python env `{name}`: {stage} failed for {packages}:\n{message}\nhint: fix the requirement in the registry's `python_envs:` (`envhub env list` shows them); other envs are unaffected"
    )]
    Install {
        /// The environment.
        name: String,
        /// `uv pip install`, `uv venv`.
        stage: String,
        /// The packages uv's message names (`` `nonexistent-pkg` ``), or every requirement
        /// when it names none of them.
        packages: String,
        /// uv's own message.
        message: String,
    },
    /// Another process held the build lock past the wait limit.
    #[error(
        "python env `{name}`: another process ({holder}) is still building it after {waited_s} s\nhint: wait for it (`envhub env list` shows it as not ready), or raise ENVHUB_PYENV_WAIT; if that process is gone, the lock frees itself"
    )]
    LockTimeout {
        /// The environment.
        name: String,
        /// `pid 1234`, as far as known.
        holder: String,
        /// Seconds waited.
        waited_s: u64,
    },
    /// A file operation failed.
    #[error("python env `{name}`: cannot {what} `{}`: {source}", path.display())]
    Io {
        /// The environment.
        name: String,
        /// What was being done (`create`, `remove`).
        what: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The OS error.
        #[source]
        source: std::io::Error,
    },
    /// Running workers hold the environment.
    #[error(
        "python env `{name}` is in use by running sessions' workers ({pids}): `{}`\nhint: close those sessions first, or add `--force` (their workers then fail, saying it was removed)", dir.display()
    )]
    InUse {
        /// The environment.
        name: String,
        /// Its folder.
        dir: PathBuf,
        /// `pid 1234, 1240`.
        pids: String,
    },
    /// No stored environment has this name.
    #[error("no python env `{name}` in `{}`{}\nhint: `envhub env list` shows them", root.display(), known_list(.known))]
    NotStored {
        /// The name asked for.
        name: String,
        /// The cache folder.
        root: PathBuf,
        /// What is stored.
        known: Vec<String>,
    },
}

fn known_list(known: &[String]) -> String {
    if known.is_empty() {
        " (none is stored)".into()
    } else {
        format!(" (stored: {})", known.join(", "))
    }
}

pub(crate) fn io(
    name: &str,
    what: &'static str,
    path: &std::path::Path,
) -> impl FnOnce(std::io::Error) -> PyEnvError {
    let (name, path) = (name.to_string(), path.to_path_buf());
    move |source| PyEnvError::Io {
        name,
        what,
        path,
        source,
    }
}
