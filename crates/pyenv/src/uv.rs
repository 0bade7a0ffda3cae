//! Running uv: found once, run with its output captured, a progress line while it works.

use envhub_catalog::package_name;
use std::io::Read;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Where uv is looked for, in order: `explicit` (ENVHUB_UV), beside `python` (the hub's
/// interpreter, where `pip install uv` puts it), then `PATH`. `Err` lists what was looked at.
pub fn find_uv(explicit: Option<&Path>, python: Option<&Path>) -> Result<PathBuf, String> {
    let mut searched = Vec::new();
    if let Some(path) = explicit {
        if path.is_file() {
            return Ok(path.to_path_buf());
        }
        searched.push(format!("ENVHUB_UV=`{}`", path.display()));
    }
    if let Some(python) = python {
        // Not canonicalized: a venv's `bin/python` links to the base interpreter, but uv is
        // installed in the venv's `bin/`.
        if let Some(dir) = python.parent().filter(|d| !d.as_os_str().is_empty()) {
            let beside = dir.join("uv");
            if beside.is_file() {
                return Ok(beside);
            }
            searched.push(format!("`{}`", beside.display()));
        }
    }
    if let Some(path) = std::env::var_os("PATH") {
        for dir in std::env::split_paths(&path) {
            let candidate = dir.join("uv");
            if candidate.is_file() {
                return Ok(candidate);
            }
        }
    }
    searched.push("`PATH`".into());
    Err(searched.join(", "))
}

/// uv's variables that change what it resolves or installs (indexes, what it may build,
/// which versions it picks, its configuration file); part of every environment's key.
/// Not these: where its cache is, how it links files, timeouts, concurrency, credentials.
pub const SETTINGS_VARS: &[&str] = &[
    "UV_INDEX",
    "UV_DEFAULT_INDEX",
    "UV_INDEX_URL",
    "UV_EXTRA_INDEX_URL",
    "UV_FIND_LINKS",
    "UV_NO_INDEX",
    "UV_INDEX_STRATEGY",
    "UV_TORCH_BACKEND",
    "UV_PRERELEASE",
    "UV_RESOLUTION",
    "UV_EXCLUDE_NEWER",
    "UV_NO_BINARY",
    "UV_NO_BINARY_PACKAGE",
    "UV_NO_BUILD",
    "UV_NO_BUILD_PACKAGE",
    "UV_CONSTRAINT",
    "UV_OVERRIDE",
    "UV_BUILD_CONSTRAINT",
    "UV_CONFIG_FILE",
    "UV_NO_CONFIG",
];

/// The uv configuration that decides what gets installed, as text for the key: the set
/// [`SETTINGS_VARS`], then the content of every configuration file uv reads for a `uv pip`
/// command run from the current folder — `UV_CONFIG_FILE`'s, else the nearest `uv.toml`
/// (or `pyproject.toml` with a `[tool.uv]` table) of the current folder and its parents,
/// then the user's (`$XDG_CONFIG_HOME/uv/uv.toml`, `~/.config/uv/uv.toml`) and the system's
/// (`$XDG_CONFIG_DIRS/uv/uv.toml`, `/etc/uv/uv.toml`); none with `UV_NO_CONFIG`.
pub fn settings() -> String {
    let mut text = String::new();
    for var in SETTINGS_VARS {
        if let Some(value) = std::env::var_os(var) {
            text.push_str(&format!("{var}={}\n", value.to_string_lossy()));
        }
    }
    for file in config_files() {
        if let Ok(content) = std::fs::read_to_string(&file) {
            text.push_str(&format!("uv config {}\n{content}\n", file.display()));
        }
    }
    text
}

fn config_files() -> Vec<PathBuf> {
    let set = |name: &str| std::env::var_os(name).filter(|v| !v.is_empty());
    if set("UV_NO_CONFIG").is_some_and(|v| v != "0" && v != "false") {
        return Vec::new();
    }
    let mut files = Vec::new();
    if let Some(file) = set("UV_CONFIG_FILE") {
        files.push(PathBuf::from(file));
    } else if let Ok(cwd) = std::env::current_dir() {
        for dir in cwd.ancestors() {
            let uv_toml = dir.join("uv.toml");
            let pyproject = dir.join("pyproject.toml");
            if uv_toml.is_file() {
                files.push(uv_toml);
                break;
            }
            if std::fs::read_to_string(&pyproject).is_ok_and(|t| t.contains("[tool.uv")) {
                files.push(pyproject);
                break;
            }
        }
    }
    let user = set("XDG_CONFIG_HOME")
        .map(PathBuf::from)
        .or_else(|| set("HOME").map(|h| PathBuf::from(h).join(".config")));
    files.extend(user.map(|d| d.join("uv").join("uv.toml")));
    let system = set("XDG_CONFIG_DIRS")
        .map(|dirs| {
            std::env::split_paths(&dirs)
                .map(|d| d.join("uv").join("uv.toml"))
                .collect::<Vec<_>>()
        })
        .unwrap_or_else(|| vec![PathBuf::from("/etc/xdg/uv/uv.toml")]);
    files.extend(system);
    files.push(PathBuf::from("/etc/uv/uv.toml"));
    files
}

/// This machine's platform as uv names targets (`--python-platform`):
/// `x86_64-unknown-linux-gnu`, `aarch64-apple-darwin`, ...
pub fn platform() -> String {
    let arch = std::env::consts::ARCH;
    if cfg!(target_os = "macos") {
        format!("{arch}-apple-darwin")
    } else if cfg!(target_env = "musl") {
        format!("{arch}-unknown-linux-musl")
    } else {
        format!("{arch}-unknown-linux-gnu")
    }
}

/// How a uv run ended badly: its message (stderr, trimmed).
pub(crate) struct Failed(pub String);

/// Runs `command` (a uv command) to the end, with stdout/stderr captured; while it runs,
/// `progress` is called every `every` with the time elapsed. The child dies with this thread
/// (`PR_SET_PDEATHSIG`): a killed hub never leaves uv writing into a folder that the next
/// build will clear.
pub(crate) fn run(
    mut command: Command,
    every: Duration,
    mut progress: impl FnMut(Duration),
) -> Result<String, Failed> {
    command
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .env("UV_NO_PROGRESS", "1");
    // A missing version fails rather than being downloaded, unless the caller asked for one.
    if !command
        .get_envs()
        .any(|(k, _)| k == std::ffi::OsStr::new("UV_PYTHON_DOWNLOADS"))
    {
        command.env("UV_PYTHON_DOWNLOADS", "never");
    }
    // SAFETY: `prctl` is async-signal-safe and allocates nothing.
    unsafe {
        command.pre_exec(|| {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGKILL);
            Ok(())
        });
    }
    let shown = format!("{command:?}");
    let mut child = command
        .spawn()
        .map_err(|e| Failed(format!("cannot start {shown}: {e}")))?;
    let mut stdout = child.stdout.take().expect("piped");
    let mut stderr = child.stderr.take().expect("piped");
    let out_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stdout.read_to_string(&mut s);
        s
    });
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = stderr.read_to_string(&mut s);
        s
    });
    let start = Instant::now();
    let mut next = every;
    let status = loop {
        match child.try_wait() {
            Ok(Some(status)) => break status,
            Ok(None) => {}
            Err(e) => return Err(Failed(format!("cannot wait for uv: {e}"))),
        }
        if start.elapsed() >= next {
            progress(start.elapsed());
            next += every;
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let out = out_reader.join().unwrap_or_default();
    let err = err_reader.join().unwrap_or_default();
    if status.success() {
        Ok(out)
    } else {
        let message = err.trim();
        Err(Failed(if message.is_empty() {
            format!("uv exited with {status}")
        } else {
            message.to_string()
        }))
    }
}

/// The requirements whose package uv's `message` names, as `` `a`, `b` ``; all of them
/// (`one of ...`) when it names none.
pub(crate) fn named_packages(message: &str, requirements: &[String]) -> String {
    let text = message.to_lowercase().replace('_', "-");
    let named: Vec<String> = requirements
        .iter()
        .filter(|r| {
            let name = package_name(r);
            !name.is_empty() && mentions(&text, &name)
        })
        .map(|r| format!("`{}`", r.trim()))
        .collect();
    if named.is_empty() {
        let all: Vec<String> = requirements
            .iter()
            .map(|r| format!("`{}`", r.trim()))
            .collect();
        format!("one of {}", all.join(", "))
    } else {
        named.join(", ")
    }
}

/// Whether `name` occurs in `text` as a whole word (`numpy` in `numpy==2`, not in `numpyro`).
fn mentions(text: &str, name: &str) -> bool {
    let is_word = |c: char| c.is_ascii_alphanumeric() || c == '-';
    text.match_indices(name).any(|(at, _)| {
        let before = text[..at].chars().next_back();
        let after = text[at + name.len()..].chars().next();
        !before.is_some_and(is_word) && !after.is_some_and(is_word)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_error_names_the_packages_uv_names() {
        let reqs = vec![
            "numpy".to_string(),
            "nonexistent_pkg==1.0".to_string(),
            "numpyro".to_string(),
        ];
        let uv = "error: No solution found\n  cause: Because nonexistent-pkg was not found in the package registry";
        assert_eq!(named_packages(uv, &reqs), "`nonexistent_pkg==1.0`");
        assert_eq!(
            named_packages("error: network down", &reqs[..2]),
            "one of `numpy`, `nonexistent_pkg==1.0`"
        );
    }
}
