//! The `envhub` binary's data-plane commands, run as a user would.

use envhub_e2e::binary;
use std::process::Command;

fn envhub(args: &[&str], vars: &[(&str, &str)]) -> (i32, String, String) {
    let out = Command::new(binary("envhub"))
        .args(args)
        .env_remove("ENVHUB_TEST_ADAPTERS")
        .envs(vars.iter().copied())
        .env(
            "ENVHUB_NAMESPACE",
            format!("e2e_cli_{}_", std::process::id()),
        )
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn run_json_reports_a_rollout() {
    let (code, out, err) = envhub(
        &[
            "run",
            "gym-cartpole",
            "--num-envs",
            "4",
            "--workers",
            "2",
            "--steps",
            "4000",
            "--json",
        ],
        &[],
    );
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["id"], "gym-cartpole");
    assert_eq!(v["steps"], 4000);
    assert!(v["steps_per_sec"].as_f64().unwrap() > 0.0);
    assert!(v["episodes"].as_u64().unwrap() > 50);
    let mean = v["mean_return"].as_f64().unwrap();
    assert!(
        (10.0..40.0).contains(&mean),
        "random CartPole returns about 22, got {mean}"
    );
}

#[test]
fn adapters_lists_availability() {
    let (code, out, _) = envhub(&["adapters", "--all", "--json"], &[]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let classic = v
        .as_array()
        .unwrap()
        .iter()
        .find(|a| a["name"] == "classic_control")
        .unwrap();
    assert_eq!(classic["availability"]["status"], "available");
    assert!(
        classic["envs"]
            .as_array()
            .unwrap()
            .iter()
            .any(|e| e == "CartPole-v1")
    );
}

/// Names of the adapters in a JSON list of them.
fn adapter_names(json: &str) -> Vec<String> {
    let v: serde_json::Value = serde_json::from_str(json).unwrap();
    v.as_array()
        .unwrap()
        .iter()
        .map(|a| a["name"].as_str().unwrap().to_string())
        .collect()
}

#[test]
fn the_test_adapter_is_listed_only_when_asked_for() {
    let (code, out, err) = envhub(&["adapters", "--all", "--json"], &[]);
    assert_eq!(code, 0, "{err}");
    let names = adapter_names(&out);
    assert!(names.iter().any(|n| n == "classic_control"), "{names:?}");
    assert!(!names.iter().any(|n| n == "null"), "{names:?}");
    let describe = Command::new(binary("envhub-worker"))
        .arg("describe")
        .env_remove("ENVHUB_TEST_ADAPTERS")
        .output()
        .unwrap();
    let names = adapter_names(&String::from_utf8_lossy(&describe.stdout));
    assert!(!names.iter().any(|n| n == "null"), "{names:?}");

    let (code, out, err) = envhub(
        &["adapters", "--all", "--json"],
        &[("ENVHUB_TEST_ADAPTERS", "1")],
    );
    assert_eq!(code, 0, "{err}");
    assert!(adapter_names(&out).iter().any(|n| n == "null"));
}

#[test]
fn bench_json_has_every_figure() {
    // An interpreter that leaves a mark when started as the Python worker: the bench of a
    // native env (and of the test adapter it times round trips with) must never start one
    // to ask what it hosts.
    let dir = std::env::temp_dir().join(format!("e2e-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (python, mark) = (dir.join("python"), dir.join("started"));
    std::fs::write(
        &python,
        format!(
            "#!/bin/sh\ncase \"$*\" in *envhub.worker*) touch '{}';; esac\nexit 1\n",
            mark.display()
        ),
    )
    .unwrap();
    let mut perms = std::fs::metadata(&python).unwrap().permissions();
    std::os::unix::fs::PermissionsExt::set_mode(&mut perms, 0o755);
    std::fs::set_permissions(&python, perms).unwrap();
    let (code, out, err) = envhub(
        &[
            "bench",
            "gym-cartpole",
            "--num-envs",
            "4",
            "--seconds",
            "0.2",
            "--round-trips",
            "500",
            "--json",
        ],
        &[("ENVHUB_PYTHON", python.to_str().unwrap())],
    );
    let started = mark.exists();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(code, 0, "{err}");
    assert!(!started, "the bench started the Python worker");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    for key in [
        "hub_steps_per_sec",
        "inproc_steps_per_sec",
        "roundtrip_p50_us",
        "roundtrip_p99_us",
    ] {
        assert!(v[key].as_f64().unwrap() > 0.0, "{key} in {v}");
    }
    assert_eq!(v["num_envs"], 4);
}

#[test]
fn missing_worker_binary_is_a_clear_error() {
    let (code, _, err) = envhub(
        &["run", "gym-cartpole", "--steps", "10"],
        &[("ENVHUB_WORKER", "/nonexistent/envhub-worker")],
    );
    assert_eq!(code, 2);
    assert!(
        err.contains("cannot start the worker `/nonexistent/envhub-worker`"),
        "{err}"
    );
    assert!(err.contains("hint:"), "{err}");
}
