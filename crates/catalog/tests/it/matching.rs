use envhub_catalog::{MatchError, Registry, TaskSpec, match_task};

fn spec(description: &str, robot: Option<&str>, env_type: Option<&str>) -> TaskSpec {
    TaskSpec {
        task_description: description.into(),
        robot_type: robot.map(Into::into),
        environment_type: env_type.map(Into::into),
        ..TaskSpec::default()
    }
}

#[test]
fn quadruped_running_forward_is_ant() {
    let reg = Registry::builtin();
    let m = match_task(
        &spec("A quadruped runs forward", Some("quadruped"), None),
        &reg,
    )
    .unwrap();
    assert_eq!(m.entry.id, "mujoco-ant");
    assert!(m.score > 0.9 && m.score <= 1.0, "{}", m.score);
    assert!(
        m.reason.contains("quadruped") && m.reason.contains("runs"),
        "{}",
        m.reason
    );
    assert!(!m.alternatives.is_empty());
    assert!(m.alternatives.iter().all(|a| a.score <= m.score));
}

#[test]
fn pick_and_place_is_fetch() {
    let reg = Registry::builtin();
    for text in ["pick up the cube and place it", "Pick-and-place: the cube!"] {
        let m = match_task(&spec(text, Some("arm"), Some("tabletop")), &reg).unwrap();
        assert!(
            m.entry.env_id.starts_with("FetchPickAndPlace"),
            "{text}: {}",
            m.entry.id
        );
        assert!(
            m.reason.contains("pick") && m.reason.contains("place"),
            "{}",
            m.reason
        );
    }
}

#[test]
fn submarine_in_a_reef_is_no_match() {
    let reg = Registry::builtin();
    let err = match_task(
        &spec(
            "Fly a submarine through a reef",
            Some("custom"),
            Some("aquatic"),
        ),
        &reg,
    )
    .unwrap_err();
    assert!(matches!(err, MatchError::NoMatch { .. }), "{err}");
}

#[test]
fn explicit_id_wins_and_unknown_id_is_an_error() {
    let reg = Registry::builtin();
    let mut s = spec("anything at all", None, None);
    s.environment_id = Some("gym-cartpole".into());
    let m = match_task(&s, &reg).unwrap();
    assert_eq!((m.entry.id.as_str(), m.score), ("gym-cartpole", 1.0));
    s.environment_id = Some("gym-cartpol".into());
    let err = match_task(&s, &reg).unwrap_err().to_string();
    assert!(err.contains("did you mean `gym-cartpole`"), "{err}");
}

#[test]
fn env_type_is_relaxed_only_for_strong_matches() {
    let reg = Registry::builtin();
    // Ant lives on the floor; asking for terrain relaxes to it because every word matches.
    let m = match_task(
        &spec("ant walks forward", Some("quadruped"), Some("aquatic")),
        &reg,
    )
    .unwrap();
    assert!(m.reason.contains("relaxed"), "{}", m.reason);
    // Unknown words only: nothing to match on.
    let err = match_task(&spec("zzz qqq", None, None), &reg)
        .unwrap_err()
        .to_string();
    assert!(err.contains("none of its words"), "{err}");
    let err = match_task(&spec("", None, None), &reg)
        .unwrap_err()
        .to_string();
    assert!(err.contains("no task words"), "{err}");
}

/// The built-in catalog's Gymnasium entries: the cases below are about its Hopper and its
/// bipeds, whatever suites the catalog grows (dm_control has a hopper and walkers too).
fn gymnasium_catalog() -> Registry {
    let entries = Registry::builtin()
        .entries()
        .iter()
        .filter(|e| e.framework == "gymnasium")
        .cloned()
        .collect();
    Registry::from_entries(entries, "gymnasium entries of @default")
}

#[test]
fn a_better_entry_the_robot_type_excludes_is_an_alternative_with_the_reason() {
    let reg = gymnasium_catalog();
    // The registry types Hopper `custom`: asking for a biped still chooses a biped, and says
    // that Hopper matches every word but is excluded by the robot type.
    let m = match_task(&spec("hop forward", Some("biped"), None), &reg).unwrap();
    assert_eq!(m.entry.robot_type, "biped");
    let hopper = &m.alternatives[0];
    assert_eq!(
        (hopper.id.as_str(), hopper.score, hopper.excluded.as_deref()),
        (
            "mujoco-hopper",
            1.0,
            Some("its robot type is `custom`, not `biped`")
        )
    );
    assert_eq!(
        hopper.describe(2),
        "`mujoco-hopper` matches 2/2 task words (hop, forward) but its robot type is `custom`, not `biped`"
    );
    // Only entries the filters exclude carry a reason, and only ones clearly better.
    assert!(m.alternatives[1..].iter().all(|a| a.excluded.is_none()));
    let m = match_task(&spec("hop forward", Some("custom"), None), &reg).unwrap();
    assert_eq!(m.entry.id, "mujoco-hopper");
    assert!(m.alternatives.iter().all(|a| a.excluded.is_none()));
}

#[test]
fn no_match_under_the_filters_names_the_entry_they_exclude() {
    let reg = gymnasium_catalog();
    let err = match_task(&spec("one-legged robot hopping", Some("biped"), None), &reg)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains(
            "`mujoco-hopper` matches 2/2 task words (legged, hopping) but its robot type is `custom`, not `biped`"
        ),
        "{err}"
    );
    assert!(
        err.contains("hint: change or leave out the filter that excludes `mujoco-hopper`"),
        "{err}"
    );
}
