//! A `/dev/shm` too small for a session: the open fails with the bytes needed and free and
//! the fix, instead of a worker's SIGBUS and a hint about `restart_on_crash`.
//!
//! Each run gets a `/dev/shm` of its own (a tmpfs of a given size in a mount namespace:
//! `unshare -rm`), which needs root or unprivileged user namespaces; skipped with the reason
//! otherwise, unless `ENVHUB_NETNS_REQUIRED` is set (the root tier: then a skip is a failure).

use envhub_e2e::binary;
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

const REQUIRED: &str = "ENVHUB_NETNS_REQUIRED";

/// Runs `envhub ARGS` with a `/dev/shm` of `size` (a tmpfs `size=` value); `None` when this
/// machine cannot make one (the reason printed, or a panic where the test is required).
fn envhub_with_shm(test: &str, size: &str, args: &[&str]) -> Option<Output> {
    let registry =
        PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../configs/bench/data_plane.yaml");
    let script = format!("mount -t tmpfs -o size={size} tmpfs /dev/shm && exec \"$@\"");
    let out = Command::new("unshare")
        .args(["-rm", "sh", "-c", &script, "sh"])
        .arg(binary("envhub"))
        .args(["--registry", "@default", "--registry"])
        .arg(registry)
        .args(args)
        .env("ENVHUB_TEST_ADAPTERS", "1")
        .env(
            "ENVHUB_NAMESPACE",
            format!("e2e_shm_{}_", std::process::id()),
        )
        .env("ENVHUB_MULTICAST", "0")
        .env_remove("ENVHUB_HUB")
        .env_remove("ENVHUB_CONNECT")
        .stdin(Stdio::null())
        .output();
    let why = match &out {
        Err(e) => format!("`unshare` cannot run ({e}; package util-linux)"),
        Ok(o) => {
            let err = String::from_utf8_lossy(&o.stderr).to_lowercase();
            if !o.status.success()
                && (err.contains("unshare:") || err.contains("mount:"))
                && ["not permitted", "permission denied", "not supported"]
                    .iter()
                    .any(|n| err.contains(n))
            {
                format!(
                    "no mount namespace here (needs root or user namespaces): {}",
                    err.trim()
                )
            } else {
                return out.ok();
            }
        }
    };
    assert!(
        std::env::var_os(REQUIRED).is_none_or(|v| v.is_empty()),
        "{test}: root-tier tests are required ({REQUIRED}) but {why}"
    );
    eprintln!("skipped {test}: {why}");
    None
}

#[test]
fn a_dev_shm_too_small_fails_the_open_with_the_bytes_needed_and_free() {
    let test = "a_dev_shm_too_small_fails_the_open_with_the_bytes_needed_and_free";
    // 64 envs of 84x84x4 frames: a batch slot of about 1.8 MB.
    let args = [
        "run",
        "null-frames",
        "--num-envs",
        "64",
        "--workers",
        "1",
        "--steps",
        "640",
    ];
    let Some(out) = envhub_with_shm(test, "1m", &args) else {
        return;
    };
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "ran in a 1 MiB /dev/shm: {err}");
    assert!(err.contains("`/dev/shm` is too small"), "{err}");
    assert!(err.contains("it needs 18"), "the bytes needed: {err}");
    assert!(err.contains("bytes are free"), "{err}");
    assert!(err.contains("--shm-size"), "the fix: {err}");
    assert!(
        !err.contains("SIGBUS") && !err.contains("restart_on_crash"),
        "{err}"
    );

    // The same run where `/dev/shm` has room: the failure above was the size alone.
    let out = envhub_with_shm(test, "64m", &args).expect("ran above");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "a 64 MiB /dev/shm: {err}");
}
