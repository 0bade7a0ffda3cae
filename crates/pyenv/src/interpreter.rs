//! The CPython interpreters present on this machine, to base environments on.
//!
//! Installed ones count: those uv finds (on `PATH`, its own installs) and pyenv's (`pyenv
//! versions`), whose shims uv cannot use for versions other than the selected one. Only
//! CPython with the GIL (the default build) qualifies: envhub's compiled module is built for
//! CPython's stable ABI, which neither PyPy nor a free-threaded build (`python3.13t`) loads.
//! Each candidate is asked what it is before it is used, whatever its name or uv says.
//! Downloading a missing version is left to uv (`uv python install`), on the user's request.

use envhub_catalog::parse_version;
use std::path::{Path, PathBuf};
use std::process::Command;

/// One interpreter found: its full version and path.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Interpreter {
    /// `3.10.13`.
    pub version: String,
    /// Its executable.
    pub path: PathBuf,
}

/// The full version (`3.11.7`) of the interpreter `python`, asked of it.
pub fn version_of(python: &Path) -> Option<String> {
    let out = Command::new(python)
        .args([
            "-I",
            "-c",
            "import sys; print('%d.%d.%d' % sys.version_info[:3])",
        ])
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
        .filter(|v| parse_version(v).is_some())
}

/// Whether `python` is a CPython of the default (GIL) build at `version`, asked of it.
pub(crate) fn qualifies(python: &Path, version: &str) -> bool {
    #[derive(serde::Deserialize)]
    struct Probe {
        implementation: String,
        version: String,
        gil_disabled: bool,
    }
    let out = Command::new(python)
        .args([
            "-I",
            "-c",
            "import json, sys, sysconfig; print(json.dumps({'implementation': sys.implementation.name, \
             'version': '%d.%d.%d' % sys.version_info[:3], \
             'gil_disabled': bool(sysconfig.get_config_var('Py_GIL_DISABLED'))}))",
        ])
        .output();
    let Ok(out) = out else { return false };
    let probe = serde_json::from_slice::<Probe>(&out.stdout);
    let ok = out.status.success()
        && probe.as_ref().is_ok_and(|p| {
            p.implementation == "cpython" && !p.gil_disabled && p.version == version
        });
    if !ok {
        tracing::debug!(python = %python.display(), "not a CPython {version} of the default build: {}", String::from_utf8_lossy(&out.stdout).trim());
    }
    ok
}

/// Asks uv to install CPython `requested` (a download), then where it is. `Err`: uv's message.
pub(crate) fn install_with_uv(uv: &Path, requested: &str) -> Result<PathBuf, String> {
    let mut install = Command::new(uv);
    install
        .args(["python", "install", requested])
        .env("UV_PYTHON_DOWNLOADS", "automatic");
    crate::uv::run(install, std::time::Duration::from_secs(10), |elapsed| {
        eprintln!(
            "envhub: uv is installing CPython {requested} ({} s)",
            elapsed.as_secs()
        )
    })
    .map_err(|crate::uv::Failed(m)| m)?;
    let mut find = Command::new(uv);
    find.args(["python", "find", "--managed-python", requested]);
    let out = crate::uv::run(find, std::time::Duration::from_secs(10), |_| {})
        .map_err(|crate::uv::Failed(m)| m)?;
    Ok(PathBuf::from(out.trim()))
}

/// `lists` merged: one interpreter per version (the first list's wins), newest first.
pub(crate) fn merged(lists: &[&[Interpreter]]) -> Vec<Interpreter> {
    let mut found: Vec<Interpreter> = Vec::new();
    for list in lists {
        for i in list.iter() {
            if !found.iter().any(|f| f.version == i.version) {
                found.push(i.clone());
            }
        }
    }
    found.sort_by_key(|i| std::cmp::Reverse(parse_version(&i.version)));
    found
}

/// The interpreters uv finds (`PATH`, its own installs); it queries every candidate, which
/// takes a second or two with pyenv's shims on `PATH`, so it is asked only when pyenv's
/// list lacks the version.
pub(crate) fn from_uv(uv: &Path) -> Vec<Interpreter> {
    #[derive(serde::Deserialize)]
    struct Listed {
        version: String,
        path: Option<PathBuf>,
        #[serde(default)]
        implementation: Option<String>,
        #[serde(default)]
        variant: Option<String>,
    }
    let out = Command::new(uv)
        .args([
            "python",
            "list",
            "--only-installed",
            "--no-python-downloads",
            "--output-format",
            "json",
        ])
        .output();
    let Ok(out) = out else { return Vec::new() };
    serde_json::from_slice::<Vec<Listed>>(&out.stdout)
        .unwrap_or_default()
        .into_iter()
        .filter(|l| {
            l.implementation.as_deref().is_none_or(|i| i == "cpython")
                && l.variant.as_deref().is_none_or(|v| v == "default")
        })
        .filter_map(|l| {
            Some(Interpreter {
                path: l.path?,
                version: l.version,
            })
        })
        .filter(|i| parse_version(&i.version).is_some())
        .collect()
}

/// pyenv's installed versions, by their real paths (its shims work only for the selected one).
pub(crate) fn from_pyenv() -> Vec<Interpreter> {
    let run = |args: &[&str]| {
        let out = Command::new("pyenv").args(args).output().ok()?;
        out.status
            .success()
            .then(|| String::from_utf8_lossy(&out.stdout).into_owned())
    };
    let (Some(root), Some(versions)) = (run(&["root"]), run(&["versions", "--bare"])) else {
        return Vec::new();
    };
    let root = PathBuf::from(root.trim());
    versions
        .lines()
        .map(str::trim)
        .filter(|v| parse_version(v).is_some_and(|(_, _, patch)| patch.is_some()))
        .map(|v| Interpreter {
            version: v.to_string(),
            path: root.join("versions").join(v).join("bin").join("python3"),
        })
        .filter(|i| i.path.is_file())
        .collect()
}

/// `3.11.7 (/usr/bin/python3.11), 3.10.13 (...)`, or `none`.
pub fn describe(list: &[Interpreter]) -> String {
    if list.is_empty() {
        return "none".into();
    }
    list.iter()
        .map(|i| format!("{} ({})", i.version, i.path.display()))
        .collect::<Vec<_>>()
        .join(", ")
}
