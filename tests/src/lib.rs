//! Helpers for envhub's end-to-end tests: an isolated hub per test and the built binaries.

use envhub::{Hub, Registry, SessionOptions};
use std::path::PathBuf;
use std::time::Duration;

/// The folder holding the workspace's built binaries (`target/<profile>`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test binary path");
    let deps = exe.parent().expect("deps folder");
    deps.parent().expect("profile folder").to_path_buf()
}

/// Path of a workspace binary; panics with the fix if it was not built.
pub fn binary(name: &str) -> PathBuf {
    let path = bin_dir().join(name);
    assert!(
        path.is_file(),
        "{} is missing: run `cargo build --workspace --bins` first (`make test` does)",
        path.display()
    );
    path
}

/// A hub in its own iceoryx2 namespace, so tests can run in parallel. Removes what the
/// namespace left in shared memory when dropped.
pub struct TestHub {
    /// The hub.
    pub hub: Hub,
    /// Its iceoryx2 namespace.
    pub namespace: String,
}

impl TestHub {
    /// A hub over the built-in registry with a short step timeout.
    pub fn new(name: &str) -> TestHub {
        Self::with(name, |_| {})
    }

    /// A hub whose session options `tweak` adjusts.
    pub fn with(name: &str, tweak: impl FnOnce(&mut SessionOptions)) -> TestHub {
        // The hub finds the worker next to the test binary's folder; fail early and clearly
        // if it was not built.
        binary("envhub-worker");
        let namespace = format!("e2e_{name}_{}_", std::process::id());
        let mut options = SessionOptions {
            namespace: namespace.clone(),
            step_timeout: Duration::from_secs(10),
            start_timeout: Duration::from_secs(20),
            ..SessionOptions::default()
        };
        tweak(&mut options);
        TestHub {
            hub: Hub::new(Registry::builtin()).with_options(options),
            namespace,
        }
    }
}

impl Drop for TestHub {
    fn drop(&mut self) {
        let _ = envhub_shm::remove_namespace(&self.namespace);
    }
}

/// Files in `/dev/shm` whose names contain `needle`.
pub fn shm_files(needle: &str) -> Vec<String> {
    std::fs::read_dir("/dev/shm")
        .map(|d| {
            d.filter_map(Result::ok)
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.contains(needle))
                .collect()
        })
        .unwrap_or_default()
}
