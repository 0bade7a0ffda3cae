//! What a Python environment is made of, and the key that names its venv.

use crate::env_lock::Locking;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// A Python environment as a registry file declares it (`python_envs:`).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PythonEnvSpec {
    /// The CPython version to base it on (`3.10`, `3.10.13`), an interpreter present on the
    /// machine; `None`: the hub's interpreter's version.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub python: Option<String>,
    /// Requirements as pip and uv read them (`metaworld==3.1.1`).
    pub requirements: Vec<String>,
    /// Packages installed after `requirements` without their declared dependencies (a suite
    /// whose metadata pulls a training stack or an sdist that cannot build, as hf-libero's
    /// does); part of the key like `requirements`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub no_deps: Vec<String>,
    /// Variables the workers of this environment run with (`MUJOCO_GL: egl`); not part of
    /// the key: they change how it runs, not what is installed.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub env: BTreeMap<String, String>,
    /// The package index uv installs from instead of its default (`--index-url`); part of
    /// the key and of the lock's declaration.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub index_url: Option<String>,
    /// Further indexes uv looks in (`--extra-index-url`, in order).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub extra_index_urls: Vec<String>,
    /// uv's PyTorch backend (`--torch-backend`: `cpu`, `cu128`, `auto`): which index torch
    /// and its kin come from.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub torch_backend: Option<String>,
    /// How it stands against its registry file's lock file (set when the registry loads).
    #[serde(skip)]
    pub lock: Locking,
}

/// Version of the key's recipe: bumped when what goes into a venv changes for the same spec.
const KEY_RECIPE: &str = "envhub-pyenv 2";
/// Version of the declaration hash a lock records.
const DECLARATION_RECIPE: &str = "envhub-lock 1";

impl PythonEnvSpec {
    /// Checks what a registry file can get wrong, as a message naming the faulty value.
    pub fn validate(&self) -> Result<(), String> {
        if self.requirements.is_empty() {
            return Err(
                "`requirements` is empty; list at least one package (`gymnasium==1.2.0`)".into(),
            );
        }
        for req in self.requirements.iter().chain(&self.no_deps) {
            let name = package_name(req);
            if name.is_empty() || req.trim_start().starts_with('-') {
                return Err(format!(
                    "`{req}` is not a requirement; write one package per item (`mujoco==3.3.0`), without pip options"
                ));
            }
        }
        if let Some(python) = &self.python
            && parse_version(python).is_none()
        {
            return Err(format!(
                "`python: {python}` is not a CPython version; write `3.10` or `3.10.13`"
            ));
        }
        for url in self.index_url.iter().chain(&self.extra_index_urls) {
            if !url.contains("://") || url.trim() != url || url.is_empty() {
                return Err(format!(
                    "`{url}` is not an index URL; write one such as `https://download.pytorch.org/whl/cpu`"
                ));
            }
        }
        if let Some(backend) = &self.torch_backend
            && (backend.is_empty()
                || !backend
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '.' || c == '-'))
        {
            return Err(format!(
                "`torch_backend: {backend}` is not a uv torch backend; write one such as `cpu`, `cu128` or `auto`"
            ));
        }
        for name in self.env.keys() {
            if name.is_empty() || name.contains(['=', '\0']) {
                return Err(format!("`env` has an invalid variable name `{name}`"));
            }
        }
        Ok(())
    }

    /// The requirements plus `extra` ones whose package the spec does not name itself (a
    /// suite's own pin of `gymnasium` wins over the worker's unpinned need of it), trimmed,
    /// sorted and without duplicates: what is installed and what the key hashes.
    pub fn full_requirements(&self, extra: &[String]) -> Vec<String> {
        let named: Vec<String> = self.requirements.iter().map(|r| package_name(r)).collect();
        normalized(
            self.requirements
                .iter()
                .chain(extra.iter().filter(|e| !named.contains(&package_name(e)))),
        )
    }

    /// The packages to install without their dependencies, trimmed, sorted, deduplicated.
    pub fn no_deps_sorted(&self) -> Vec<String> {
        normalized(self.no_deps.iter())
    }

    /// What uv is told besides the requirements: the index options and torch backend, as
    /// its command-line arguments.
    pub fn uv_args(&self) -> Vec<String> {
        let mut args = Vec::new();
        if let Some(url) = &self.index_url {
            args.extend(["--index-url".to_string(), url.clone()]);
        }
        for url in &self.extra_index_urls {
            args.extend(["--extra-index-url".to_string(), url.clone()]);
        }
        if let Some(backend) = &self.torch_backend {
            args.extend(["--torch-backend".to_string(), backend.clone()]);
        }
        args
    }

    /// The text both hashes start from: the full requirements, the `no_deps` packages and
    /// the uv options (absent ones add nothing).
    fn declared(&self, extra: &[String]) -> String {
        let mut text = String::new();
        for req in self.full_requirements(extra) {
            text.push_str(&req);
            text.push('\n');
        }
        for req in self.no_deps_sorted() {
            text.push_str("no-deps ");
            text.push_str(&req);
            text.push('\n');
        }
        for arg in self.uv_args() {
            text.push_str(&arg);
            text.push('\n');
        }
        text
    }

    /// The hash a lock records of the declaration it was resolved from (16 hex digits): the
    /// Python version as written, [`full_requirements`], `no_deps` and the uv options; not
    /// `env` (how it runs, not what is installed).
    ///
    /// [`full_requirements`]: PythonEnvSpec::full_requirements
    pub fn declaration_hash(&self, extra: &[String]) -> String {
        let text = format!(
            "{DECLARATION_RECIPE}\npython {}\n{}",
            self.python.as_deref().unwrap_or("").trim(),
            self.declared(extra)
        );
        format!("{:016x}", fnv1a64(text.as_bytes()))
    }

    /// The stable key of this environment built on Python `python_version` (major.minor or
    /// full): 16 hex digits of a hash of the version, [`full_requirements`], `no_deps`, the
    /// uv options and `context` — what else decides what gets installed (the platform, uv's
    /// configuration, the locked pins). Equal sets in another order give the same key; any
    /// change of a pin gives another.
    ///
    /// [`full_requirements`]: PythonEnvSpec::full_requirements
    pub fn key(&self, python_version: &str, extra: &[String], context: &str) -> String {
        let text = format!(
            "{KEY_RECIPE}\npython {python_version}\n{}{context}",
            self.declared(extra)
        );
        format!("{:016x}", fnv1a64(text.as_bytes()))
    }
}

