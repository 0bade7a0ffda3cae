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
