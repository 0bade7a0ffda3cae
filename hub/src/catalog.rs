//! The adapter catalog: which adapters exist, what they run, whether they can run here.
//!
//! The hub links no simulator, so it asks the worker binary (`envhub-worker describe`) once
//! per process and keeps the answer.

use crate::error::HubError;
use crate::worker_binary::worker_binary;
use envhub_core::Availability;
use serde::{Deserialize, Serialize};
use std::sync::OnceLock;

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
}

static CATALOG: OnceLock<Result<Vec<AdapterInfo>, String>> = OnceLock::new();

/// Every adapter, asked of the worker binary once per process.
pub fn adapters() -> Result<&'static [AdapterInfo], HubError> {
    let cached = CATALOG.get_or_init(|| {
        let path = worker_binary();
        let out = std::process::Command::new(&path)
            .arg("describe")
            .output()
            .map_err(|e| format!("{}\u{0}{e}", path.display()))?;
        if !out.status.success() {
            // Typically the loader failing on a missing library: say which.
            let stderr = String::from_utf8_lossy(&out.stderr);
            let last = stderr
                .lines()
                .rev()
                .find(|l| !l.trim().is_empty())
                .unwrap_or("");
            return Err(format!(
                "{}\u{0}`describe` exited with {}: {last}",
                path.display(),
                out.status
            ));
        }
        serde_json::from_slice(&out.stdout)
            .map_err(|e| format!("{}\u{0}unreadable `describe` output: {e}", path.display()))
    });
    match cached {
        Ok(list) => Ok(list),
        Err(e) => {
            let (path, reason) = e.split_once('\u{0}').unwrap_or(("envhub-worker", e));
            Err(HubError::WorkerBinary {
                path: path.to_string(),
                reason: reason.to_string(),
            })
        }
    }
}
