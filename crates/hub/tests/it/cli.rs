//! The CLI as people see it: output checked by snapshots, exit codes by assertion.

use crate::{temp_dir, write};
use std::path::Path;
use std::process::Command;

struct Run {
    code: i32,
    stdout: String,
    stderr: String,
}

/// Runs `envhub args` in `cwd` with no ENVHUB_* variables from the outside.
fn envhub_in(cwd: &Path, args: &[&str], vars: &[(&str, &str)]) -> Run {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_envhub"));
    cmd.args(args).current_dir(cwd);
    for (k, _) in std::env::vars() {
        if k.starts_with("ENVHUB_") {
            cmd.env_remove(k);
        }
    }
    // An empty cache of Python environments: `envhub envs` says `(not built)` for the
    // catalog's suites whatever this machine has built.
    cmd.env(
        "ENVHUB_PYENV_DIR",
        std::env::temp_dir().join("envhub-it-no-pyenvs"),
    );
    cmd.envs(vars.iter().copied());
    let out = cmd.output().expect("envhub runs");
    Run {
        code: out.status.code().unwrap_or(-1),
        stdout: String::from_utf8(out.stdout).unwrap(),
        stderr: String::from_utf8(out.stderr).unwrap(),
    }
}

fn envhub(args: &[&str]) -> Run {
    envhub_in(&std::env::temp_dir(), args, &[])
}

