use crate::{repo_root, temp_dir, write};
use envhub_catalog::{Registry, RegistryError, SearchQuery};
use std::path::PathBuf;

fn ids(hits: &[envhub_catalog::SearchHit<'_>]) -> Vec<String> {
    hits.iter().map(|h| h.entry.id.clone()).collect()
}

fn query() -> SearchQuery {
    SearchQuery::default()
}

#[test]
fn builtin_catalog_loads_every_entry() {
    let reg = Registry::builtin();
    assert!(reg.len() >= 45, "only {} entries", reg.len());
    let mut ids: Vec<&str> = reg.entries().iter().map(|e| e.id.as_str()).collect();
    ids.sort();
    ids.dedup();
    assert_eq!(ids.len(), reg.len(), "ids are unique");
    for e in reg.entries() {
        assert!(!e.description.is_empty(), "{} has a description", e.id);
        assert!(!e.task_tags.is_empty(), "{} has tags", e.id);
    }
    for robot in [
        "arm",
        "quadruped",
        "biped",
        "dexterous_hand",
        "mobile_base",
        "custom",
    ] {
        assert!(
            reg.robot_types().contains(&robot.to_string()),
            "robot type {robot} is used"
        );
    }
    for env_type in ["tabletop", "floor", "terrain", "aerial", "aquatic"] {
        assert!(
            reg.distinct("env_type").contains(&env_type.to_string()),
            "env type {env_type}"
        );
    }
    for framework in [
        "gymnasium",
        "maniskill",
        "libero",
        "isaac_lab",
        "custom_mjcf",
    ] {
        assert!(
            reg.frameworks().contains(&framework.to_string()),
            "framework {framework}"
        );
    }
}

#[test]
fn builtin_fixes_robosmith_mistakes() {
    let reg = Registry::builtin();
    let lander = reg.get("gym-lunar-lander-continuous").unwrap();
    assert_eq!(
        lander.kwargs.get("continuous"),
        Some(&serde_json::json!(true))
    );
    assert_eq!(lander.action_type, "continuous");
    let custom = reg
        .entries()
        .iter()
        .find(|e| e.framework == "custom_mjcf")
        .expect("a custom_mjcf example");
    let asset = custom.asset_path.as_ref().expect("it names its asset");
    assert!(asset.is_file(), "{} exists", asset.display());
}

#[test]
fn loads_robosmith_registry_unchanged() {
    let path = repo_root().join("../shared/compat/robosmith_env_registry.yaml");
    if !path.is_file() {
        // The compat file sits beside the repository in the project's layout.
        panic!("missing {}", path.display());
    }
    let reg = Registry::load(&[&path]).unwrap();
    assert_eq!(reg.len(), 30);
    let ant = reg.get("mujoco-ant").unwrap();
    assert_eq!(ant.env_id, "Ant-v5");
    assert_eq!(
        ant.task_tags,
        ["locomotion", "walk", "run", "quadruped", "forward"]
    );
    assert!(ant.kwargs.is_empty() && ant.max_episode_steps.is_none());
}

#[test]
fn optional_fields_take_robosmith_defaults() {
    let dir = temp_dir("defaults");
    let file = write(
        &dir,
        "r.yaml",
        "environments:\n  - id: mini\n    name: Mini\n    framework: gymnasium\n    env_id: CartPole-v1\n    robot_type: custom\n    env_type: floor\n",
    );
    let reg = Registry::load(&[file]).unwrap();
    let e = reg.get("mini").unwrap();
    assert_eq!(e.robot_model, "");
    assert!(e.task_tags.is_empty());
    assert_eq!(e.obs_type, "state");
    assert_eq!(e.action_type, "continuous");
    assert_eq!(e.description, "");
    assert_eq!(e.source, "");
}

const ENTRY: &str = "  - id: {ID}\n    name: N\n    framework: gymnasium\n    env_id: CartPole-v1\n    robot_type: custom\n    env_type: floor\n";

fn entry(id: &str) -> String {
    ENTRY.replace("{ID}", id)
}

fn load_text(text: &str) -> Result<Registry, RegistryError> {
    let dir = temp_dir(&format!(
        "bad-{:x}",
        text.len() * 31 + text.bytes().map(usize::from).sum::<usize>()
    ));
    let file = write(&dir, "bad.yaml", text);
    Registry::load(&[file])
}

#[test]
fn unknown_field_names_file_line_and_valid_fields() {
    let text = format!("environments:\n{}    robot: arm\n", entry("a"));
    let err = load_text(&text).unwrap_err().to_string();
    assert!(err.contains("bad.yaml:8:"), "{err}");
    assert!(err.contains("unknown field `robot`"), "{err}");
    assert!(
        err.contains("`robot_type`") && err.contains("`asset_path`"),
        "{err}"
    );
}

#[test]
fn missing_field_is_named() {
    let text = "environments:\n  - id: a\n    name: N\n    framework: gymnasium\n    robot_type: custom\n    env_type: floor\n";
    let err = load_text(text).unwrap_err().to_string();
    assert!(err.contains("missing field `env_id`"), "{err}");
    assert!(err.contains("bad.yaml:2:"), "{err}");
}

#[test]
fn wrong_type_names_the_field() {
    let text = format!("environments:\n{}    task_tags: 3\n", entry("a"));
    let err = load_text(&text).unwrap_err().to_string();
    assert!(err.contains("environments[0].task_tags"), "{err}");
    assert!(err.contains("invalid type"), "{err}");
    assert!(err.contains(":8:"), "{err}");
    let text = format!("environments:\n{}    max_episode_steps: lots\n", entry("a"));
    let err = load_text(&text).unwrap_err().to_string();
    assert!(err.contains("environments[0].max_episode_steps"), "{err}");
}

#[test]
fn duplicate_id_names_both_lines() {
    let text = format!("environments:\n{}{}", entry("twin"), entry("twin"));
    let err = load_text(&text).unwrap_err();
    assert!(
        matches!(
            err,
            RegistryError::DuplicateId {
                line: 8,
                first_line: 2,
                ..
            }
        ),
        "{err}"
    );
    assert!(err.to_string().contains("duplicate id `twin`"));
}

#[test]
fn malformed_yaml_and_bad_values() {
    let err = load_text("environments: [\n  - id: a\n")
        .unwrap_err()
        .to_string();
    assert!(err.contains("bad.yaml:"), "{err}");
    let err = load_text("envs: []\n").unwrap_err().to_string();
    assert!(err.contains("unknown field `envs`"), "{err}");
    let err = load_text(&format!("environments:\n{}", entry("\"has space\""))).unwrap_err();
    assert!(err.to_string().contains("`environments[0].id`"), "{err}");
    let text = format!("environments:\n{}    max_episode_steps: 0\n", entry("z"));
    assert!(
        load_text(&text)
            .unwrap_err()
            .to_string()
            .contains("max_episode_steps")
    );
    let missing = Registry::load(&[PathBuf::from("/nonexistent/reg.yaml")]).unwrap_err();
    assert!(
        missing
            .to_string()
            .contains("cannot read registry `/nonexistent/reg.yaml`")
    );
}

#[test]
fn later_files_override_in_place_and_add() {
    let dir = temp_dir("combine");
    let user = write(
        &dir,
        "mine.yaml",
        "environments:\n  - id: mujoco-ant\n    name: My Ant\n    framework: gymnasium\n    env_id: Ant-v5\n    robot_type: quadruped\n    env_type: floor\n    max_episode_steps: 100\n    kwargs: {ctrl_cost_weight: 0.1}\n  - id: my-env\n    name: Mine\n    framework: mysim\n    env_id: Mine-v0\n    robot_type: arm\n    env_type: tabletop\n    asset_path: model.xml\n",
    );
    let base = Registry::builtin();
    let reg = Registry::load(&[PathBuf::from("@default"), user]).unwrap();
    assert_eq!(reg.len(), base.len() + 1);
    let pos = |r: &Registry, id: &str| r.entries().iter().position(|e| e.id == id).unwrap();
    assert_eq!(pos(&reg, "mujoco-ant"), pos(&base, "mujoco-ant"));
    assert_eq!(reg.get("mujoco-ant").unwrap().name, "My Ant");
    assert_eq!(reg.get("mujoco-ant").unwrap().max_episode_steps, Some(100));
    assert_eq!(pos(&reg, "my-env"), reg.len() - 1);
    assert_eq!(
        reg.get("my-env").unwrap().asset_path,
        Some(dir.join("model.xml"))
    );
}

#[test]
fn unknown_id_suggests_closest() {
    let reg = Registry::builtin();
    let err = reg.get("mujoco-antt").unwrap_err().to_string();
    assert!(err.contains("did you mean `mujoco-ant`"), "{err}");
    let err = reg.get("Ant-v5").unwrap_err().to_string();
    assert!(
        err.contains("`mujoco-ant`"),
        "an env_id points at its entry: {err}"
    );
}

#[test]
fn search_filters_combine() {
    let reg = Registry::builtin();
    let quad = ids(&reg.search(&SearchQuery {
        robot_type: Some("QUAD".into()),
        ..query()
    }));
    assert!(quad.contains(&"mujoco-ant".to_string()));
    assert!(
        reg.search(&SearchQuery {
            robot_type: Some("quadruped".into()),
            ..query()
        })
        .iter()
        .all(|h| h.entry.robot_type == "quadruped")
    );

    let gym = reg.search(&SearchQuery {
        framework: Some("gym".into()),
        ..query()
    });
    assert!(!gym.is_empty() && gym.iter().all(|h| h.entry.framework == "gymnasium"));
    let isaac = reg.search(&SearchQuery {
        framework: Some("isaaclab".into()),
        ..query()
    });
    assert!(!isaac.is_empty() && isaac.iter().all(|h| h.entry.framework == "isaac_lab"));

    let tabletop_franka = reg.search(&SearchQuery {
        env_type: Some("tabletop".into()),
        robot_model: Some("franka".into()),
        ..query()
    });
    assert!(!tabletop_franka.is_empty());
    assert!(
        tabletop_franka
            .iter()
            .all(|h| h.entry.env_type == "tabletop" && h.entry.robot_model.contains("franka"))
    );

    let discrete = reg.search(&SearchQuery {
        action_type: Some("discrete".into()),
        ..query()
    });
    assert!(ids(&discrete).contains(&"gym-cartpole".to_string()));
    assert!(discrete.iter().all(|h| h.entry.action_type == "discrete"));
}

#[test]
fn tags_are_stemmed_scored_and_sorted() {
    let reg = Registry::builtin();
    let walking = reg.search(&SearchQuery {
        tags: vec!["walking".into()],
        ..query()
    });
    assert!(ids(&walking).contains(&"mujoco-walker2d".to_string()));
    let hopping = reg.search(&SearchQuery {
        tags: vec!["hopping".into()],
        ..query()
    });
    assert_eq!(hopping[0].entry.id, "mujoco-hopper");

    let hits = reg.search(&SearchQuery {
        robot_type: Some("quadruped".into()),
        tags: vec!["running".into(), "forward".into()],
        ..query()
    });
    assert_eq!(hits[0].entry.id, "mujoco-ant");
    assert_eq!(hits[0].matched_tags, ["running", "forward"]);
    let scores: Vec<usize> = hits.iter().map(|h| h.matched_tags.len()).collect();
    assert!(
        scores.windows(2).all(|w| w[0] >= w[1]),
        "sorted by score: {scores:?}"
    );

    // Ties keep file order.
    let file_order: Vec<String> = reg.entries().iter().map(|e| e.id.clone()).collect();
    let balance = reg.search(&SearchQuery {
        tags: vec!["balance".into()],
        ..query()
    });
    let tied = ids(&balance);
    let positions: Vec<usize> = tied
        .iter()
        .map(|id| file_order.iter().position(|f| f == id).unwrap())
        .collect();
    assert!(positions.windows(2).all(|w| w[0] < w[1]), "{tied:?}");
}

#[test]
fn one_letter_tags_match_nothing() {
    let reg = Registry::builtin();
    assert!(
        reg.search(&SearchQuery {
            tags: vec!["a".into()],
            ..query()
        })
        .is_empty()
    );
    assert!(
        reg.search(&SearchQuery {
            tags: vec!["pen".into()],
            ..query()
        })
        .iter()
        .all(|h| !h.entry.env_id.contains("Pendulum"))
    );
}
