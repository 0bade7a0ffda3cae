"""The RoboSmith-style API of the `envhub` package: registry, search, task matching, config,
adapters (real registry files, the real worker binary for the adapter catalog)."""

from __future__ import annotations

import pytest
from harness import REPO_ROOT, import_envhub

envhub = import_envhub()


def test_registry_lists_and_gets_entries():
    reg = envhub.EnvRegistry()
    assert len(reg) >= 45
    entry = reg.get("gym-cartpole")
    assert isinstance(entry, envhub.EnvEntry)
    assert (entry.framework, entry.env_id, entry.action_type) == ("gymnasium", "CartPole-v1", "discrete")
    assert "balance" in entry.task_tags
    assert entry.id in reg and entry in reg.list_all()
    assert reg.list_ids()[: len(reg.list_ids())] == [e.id for e in reg]
    assert "gymnasium" in reg.list_frameworks()
    assert "quadruped" in reg.list_robot_types()
    assert entry.to_dict()["env_id"] == "CartPole-v1"


def test_unknown_id_is_a_key_error_with_suggestions():
    reg = envhub.EnvRegistry()
    with pytest.raises(KeyError) as caught:
        reg.get("gym-cartpol")
    err = caught.value
    assert isinstance(err, envhub.UnknownEnvError) and isinstance(err, envhub.EnvHubError)
    assert "gym-cartpole" in err.suggestions
    assert "did you mean `gym-cartpole`" in str(err)
    assert str(err).startswith("unknown environment id")  # not quoted as KeyError would


def test_search_filters_like_robosmith():
    reg = envhub.EnvRegistry()
    quads = reg.search(robot_type="quad")
    assert quads and all(e.robot_type == "quadruped" for e in quads)
    gym = reg.search(framework="gym")
    assert gym and all(e.framework == "gymnasium" for e in gym)
    hits = reg.search(tags=["balance", "pole"])
    assert hits[0].id == "gym-cartpole"
    assert reg.search(robot_type="no-such-robot") == []


def test_custom_registry_file(null_registry):
    reg = envhub.EnvRegistry(null_registry)
    assert reg.list_ids() == ["null-env"]
    both = envhub.EnvRegistry(["@default", null_registry])
    assert "null-env" in both and "gym-cartpole" in both


def test_malformed_registry_names_file_and_line(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("environments:\n  - id: x\n    name: X\n    framwork: gymnasium\n")
    with pytest.raises(envhub.RegistryError) as caught:
        envhub.EnvRegistry(str(bad))
    assert isinstance(caught.value, ValueError)
    assert "bad.yaml:" in str(caught.value) and "framwork" in str(caught.value)


def test_match_task_to_env():
    reg = envhub.EnvRegistry()
    found = envhub.match_task_to_env(envhub.TaskSpec("balance a pole on a cart"), reg)
    assert found.entry.id == "gym-cartpole"
    assert 0 < found.score <= 1 and "balance" in found.match_reason
    explicit = envhub.match_task_to_env(envhub.TaskSpec("anything", environment_id="gym-pendulum"), reg)
    assert explicit.entry.id == "gym-pendulum" and explicit.score == 1.0
    # As RoboSmith: no match is `None`; `strict=True` says why.
    reef = envhub.TaskSpec("a submarine explores a coral reef")
    assert envhub.match_task_to_env(reef, reg) is None
    with pytest.raises(envhub.NoMatchError) as caught:
        envhub.match_task_to_env(reef, reg, strict=True)
    assert isinstance(caught.value, LookupError) and "hint:" in str(caught.value)
    assert envhub.match_task_to_env(envhub.TaskSpec("balance a pole"), reg, framework="isaac_lab").entry.id == "isaac-cartpole"



def test_match_names_a_better_entry_the_robot_type_excludes():
    """The registry types Hopper `custom`: a biped hopping task says so."""
    reg = envhub.EnvRegistry()
    found = envhub.match_task_to_env(envhub.TaskSpec("hop forward", robot_type="biped"), reg)
    assert found.entry.robot_type == "biped"
    hopper = found.alternatives[0]
    assert hopper["id"] == "mujoco-hopper" and hopper["score"] == 1.0
    assert hopper["excluded"] == "its robot type is `custom`, not `biped`"
    # dm_control's hopper (also typed `custom`) may follow, excluded for the same reason.
    assert all(a.get("excluded", hopper["excluded"]) == hopper["excluded"] for a in found.alternatives[1:])
    with pytest.raises(envhub.NoMatchError) as caught:
        envhub.match_task_to_env(envhub.TaskSpec("one-legged robot hopping", robot_type="biped"), reg, strict=True)
    assert "`mujoco-hopper` matches 2/2 task words (legged, hopping) but its robot type is `custom`" in str(caught.value)

def test_env_config_fields():
    cfg = envhub.EnvConfig(seed=3, max_episode_steps=50, extra={"g": 9.81})
    assert (cfg.render_mode, cfg.num_envs, cfg.asset_path, cfg.workers) == (None, 1, None, None)
    assert '"g": 9.81' in cfg.to_json()


def test_adapter_registry():
    adapters = envhub.AdapterRegistry()
    assert "classic_control" in adapters.list_available()
    every = {a["name"]: a for a in adapters.list_all()}
    classic = every["classic_control"]
    assert classic["available"] and "gymnasium" in classic["frameworks"] and "CartPole-v1" in classic["envs"]
    assert set(classic) >= {"name", "frameworks", "available", "requires", "description", "reason"}
    for a in every.values():
        if not a["available"]:
            assert a["reason"] and a["hint"], a


def test_make_env_from_an_entry(null_registry):
    reg = envhub.EnvRegistry(null_registry)
    env = envhub.make_env(reg.get("null-env"), seed=1)
    try:
        obs, _ = env.reset()
        assert obs.shape == (4,)
    finally:
        env.close()
    env = envhub.make_env("gym-pendulum", max_episode_steps=5, g=9.81)
    try:
        env.reset(seed=0)
        steps = 0
        while True:
            steps += 1
            *_, terminated, truncated, _ = env.step(env.action_space.sample())
            if terminated or truncated:
                break
        assert steps == 5
    finally:
        env.close()


def test_worker_binary_is_found():
    path = envhub.worker_binary()
    assert path.endswith("envhub-worker")
    assert REPO_ROOT.joinpath("python").exists()
