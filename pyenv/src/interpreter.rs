//! The CPython interpreters present on this machine, to base environments on.
//!
//! uv cannot download its managed Pythons here, so only installed ones count: those uv finds
//! (on `PATH`, its own installs) and pyenv's (`pyenv versions`), whose shims uv cannot use
//! for versions other than the selected one.

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