#[test]
fn envs_table_filters() {
    let run = envhub(&["envs", "--robot", "quadruped", "--framework", "gym"]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    insta::assert_snapshot!(run.stdout);
}

#[test]
fn envs_tags_space_or_comma_separated() {
    let a = envhub(&["envs", "--tags", "pick place"]);
    let b = envhub(&["envs", "--tags", "pick,place"]);
    let c = envhub(&["envs", "--tags", "pick", "place"]);
    assert_eq!(a.code, 0);
    assert_eq!(a.stdout, b.stdout);
    assert_eq!(a.stdout, c.stdout);
    insta::assert_snapshot!(a.stdout);
}

#[test]
fn envs_json_is_an_array_of_entries() {
    let run = envhub(&[
        "envs",
        "--model",
        "franka",
        "--env-type",
        "tabletop",
        "--json",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    let v: serde_json::Value = serde_json::from_str(&run.stdout).unwrap();
    let arr = v.as_array().unwrap();
    assert!(!arr.is_empty());
    for e in arr {
        for key in [
            "id",
            "name",
            "framework",
            "env_id",
            "robot_type",
            "robot_model",
            "env_type",
            "task_tags",
            "obs_type",
            "action_type",
            "description",
            "source",
        ] {
            assert!(e.get(key).is_some(), "{key} in {e}");
        }
    }
}

#[test]
fn envs_no_match_lists_existing_values() {
    let run = envhub(&["envs", "--robot", "octopus"]);
    assert_eq!(run.code, 1);
    assert!(run.stdout.is_empty());
    insta::assert_snapshot!(run.stderr);
}

#[test]
fn show_entry() {
    let run = envhub(&["show", "gym-lunar-lander-continuous"]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    insta::assert_snapshot!(run.stdout);
    let json = envhub(&["show", "mujoco-ant", "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json.stdout).unwrap();
    assert_eq!(v["env_id"], "Ant-v5");
}

#[test]
fn show_unknown_id_is_an_error_with_hint() {
    let run = envhub(&["show", "mujoco-antt"]);
    assert_eq!(run.code, 2);
    insta::assert_snapshot!(run.stderr);
}

#[test]
fn match_human_and_json() {
    let run = envhub(&["match", "A quadruped runs forward", "--robot", "quadruped"]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    insta::assert_snapshot!(run.stdout);
    let json = envhub(&[
        "match",
        "pick up the cube and place it",
        "--robot",
        "arm",
        "--env-type",
        "tabletop",
        "--json",
    ]);
    assert_eq!(json.code, 0);
    let v: serde_json::Value = serde_json::from_str(&json.stdout).unwrap();
    assert_eq!(v["id"], "fetch-pick-and-place");
    assert!(v["score"].as_f64().unwrap() > 0.0);
    assert!(v["reason"].as_str().unwrap().contains("pick"));
    assert!(v["alternatives"].as_array().is_some());
}

#[test]
fn match_names_a_better_entry_the_robot_type_excludes() {
    let run = envhub(&[
        "match",
        "a robot hops forward on one leg",
        "--robot",
        "biped",
    ]);
    assert_eq!(run.code, 0, "{}", run.stderr);
    insta::assert_snapshot!(run.stdout);
    // Only hoppers hop, and the catalog types them `custom`.
    let none = envhub(&["match", "a robot hopping", "--robot", "biped"]);
    assert_eq!(none.code, 1);
    insta::assert_snapshot!(none.stderr);
}

#[test]
fn match_nothing_exits_one_with_why() {
    let run = envhub(&[
        "match",
        "Fly a submarine through a reef",
        "--robot",
        "custom",
        "--env-type",
        "aquatic",
    ]);
    assert_eq!(run.code, 1);
    insta::assert_snapshot!(run.stderr);
}

#[test]
fn registry_flags_env_and_config_choose_files() {
    let dir = temp_dir("cli-registry");
    write(
        &dir,
        "mine.yaml",
        "environments:\n  - id: my-env\n    name: Mine\n    framework: gymnasium\n    env_id: CartPole-v1\n    robot_type: custom\n    env_type: floor\n    description: mine\n    task_tags: [wobble]\n",
    );
    // --registry replaces the catalog; repeat it to combine with `@default`.
    let only = envhub_in(&dir, &["envs", "--registry", "mine.yaml", "--json"], &[]);
    assert_eq!(
        serde_json::from_str::<serde_json::Value>(&only.stdout)
            .unwrap()
            .as_array()
            .unwrap()
            .len(),
        1
    );
    let both = envhub_in(
        &dir,
        &[
            "show",
            "mujoco-ant",
            "--registry",
            "@default",
            "--registry",
            "mine.yaml",
        ],
        &[],
    );
    assert_eq!(both.code, 0, "{}", both.stderr);

    // ENVHUB_REGISTRY.
    let via_env = envhub_in(
        &dir,
        &["show", "my-env"],
        &[("ENVHUB_REGISTRY", "mine.yaml")],
    );
    assert_eq!(via_env.code, 0, "{}", via_env.stderr);

    // envhub.yaml in the current directory, and --config / ENVHUB_CONFIG elsewhere.
    write(&dir, "envhub.yaml", "env_registry_path: mine.yaml\n");
    assert_eq!(envhub_in(&dir, &["show", "my-env"], &[]).code, 0);
    assert_eq!(envhub_in(&dir, &["show", "mujoco-ant"], &[]).code, 2);
    let elsewhere = temp_dir("cli-registry-cwd");
    let cfg = dir.join("envhub.yaml");
    let cfg = cfg.to_str().unwrap();
    assert_eq!(
        envhub_in(&elsewhere, &["--config", cfg, "show", "my-env"], &[]).code,
        0
    );
    assert_eq!(
        envhub_in(&elsewhere, &["show", "my-env"], &[("ENVHUB_CONFIG", cfg)]).code,
        0
    );

    // A typo in the config file is an error naming the valid fields.
    write(&dir, "envhub.yaml", "env_registry: mine.yaml\n");
    let bad = envhub_in(&dir, &["envs"], &[]);
    assert_eq!(bad.code, 2);
    assert!(
        bad.stderr.contains("unknown field `env_registry`"),
        "{}",
        bad.stderr
    );
    assert!(bad.stderr.contains("env_registry_path"), "{}", bad.stderr);
}

#[test]
fn bad_registry_file_is_one_error_line_and_a_hint() {
    let dir = temp_dir("cli-bad");
    write(
        &dir,
        "bad.yaml",
        "environments:\n  - id: x\n    name: X\n    framework: gymnasium\n    env_id: CartPole-v1\n    robot_type: custom\n    env_type: floor\n    tags: [a]\n",
    );
    let run = envhub_in(&dir, &["envs", "--registry", "bad.yaml"], &[]);
    assert_eq!(run.code, 2);
    let lines: Vec<&str> = run.stderr.lines().collect();
    assert_eq!(lines.len(), 2, "{}", run.stderr);
    assert!(lines[0].starts_with("error: bad.yaml:8:"), "{}", run.stderr);
    assert!(lines[1].starts_with("hint: "), "{}", run.stderr);
}
