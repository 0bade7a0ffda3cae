//! Provisioning with the real uv and real installs from PyPI (small packages; uv's cache at
//! its default, so repeats are cheap). Skipped, with the reason, where no uv is found, unless
//! `ENVHUB_PYENV_REQUIRED` is set (`make rust-test` sets it), when that is a failure.

use envhub_pyenv::{PyEnvError, PythonEnvSpec, Store, find_uv};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

const REQUIRED: &str = "ENVHUB_PYENV_REQUIRED";

/// The hub's interpreter as the Makefile sets it, else the workspace's `.venv`.
fn python() -> PathBuf {
    std::env::var_os("ENVHUB_PYTHON")
        .filter(|p| !p.is_empty())
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("../../.venv/bin/python"))
}

/// A store in a fresh folder, or `None` (skip) when uv is missing and not required.
fn store(test: &str) -> Option<Store> {
    let explicit = std::env::var_os("ENVHUB_UV").map(PathBuf::from);
    let uv = match find_uv(explicit.as_deref(), Some(&python())) {
        Ok(uv) => uv,
        Err(searched) => {
            assert!(
                std::env::var_os(REQUIRED).is_none_or(|v| v.is_empty()),
                "{test}: uv is required ({REQUIRED}) but none was found (looked at {searched}); `make venv` installs it"
            );
            eprintln!("skipping {test}: no uv (looked at {searched})");
            return None;
        }
    };
    let root =
        std::env::temp_dir().join(format!("envhub-pyenv-test-{}-{test}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    Some(Store::new(root, uv, python()).with_progress(false))
}

fn spec(reqs: &[&str]) -> PythonEnvSpec {
    PythonEnvSpec {
        requirements: reqs.iter().map(|s| s.to_string()).collect(),
        ..Default::default()
    }
}

fn run_python(python: &Path, code: &str) -> String {
    let out = Command::new(python)
        .arg("-c")
        .arg(code)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

fn leftovers(root: &Path) -> Vec<String> {
    std::fs::read_dir(root)
        .map(|r| {
            r.flatten()
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .filter(|n| n.starts_with(".tmp-") || n.starts_with(".trash-"))
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn an_env_is_built_once_then_found_ready_listed_and_removed() {
    let Some(store) = store("built_once") else {
        return;
    };
    let mut s = spec(&["packaging==24.2"]);
    s.env.insert("ENVHUB_TEST_VAR".into(), "1".into());
    let start = Instant::now();
    let env = store.ensure("tiny", &s).unwrap();
    let cold = start.elapsed();
    assert!(env.built);
    assert_eq!(
        env.env.get("ENVHUB_TEST_VAR").map(String::as_str),
        Some("1")
    );
    assert_eq!(
        run_python(
            &env.python,
            "import packaging; print(packaging.__version__)"
        ),
        "24.2"
    );
    // The venv's interpreter is its own, not the hub's: the hub's packages are not visible.
    assert_eq!(
        run_python(
            &env.python,
            "import sys; print(sys.prefix != sys.base_prefix)"
        ),
        "True"
    );
    let start = Instant::now();
    let again = store.ensure("tiny", &s).unwrap();
    eprintln!(
        "tiny env: built in {cold:?}, found ready in {:?}",
        start.elapsed()
    );
    assert!(!again.built && again.dir == env.dir);
    let listed = store.list();
    assert_eq!(listed.len(), 1, "{listed:?}");
    let manifest = listed[0].manifest.as_ref().expect("ready");
    assert_eq!(manifest.requirements, ["packaging==24.2"]);
    assert!(listed[0].size_bytes > 10_000 && listed[0].last_use.is_some());
    // Another pin is another venv; the first stays.
    let other = store.ensure("tiny", &spec(&["packaging==24.1"])).unwrap();
    assert_ne!(other.dir, env.dir);
    // In use (a process holds it, as a session's worker does): refused, naming the pid.
    let mut holder = Command::new(python())
        .args([
            "-c",
            "import fcntl, os, sys, time\n\
             fd = os.open(sys.argv[1], os.O_RDONLY)\n\
             fcntl.flock(fd, fcntl.LOCK_SH)\n\
             print('held', flush=True)\n\
             time.sleep(60)\n",
        ])
        .arg(env.hold())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut line = String::new();
    std::io::BufRead::read_line(
        &mut std::io::BufReader::new(holder.stdout.take().unwrap()),
        &mut line,
    )
    .unwrap();
    let err = store.remove("tiny", false).unwrap_err();
    assert!(matches!(err, PyEnvError::InUse { .. }), "{err}");
    assert!(
        err.to_string().contains("pid ") && err.to_string().contains("--force"),
        "{err}"
    );
    assert!(env.dir.exists() && other.dir.exists());
    let removed = store.remove("tiny", true).unwrap();
    holder.kill().unwrap();
    holder.wait().unwrap();
    assert_eq!(removed.len(), 2);
    assert!(!env.dir.exists() && store.list().is_empty());
    let err = store.remove("tiny", false).unwrap_err();
    assert!(matches!(err, PyEnvError::NotStored { .. }), "{err}");
    let _ = std::fs::remove_dir_all(store.root());
}

#[test]
fn two_builds_of_one_env_at_once_build_it_once() {
    let Some(store) = store("concurrent") else {
        return;
    };
    let s = spec(&["packaging==24.2", "six==1.16.0"]);
    let results: Vec<_> = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..3)
            .map(|_| scope.spawn(|| store.ensure("shared", &s)))
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap().unwrap())
            .collect()
    });
    assert_eq!(results.iter().filter(|e| e.built).count(), 1, "{results:?}");
    assert!(results.iter().all(|e| e.dir == results[0].dir));
    assert_eq!(store.list().len(), 1);
    let _ = std::fs::remove_dir_all(store.root());
}

#[test]
fn a_failed_install_names_the_package_and_leaves_nothing_ready() {
    let Some(store) = store("failed") else { return };
    let bad = spec(&["packaging", "envhub-no-such-package-zz==1.0"]);
    let err = store.ensure("broken", &bad).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, PyEnvError::Install { .. }), "{text}");
    assert!(text.contains("`envhub-no-such-package-zz==1.0`"), "{text}");
    // uv's own words are carried.
    assert!(text.contains("not found in the package registry"), "{text}");
    assert!(
        store.list().is_empty() && leftovers(store.root()).is_empty(),
        "{:?}",
        store.list()
    );
    // Other envs keep working.
    assert!(
        store
            .ensure("fine", &spec(&["packaging==24.2"]))
            .unwrap()
            .built
    );
    let _ = std::fs::remove_dir_all(store.root());
}

