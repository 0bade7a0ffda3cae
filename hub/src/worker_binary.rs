//! Finding the `envhub-worker` binary.

use crate::env_vars::ENVHUB_WORKER;
use std::path::PathBuf;

const NAME: &str = "envhub-worker";

/// `ENVHUB_WORKER`, else next to the running binary (or one folder up, for test binaries in
/// `target/*/deps`), else on `PATH`. Returns the first candidate even if missing, so the
/// error can name it.
pub fn worker_binary() -> PathBuf {
    if let Some(p) = std::env::var_os(ENVHUB_WORKER).filter(|p| !p.is_empty()) {
        return PathBuf::from(p);
    }
    let mut candidates = Vec::new();
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
