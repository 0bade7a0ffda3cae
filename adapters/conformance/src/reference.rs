//! The parity tests' side of a Python reference script (envpool's `*_align_test.py` idea,
//! driven from Rust): running it, and comparing its numbers.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

// `ENVHUB_PYTHON` is declared with the other variables in `crates/hub/src/env_vars.rs`, which test
// support cannot depend on; `ENVHUB_SKIP_PYTHON_TESTS` is not declared there yet.
/// The interpreter (default: `<repo>/.venv/bin/python`, which `make test` creates).
const ENVHUB_PYTHON: &str = "ENVHUB_PYTHON";
/// `1`: a test whose Python lacks what it needs is skipped instead of failing.
const ENVHUB_SKIP_PYTHON_TESTS: &str = "ENVHUB_SKIP_PYTHON_TESTS";

fn repo_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Runs `script` (a path from the repository root, run from there) and parses what it prints as
/// JSON.
///
/// The interpreter is `$ENVHUB_PYTHON`, else `<repo>/.venv/bin/python`, and must import every
/// module in `imports`. If it cannot, this fails with a hint naming `needs` (what to install,
/// `gymnasium 1.4 and mujoco 3.17`) — unless `ENVHUB_SKIP_PYTHON_TESTS=1`: then it prints why
/// and returns `None`, and the test should return. A script that fails once started fails the
/// test either way.
#[track_caller]
pub fn python_reference(script: &str, imports: &[&str], needs: &str) -> Option<Value> {
    let root = repo_root();
    let python = std::env::var_os(ENVHUB_PYTHON)
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join(".venv/bin/python"));
    let probe = Command::new(&python)
        .args(["-c", &format!("import {}", imports.join(", "))])
        .output();
    let problem = match probe {
        Err(e) => Some(format!("cannot run `{}`: {e}", python.display())),
        Ok(out) if !out.status.success() => Some(format!(
            "`{}` cannot import {}: {}",
            python.display(),
            imports.join(" and "),
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
                .trim()
        )),
        Ok(_) => None,
    };
    if let Some(problem) = problem {
        if std::env::var(ENVHUB_SKIP_PYTHON_TESTS).as_deref() == Ok("1") {
            println!(
                "skipped the test against `{script}` ({ENVHUB_SKIP_PYTHON_TESTS}=1): {problem}"
            );
            return None;
        }
        panic!(
            "{problem}\nhint: run `make test` (it creates `.venv` with {needs}), or set \
             {ENVHUB_PYTHON} to a Python with {needs}; {ENVHUB_SKIP_PYTHON_TESTS}=1 skips \
             this test"
        );
    }
    let script = root.join(script);
    let out = Command::new(&python)
        .arg(&script)
        .current_dir(&root)
        .output()
        .unwrap_or_else(|e| panic!("cannot run `{}`: {e}", script.display()));
    assert!(
        out.status.success(),
        "`{}` failed:\n{}",
        script.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).expect("the reference script prints JSON"))
}

/// The Gymnasium version a reference records (its `gymnasium` field); panics unless it is of
/// `series` (`1.4`), the one the envs follow.
#[track_caller]
pub fn gymnasium_version<'a>(reference: &'a Value, series: &str) -> &'a str {
    let version = reference["gymnasium"].as_str().unwrap_or("?");
    assert!(
        version.starts_with(&format!("{series}.")),
        "the reference is gymnasium {version}; these envs follow gymnasium {series}\n\
         hint: install gymnasium=={series}.* in the Python the test runs"
    );
    version
}

/// Whether `got` is within `tol` of `want`, relative to `|want|` (absolute where `|want| < 1`).
pub fn close(got: f64, want: f64, tol: f64) -> bool {
    (got - want).abs() <= tol * want.abs().max(1.0)
}

/// The difference [`close`] bounds: `|got - want|` relative to `|want|` (absolute where
/// `|want| < 1`); 0 when they are equal.
pub fn scaled_diff(got: f64, want: f64) -> f64 {
    (got - want).abs() / want.abs().max(1.0)
}

/// A JSON list of numbers as `f64`s; panics on anything else.
#[track_caller]
pub fn floats(v: &Value) -> Vec<f64> {
    v.as_array()
        .expect("a list of numbers")
        .iter()
        .map(|x| x.as_f64().expect("a number"))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn close_is_relative_above_one_and_absolute_below() {
        assert!(close(1000.0005, 1000.0, 1e-6));
        assert!(!close(1000.002, 1000.0, 1e-6));
        assert!(close(1e-7, 0.0, 1e-6));
        assert!(!close(2e-6, 0.0, 1e-6));
        assert_eq!(scaled_diff(1001.0, 1000.0), 1e-3);
        assert_eq!(scaled_diff(0.5, 0.25), 0.25);
    }

    #[test]
    fn floats_reads_a_list_of_numbers() {
        assert_eq!(floats(&json!([1, -2.5, 3e-300])), [1.0, -2.5, 3e-300]);
    }

    #[test]
    fn version_of_the_series_is_returned() {
        let reference = json!({"gymnasium": "1.4.0"});
        assert_eq!(gymnasium_version(&reference, "1.4"), "1.4.0");
    }

    #[test]
    #[should_panic(expected = "the reference is gymnasium 1.40.0; these envs follow gymnasium 1.4")]
    fn version_outside_the_series_is_refused() {
        gymnasium_version(&json!({"gymnasium": "1.40.0"}), "1.4");
    }
}
