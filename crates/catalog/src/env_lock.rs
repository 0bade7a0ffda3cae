//! Lock files: what each Python environment of a registry file resolved to, per platform.
//!
//! `envhub env lock` writes one beside the registry file that declares the environments
//! (`env_registry.yaml` → `env_registry.lock.yaml`); sync and sessions install exactly its
//! pins for this platform. It is YAML, one pin per line, sorted, so a relock's diff shows
//! what moved:
//!
//! ```yaml
//! version: 1
//! python_envs:
//!   metaworld:
//!     declaration: "e78dee4ddec9768f"   # hash of the declaration it was resolved from
//!     python: "3.11"
//!     platforms:
//!       x86_64-unknown-linux-gnu:
//!         - "absl-py==2.5.1"
//! ```

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The format version this envhub writes and reads.
pub const LOCK_VERSION: u32 = 1;

/// A lock file: the locked environments of one registry file, by name.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LockFile {
    /// [`LOCK_VERSION`].
    pub version: u32,
    /// Each locked environment.
    #[serde(default)]
    pub python_envs: BTreeMap<String, EnvLock>,
}

/// One environment's lock.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EnvLock {
    /// `PythonEnvSpec::declaration_hash` of the
    /// declaration it was resolved from: a registry edit without relocking shows as a
    /// mismatch.
    pub declaration: String,
    /// The Python version it was resolved for (major.minor).
    pub python: String,
    /// Platform (uv's target triple, `x86_64-unknown-linux-gnu`) → every package installed
    /// there, `name==version`, sorted (the worker's own needs and `no_deps` ones included).
    pub platforms: BTreeMap<String, Vec<String>>,
}

/// How a declared environment stands against its registry file's lock.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum Locking {
    /// Its registry file has no lock file: resolved when built, as requirements say.
    #[default]
    Unlocked,
    /// The lock file has this environment.
    Locked {
        /// The lock file (for messages).
        file: String,
        /// Its entry.
        lock: EnvLock,
    },
    /// The lock file exists but does not have this environment (added without relocking).
    Missing {
        /// The lock file.
        file: String,
    },
}

/// The lock file of the registry file `registry`: `<stem>.lock.yaml` beside it.
pub fn lock_path(registry: &Path) -> PathBuf {
    let stem = registry
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    registry.with_file_name(format!("{stem}.lock.yaml"))
}

impl LockFile {
    /// Parses a lock file's text; `Err` says what is wrong, with the line where known.
    pub fn parse(text: &str) -> Result<LockFile, String> {
        let file: LockFile = serde_norway::from_str(text).map_err(|e| e.to_string())?;
        if file.version != LOCK_VERSION {
            return Err(format!(
                "lock format version {} is not the one this envhub reads ({LOCK_VERSION}); relock with `envhub env lock`",
                file.version
            ));
        }
        Ok(file)
    }

    /// The file's text: stable order, one pin a line, strings quoted.
    pub fn render(&self, registry_name: &str) -> String {
        let q = |s: &str| serde_json::to_string(s).expect("a string serializes");
        let mut out = format!(
            "# Python environments of {registry_name}, resolved by `envhub env lock` (uv pip compile).\n\
             # `envhub env sync` and sessions install exactly these pins for their platform.\n\
             # Generated: after changing an environment there, run `envhub env lock NAME`.\n\
             version: {LOCK_VERSION}\npython_envs:\n"
        );
        if self.python_envs.is_empty() {
            out = out.replace("python_envs:\n", "python_envs: {}\n");
        }
        for (name, lock) in &self.python_envs {
            out.push_str(&format!("  {}:\n", q(name)));
            out.push_str(&format!("    declaration: {}\n", q(&lock.declaration)));
            out.push_str(&format!("    python: {}\n", q(&lock.python)));
            out.push_str("    platforms:\n");
            for (platform, pins) in &lock.platforms {
                out.push_str(&format!("      {}:\n", q(platform)));
                for pin in pins {
                    out.push_str(&format!("        - {}\n", q(pin)));
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> LockFile {
        let mut platforms = BTreeMap::new();
        platforms.insert(
            "x86_64-unknown-linux-gnu".to_string(),
            vec!["mujoco==3.3.0".to_string(), "torch==2.9.0+cpu".to_string()],
        );
        platforms.insert(
            "aarch64-unknown-linux-gnu".to_string(),
            vec!["mujoco==3.3.0".to_string()],
        );
        let mut file = LockFile {
            version: LOCK_VERSION,
            python_envs: BTreeMap::new(),
        };
        file.python_envs.insert(
            "meta.world-1".into(),
            EnvLock {
                declaration: "00ff00ff00ff00ff".into(),
                python: "3.11".into(),
                platforms,
            },
        );
        file
    }

    #[test]
    fn a_rendered_lock_parses_back_to_itself() {
        let file = sample();
        let text = file.render("suites.yaml");
        assert_eq!(LockFile::parse(&text).unwrap(), file);
        // One pin a line, platforms in a stable order: diffs show what moved.
        assert!(
            text.contains("\n        - \"torch==2.9.0+cpu\"\n"),
            "{text}"
        );
        assert!(
            text.find("aarch64").unwrap() < text.find("x86_64").unwrap(),
            "{text}"
        );
        let empty = LockFile {
            version: LOCK_VERSION,
            ..Default::default()
        };
        assert_eq!(LockFile::parse(&empty.render("x.yaml")).unwrap(), empty);
    }

    #[test]
    fn bad_lock_files_say_what_is_wrong() {
        let text = sample().render("s.yaml").replace("python:", "pyhton:");
        let err = LockFile::parse(&text).unwrap_err();
        assert!(err.contains("unknown field `pyhton`"), "{err}");
        let err = LockFile::parse("version: 7\npython_envs: {}\n").unwrap_err();
        assert!(err.contains("version 7"), "{err}");
        assert_eq!(
            lock_path(Path::new("/a/env_registry.yaml")),
            Path::new("/a/env_registry.lock.yaml")
        );
    }
}
