//! Adapters hosted by a worker binary of their own, installed beside this one. This binary
//! lists them from constants (it links none of their simulator) and hands a job for one of
//! them over to that binary (`exec`, same pid, same arguments).
//!
//! Why: rapier3d and its geometry crates are about a tenth of the release build, and the
//! binaries `make demo` runs need none of them, so they build after the demo (in `make test`,
//! `make wheel` or `make build-all`). The constants are checked against the real adapter
//! (`tests/e2e/worker_binaries.rs`).

use envhub_core::{Availability, Env, EnvAdapter, EnvConfig, EnvError, EnvSpec};
use std::os::unix::process::CommandExt;
use std::path::PathBuf;

/// What a worker lists of an adapter another binary hosts.
#[derive(Debug)]
pub struct DelegatedInfo {
    /// The adapter's name.
    pub name: &'static str,
    /// The binary that hosts it, beside this one.
    pub binary: &'static str,
    /// As [`EnvAdapter::frameworks`].
    pub frameworks: &'static [&'static str],
    /// As [`EnvAdapter::description`].
    pub description: &'static str,
    /// As [`EnvAdapter::render_modes`].
    pub render_modes: &'static [&'static str],
    /// As [`EnvAdapter::list_envs`].
    pub env_ids: &'static [&'static str],
}

/// `envhub-rapier`'s adapter, in `envhub-worker-rapier`.
pub const RAPIER: DelegatedInfo = DelegatedInfo {
    name: "rapier",
    binary: "envhub-worker-rapier",
    frameworks: &["rapier"],
    description: "robot tasks on rapier3d 0.36 (arm reach and push, quadruped, wheeled base on terrain), native Rust",
    render_modes: &["rgb_array"],
    env_ids: &["ArmReach-v0", "ArmPush-v0", "AntRun-v0", "RoverTerrain-v0"],
};

/// Every adapter another binary hosts.
pub const ALL: &[&DelegatedInfo] = &[&RAPIER];

/// The binary beside this one that hosts `info`'s adapter.
fn binary_path(info: &DelegatedInfo) -> PathBuf {
    std::env::current_exe()
        .unwrap_or_default()
        .with_file_name(info.binary)
}

/// An adapter of [`ALL`] as this binary lists it.
pub struct Delegated(pub &'static DelegatedInfo);

impl Delegated {
    fn missing(&self) -> Option<(String, String)> {
        let path = binary_path(self.0);
        (!path.is_file()).then(|| {
            (
                format!(
                    "no `{}` at `{}`: the `{}` adapter runs in that binary, which was not built or installed",
                    self.0.binary,
                    path.display(),
                    self.0.name
                ),
                format!(
                    "run `make build-all` (or `cargo build --release -p {0}`), or install with \
                     `cargo install --path crates/hub --features worker`; `{0}` must sit beside `envhub-worker`",
                    self.0.binary
                ),
            )
        })
    }

    fn refuse(&self, env_id: &str) -> EnvError {
        if !self.supports(env_id) {
            return self.unknown_env(env_id);
        }
        let (reason, hint) = self.missing().unwrap_or_else(|| {
            (
                format!("`{}` hosts this adapter", self.0.binary),
                "start it through `envhub-worker`, which hands the job over".into(),
            )
        });
        EnvError::Unavailable {
            adapter: self.0.name.into(),
            reason,
            hint,
        }
    }
}

impl EnvAdapter for Delegated {
    fn name(&self) -> &'static str {
        self.0.name
    }

    fn frameworks(&self) -> &'static [&'static str] {
        self.0.frameworks
    }

    fn requires(&self) -> &'static [&'static str] {
        &[]
    }

    fn description(&self) -> &'static str {
        self.0.description
    }

    fn availability(&self) -> Availability {
        match self.missing() {
            None => Availability::Available,
            Some((reason, hint)) => Availability::Unavailable { reason, hint },
        }
    }

    fn render_modes(&self) -> &'static [&'static str] {
        self.0.render_modes
    }

    fn list_envs(&self) -> Vec<String> {
        self.0.env_ids.iter().map(|id| id.to_string()).collect()
    }

    fn spec(&self, env_id: &str, _config: &EnvConfig) -> Result<EnvSpec, EnvError> {
        Err(self.refuse(env_id))
    }

    fn make(&self, env_id: &str, _config: &EnvConfig) -> Result<Box<dyn Env>, EnvError> {
        Err(self.refuse(env_id))
    }
}

/// Replaces this process with the binary that hosts `adapter`, when another one does and it
/// is installed; returns when this binary should go on with the job itself (it hosts the
/// adapter, no binary does, or the binary is missing: the job then fails with
/// [`Delegated`]'s reason), or with the error of an `exec` that failed.
pub fn hand_over(adapter: &str, hosted_here: bool) -> Result<(), String> {
    let Some(info) = ALL.iter().find(|info| info.name == adapter) else {
        return Ok(());
    };
    let path = binary_path(info);
    if hosted_here || !path.is_file() {
        return Ok(());
    }
    let err = std::process::Command::new(&path)
        .args(std::env::args_os().skip(1))
        .exec();
    Err(format!(
        "cannot start `{}`: {err}\nhint: it must be an executable beside `envhub-worker`: rebuild it (`make build-all`) or reinstall envhub",
        path.display()
    ))
}