/// Requirements trimmed, without empty ones, sorted and deduplicated (the order a registry
/// file lists them in changes nothing).
fn normalized<'a>(requirements: impl Iterator<Item = &'a String>) -> Vec<String> {
    let mut all: Vec<String> = requirements
        .map(|r| r.trim().to_string())
        .filter(|r| !r.is_empty())
        .collect();
    all.sort();
    all.dedup();
    all
}

/// FNV-1a, 64 bits: tiny, and fixed by its definition (std's hashers may change between Rust
/// releases, which would rename every venv). Not a defence against crafted collisions; the
/// venv's manifest records its full requirement list, which readiness checks.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut hash: u64 = 0xcbf2_9ce4_8422_2325;
    for b in bytes {
        hash ^= u64::from(*b);
        hash = hash.wrapping_mul(0x0000_0100_0000_01b3);
    }
    hash
}

/// The normalized package name a requirement names (`Gymnasium[mujoco]>=1.1` → `gymnasium`;
/// PEP 503: lowercase, runs of `-`, `_`, `.` as one `-`).
pub fn package_name(requirement: &str) -> String {
    let name: String = requirement
        .trim()
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
        .collect();
    let mut out = String::new();
    for c in name.chars() {
        if matches!(c, '-' | '_' | '.') {
            if !out.ends_with('-') {
                out.push('-');
            }
        } else {
            out.push(c.to_ascii_lowercase());
        }
    }
    out
}

/// `(major, minor, patch)` of a version written `3.10` or `3.10.13`.
pub fn parse_version(text: &str) -> Option<(u32, u32, Option<u32>)> {
    let mut parts = text.trim().split('.');
    let major = parts.next()?.parse().ok()?;
    let minor = parts.next()?.parse().ok()?;
    let patch = match parts.next() {
        Some(p) => Some(p.parse().ok()?),
        None => None,
    };
    (parts.next().is_none() && major == 3).then_some((major, minor, patch))
}

