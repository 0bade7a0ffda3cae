//! rapier's adapter runs in a worker binary of its own (`envhub-worker-rapier`): what the
//! other workers list of it is the adapter's own, they hand its jobs over, and without the
//! binary its envs say how to get it instead of failing somewhere deeper.

use envhub_core::EnvAdapter;
use envhub_e2e::binary;
use std::process::Command;

/// The `rapier` entry of `describe` by worker binary `path`.
fn rapier_entry(path: &std::path::Path) -> serde_json::Value {
    let out = Command::new(path).arg("describe").output().unwrap();
    assert!(out.status.success(), "{}: {:?}", path.display(), out);
    let list: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).unwrap();
    list.into_iter()
        .find(|a| a["name"] == "rapier")
        .unwrap_or_else(|| panic!("{} lists no rapier adapter", path.display()))
}

#[test]
fn every_worker_lists_rapier_as_its_own_binary_does() {
    let own = rapier_entry(&binary("envhub-worker-rapier"));
    let adapter = envhub_rapier::Rapier;
    assert_eq!(own["envs"], serde_json::json!(adapter.list_envs()));
    assert_eq!(own["frameworks"], serde_json::json!(adapter.frameworks()));
    assert_eq!(own["requires"], serde_json::json!(adapter.requires()));
    assert_eq!(own["description"], adapter.description());
    assert_eq!(
        own["render_modes"],
        serde_json::json!(adapter.render_modes())
    );
    assert_eq!(own["availability"]["status"], "available");
    // `envhub-worker` lists it from constants (it is `envhub-worker-mujoco` by then, where
    // libmujoco is found, as under `make test`): the same entry.
    assert_eq!(rapier_entry(&binary("envhub-worker")), own);
}

/// `envhub-worker` copied alone into a folder of its own (named after `test`), with `rapier`
/// (bytes, mode) beside it if given; then `envhub run rapier-arm-reach` through it. Returns the
/// lone worker's `rapier` entry, whether the run succeeded and what it printed.
fn run_rapier_beside(
    test: &str,
    rapier: Option<(&[u8], u32)>,
) -> (serde_json::Value, bool, String) {
    use std::os::unix::fs::PermissionsExt;
    let dir = std::env::temp_dir().join(format!("envhub-e2e-{test}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let worker = dir.join("envhub-worker");
    std::fs::copy(binary("envhub-worker"), &worker).unwrap();
    if let Some((bytes, mode)) = rapier {
        let path = dir.join("envhub-worker-rapier");
        std::fs::write(&path, bytes).unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(mode)).unwrap();
    }
    let entry = rapier_entry(&worker);
    let out = Command::new(binary("envhub"))
        .args([
            "run",
            "rapier-arm-reach",
            "--num-envs",
            "2",
            "--steps",
            "10",
        ])
        .env("ENVHUB_WORKER", &worker)
        .env(
            "ENVHUB_NAMESPACE",
            format!("e2e_{test}_{}_", std::process::id()),
        )
        .output()
        .unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    let text =
        String::from_utf8_lossy(&out.stderr).into_owned() + &String::from_utf8_lossy(&out.stdout);
    (entry, out.status.success(), text)
}

#[test]
fn without_rapier_s_worker_its_envs_say_how_to_get_it() {
    let (entry, ok, text) = run_rapier_beside("norapier", None);
    assert_eq!(entry["availability"]["status"], "unavailable", "{entry}");
    let reason = entry["availability"]["reason"].as_str().unwrap();
    assert!(reason.contains("no `envhub-worker-rapier` at"), "{reason}");
    // Through the CLI, as a user would meet it.
    assert!(!ok, "{text}");
    assert!(
        text.contains("envhub-worker-rapier") && text.contains("make build-all"),
        "{text}"
    );
}

#[test]
fn a_rapier_worker_that_cannot_start_is_an_answer_naming_it() {
    // There, but not executable: the hand-over's `exec` fails.
    let (_, ok, text) = run_rapier_beside("badrapier", Some((b"not a program", 0o644)));
    assert!(!ok, "{text}");
    assert!(
        text.contains("the worker for adapter `rapier`: cannot start `")
            && text.contains("envhub-worker-rapier`: Permission denied"),
        "{text}"
    );
}