/// Run by `an_interrupted_build_never_counts_as_ready` in a child process that it kills.
#[test]
fn child_build() {
    let Some(root) = std::env::var_os("ENVHUB_PYENV_TEST_CHILD_ROOT") else {
        return;
    };
    let explicit = std::env::var_os("ENVHUB_UV").map(PathBuf::from);
    let uv = find_uv(explicit.as_deref(), Some(&python())).unwrap();
    let store = Store::new(PathBuf::from(root), uv, python()).with_progress(false);
    let _ = store.ensure("interrupted", &spec(&["numpy", "packaging"]));
}

#[test]
fn an_interrupted_build_never_counts_as_ready() {
    let Some(store) = store("interrupted") else {
        return;
    };
    let s = spec(&["numpy", "packaging"]);
    let mut child = Command::new(std::env::current_exe().unwrap())
        .args(["--exact", "child_build", "--nocapture"])
        .env("ENVHUB_PYENV_TEST_CHILD_ROOT", store.root())
        .spawn()
        .unwrap();
    // Killed as soon as its build folder appears: mid-venv or mid-install.
    let deadline = Instant::now() + Duration::from_secs(60);
    while leftovers(store.root()).is_empty() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("the child exited ({status}) before it started building");
        }
        assert!(
            Instant::now() < deadline,
            "the child never started building"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    child.kill().unwrap();
    child.wait().unwrap();
    let plan = store.plan("interrupted", &s).unwrap();
    assert!(
        store.ready(&plan).is_none(),
        "an interrupted build counts as ready"
    );
    assert!(!plan.dir.exists());
    assert!(!leftovers(store.root()).is_empty());
    // The next build clears what was left and completes (the lock died with the child).
    let env = store.ensure("interrupted", &s).unwrap();
    assert!(env.built && leftovers(store.root()).is_empty());
    let _ = std::fs::remove_dir_all(store.root());
}

