//! Finding the `envhub-worker` binary.

use crate::env_vars::ENVHUB_WORKER;
use std::path::PathBuf;
use std::sync::OnceLock;

const NAME: &str = "envhub-worker";

/// A location an embedding program knows better than the executable's folder (the Python
/// module's interpreter lives elsewhere; the worker is installed beside the module).
static DEFAULT: OnceLock<PathBuf> = OnceLock::new();

/// Sets where to look for the worker before the running executable's folder and `PATH`
/// (`ENVHUB_WORKER` still wins). For programs that embed the hub, such as the Python module.
/// The first call wins; returns whether this one did.
pub fn set_default_worker_binary(path: PathBuf) -> bool {
    DEFAULT.set(path).is_ok()
}

/// `ENVHUB_WORKER`, else the default set with [`set_default_worker_binary`] if that file
/// exists, else next to the running binary (or one folder up, for test binaries in
/// `target/*/deps`), else on `PATH`. Returns the first candidate even if missing, so the
/// error can name it.
pub fn worker_binary() -> PathBuf {
    if let Some(p) = std::env::var_os(ENVHUB_WORKER).filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    let mut candidates: Vec<PathBuf> = DEFAULT.get().cloned().into_iter().collect();
    if let Ok(exe) = std::env::current_exe()
        && let Some(dir) = exe.parent()
    {
        candidates.push(dir.join(NAME));
        if let Some(up) = dir.parent() {
            candidates.push(up.join(NAME));
        }
    }
    if let Some(path) = std::env::var_os("PATH") {
        candidates.extend(std::env::split_paths(&path).map(|d| d.join(NAME)));
    }
    candidates
        .iter()
        .find(|c| c.is_file())
        .cloned()
        .or_else(|| candidates.first().cloned())
        .unwrap_or_else(|| PathBuf::from(NAME))
}