/// Whether a name can name an environment (and its folder): letters, digits, `-`, `_`, `.`,
/// not starting with `.`.
pub fn valid_name(name: &str) -> bool {
    !name.is_empty()
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.'))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(reqs: &[&str]) -> PythonEnvSpec {
        PythonEnvSpec {
            requirements: reqs.iter().map(|s| s.to_string()).collect(),
            ..Default::default()
        }
    }

    #[test]
    fn no_deps_packages_change_the_key_and_are_checked() {
        let plain = spec(&["robosuite==1.4.0"]);
        let mut with = plain.clone();
        with.no_deps = vec!["hf-libero==0.1.4".into()];
        assert_ne!(plain.key("3.11", &[], ""), with.key("3.11", &[], ""));
        with.no_deps.push("--index-url x".into());
        assert!(with.validate().unwrap_err().contains("--index-url x"));
    }

    #[test]
    fn the_key_is_stable_across_releases_and_orders() {
        let extra = vec!["numpy".to_string()];
        let a = spec(&["gymnasium==1.2.0", "mujoco==3.3.0"]);
        let b = spec(&["mujoco==3.3.0 ", "gymnasium==1.2.0", "mujoco==3.3.0"]);
        // Fixed: a change here renames every user's venvs (bump KEY_RECIPE on purpose).
        assert_eq!(a.key("3.11", &extra, ""), "7fe40b9a57f71698");
        assert_eq!(a.key("3.11", &extra, ""), b.key("3.11", &extra, ""));
        assert_ne!(a.key("3.11", &extra, ""), a.key("3.10", &extra, ""));
        assert_ne!(
            a.key("3.11", &extra, ""),
            spec(&["gymnasium==1.2.1", "mujoco==3.3.0"]).key("3.11", &extra, "")
        );
        assert_ne!(a.key("3.11", &extra, ""), a.key("3.11", &[], ""));
        // Variables do not change what is installed.
        let mut with_env = a.clone();
        with_env.env.insert("MUJOCO_GL".into(), "egl".into());
        assert_eq!(a.key("3.11", &extra, ""), with_env.key("3.11", &extra, ""));
    }

    #[test]
    fn the_key_covers_the_context_and_the_uv_options() {
        let a = spec(&["mujoco==3.3.0"]);
        let key = a.key("3.11", &[], "platform x86_64-unknown-linux-gnu\n");
        assert_ne!(
            key,
            a.key("3.11", &[], "platform aarch64-unknown-linux-gnu\n")
        );
        let mut cpu = a.clone();
        cpu.torch_backend = Some("cpu".into());
        let mut indexed = a.clone();
        indexed.extra_index_urls = vec!["https://example.org/simple".into()];
        let keys = [&a, &cpu, &indexed].map(|s| s.key("3.11", &[], ""));
        assert!(keys[0] != keys[1] && keys[1] != keys[2] && keys[0] != keys[2]);
        assert_eq!(
            cpu.uv_args(),
            ["--torch-backend", "cpu"].map(String::from).to_vec()
        );
        // The lock's declaration hash: the declaration as written, not how it runs.
        let mut with_env = a.clone();
        with_env.env.insert("MUJOCO_GL".into(), "egl".into());
        assert_eq!(a.declaration_hash(&[]), with_env.declaration_hash(&[]));
        assert_ne!(a.declaration_hash(&[]), cpu.declaration_hash(&[]));
        assert_ne!(
            a.declaration_hash(&[]),
            a.declaration_hash(&["numpy".to_string()])
        );
        let mut pinned_python = a.clone();
        pinned_python.python = Some("3.12".into());
        assert_ne!(a.declaration_hash(&[]), pinned_python.declaration_hash(&[]));
        cpu.torch_backend = Some("CUDA 12".into());
        assert!(cpu.validate().unwrap_err().contains("torch_backend"));
        indexed.index_url = Some("pypi.org/simple".into());
        assert!(
            indexed
                .validate()
                .unwrap_err()
                .contains("`pypi.org/simple`")
        );
    }

    #[test]
    fn a_suites_own_pin_wins_over_the_workers_needs() {
        let extra = vec!["numpy".to_string(), "gymnasium".to_string()];
        let s = spec(&["Gymnasium[mujoco]==1.2.0", "metaworld"]);
        assert_eq!(
            s.full_requirements(&extra),
            ["Gymnasium[mujoco]==1.2.0", "metaworld", "numpy"]
        );
    }

    #[test]
    fn package_names_are_normalized() {
        assert_eq!(package_name("Gymnasium[mujoco]>=1.1"), "gymnasium");
        assert_eq!(package_name("hf_libero==0.1.4"), "hf-libero");
        assert_eq!(
            package_name("zope.interface ; python_version<'4'"),
            "zope-interface"
        );
        assert_eq!(package_name("==1"), "");
    }

    #[test]
    fn bad_specs_name_the_faulty_value() {
        assert!(spec(&[]).validate().unwrap_err().contains("empty"));
        assert!(
            spec(&["--index-url x"])
                .validate()
                .unwrap_err()
                .contains("`--index-url x`")
        );
        let mut s = spec(&["numpy"]);
        s.python = Some("three".into());
        assert!(s.validate().unwrap_err().contains("`python: three`"));
        s.python = Some("3.10".into());
        assert_eq!(s.validate(), Ok(()));
        assert_eq!(parse_version("3.10.13"), Some((3, 10, Some(13))));
        assert!(valid_name("meta-world_3.x") && !valid_name(".hidden") && !valid_name("a/b"));
    }
}