#[test]
fn a_build_held_by_another_waits_a_bounded_time_and_says_who() {
    let Some(store) = store("lock_wait") else {
        return;
    };
    let store = std::sync::Arc::new(store.with_lock_wait(Duration::from_millis(300)));
    let s = spec(&["packaging==24.2"]);
    let plan = store.plan("held", &s).unwrap();
    std::fs::create_dir_all(store.root()).unwrap();
    let lock_path = store.root().join(format!("held-{}.lock", plan.key));
    std::fs::write(&lock_path, "pid 4242").unwrap();
    let file = std::fs::File::open(&lock_path).unwrap();
    use std::os::fd::AsRawFd;
    // SAFETY: a plain flock on a descriptor open for the call.
    assert_eq!(
        unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) },
        0
    );
    // The lock is held for as long as this test likes: only the store's own 0.3 s wait can
    // end the call (a thread, so that a wait without end fails here rather than hangs).
    let (tx, waited) = std::sync::mpsc::channel();
    let (waiter, wanted) = (store.clone(), s.clone());
    std::thread::spawn(move || {
        let _ = tx.send(waiter.ensure("held", &wanted).map(drop));
    });
    let Ok(result) = waited.recv_timeout(Duration::from_secs(60)) else {
        panic!("a build held by another waits without end");
    };
    let err = result.unwrap_err();
    let text = err.to_string();
    assert!(
        matches!(err, PyEnvError::LockTimeout { .. }) && text.contains("pid 4242"),
        "{text}"
    );
    drop(file);
    assert!(store.ensure("held", &s).unwrap().built);
    let _ = std::fs::remove_dir_all(store.root());
}

#[test]
fn a_missing_python_version_lists_the_present_ones() {
    let Some(store) = store("missing_python") else {
        return;
    };
    let mut s = spec(&["packaging"]);
    s.python = Some("3.99".into());
    let err = store.ensure("future", &s).unwrap_err();
    let text = err.to_string();
    assert!(matches!(err, PyEnvError::PythonNotFound { .. }), "{text}");
    let own = envhub_pyenv::version_of(&python()).unwrap();
    assert!(
        text.contains("Python 3.99") && text.contains(&own),
        "{text}"
    );
}

#[test]
fn an_env_on_a_second_python_version() {
    let Some(store) = store("second_python") else {
        return;
    };
    let own = envhub_pyenv::version_of(&python()).unwrap();
    let Some(other) = store.interpreters().iter().find(|i| {
        !i.version.starts_with(&own[..4])
            && ["3.10.", "3.12.", "3.13.", "3.9."]
                .iter()
                .any(|v| i.version.starts_with(v))
    }) else {
        assert!(
            std::env::var_os(REQUIRED).is_none_or(|v| v.is_empty()),
            "a second CPython (3.9, 3.10, 3.12 or 3.13) is required ({REQUIRED}) but only {own} is present"
        );
        eprintln!("skipping: no second CPython version");
        return;
    };
    let minor: String = other
        .version
        .split('.')
        .take(2)
        .collect::<Vec<_>>()
        .join(".");
    let mut s = spec(&["packaging==24.2"]);
    s.python = Some(minor.clone());
    let env = store.ensure("second", &s).unwrap();
    let got = run_python(
        &env.python,
        "import sys; print('%d.%d' % sys.version_info[:2])",
    );
    assert_eq!(got, minor);
    let _ = std::fs::remove_dir_all(store.root());
}
