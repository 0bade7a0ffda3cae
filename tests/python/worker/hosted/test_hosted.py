"""Python-hosted adapters: the `gymnasium` adapter, availability of the others, user adapters,
and failures of a Python env (an exception, a killed worker)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap

import gymnasium
import numpy as np
import pytest
from harness import REPO_ROOT, SUPPORT, import_envhub

envhub = import_envhub()

REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: cp-native
        name: CartPole native
        framework: gymnasium
        env_id: CartPole-v1
        robot_type: custom
        env_type: floor
      - id: cp-python
        name: CartPole through Python
        framework: gymnasium
        env_id: CartPole-v1
        adapter: gymnasium
        robot_type: custom
        env_type: floor
      - id: cp-python-short
        name: CartPole through Python, 5 steps
        framework: gym
        env_id: CartPole-v1
        adapter: gymnasium
        max_episode_steps: 5
        robot_type: custom
        env_type: floor
      - id: lunar-continuous
        name: LunarLander continuous
        framework: gymnasium
        env_id: LunarLander-v3
        kwargs: {continuous: true}
        robot_type: custom
        env_type: floor
      - id: point-maze
        name: PointMaze
        framework: gymnasium
        env_id: PointMaze_UMaze-v3
        robot_type: custom
        env_type: maze
      - id: fetch-reach
        name: Fetch reach
        framework: gymnasium
        env_id: FetchReach-v4
        robot_type: arm
        env_type: tabletop
      - id: mani-pick
        name: ManiSkill pick cube
        framework: mani_skill
        env_id: PickCube-v1
        robot_type: arm
        env_type: tabletop
      - id: libero-10
        name: LIBERO 10, task 0
        framework: libero
        env_id: libero_10/0
        robot_type: arm
        env_type: tabletop
      - id: isaac-cartpole
        name: Isaac cartpole
        framework: isaaclab
        env_id: Isaac-Cartpole-v0
        robot_type: custom
        env_type: floor
      - id: mysim-echo
        name: My simulator echo
        framework: mysim
        env_id: Echo-v0
        robot_type: custom
        env_type: floor
        task_tags: [echo, test]
        description: Echoes its config.
        kwargs: {gain: 2}
      - id: keeps-actions
        name: Keeps its actions
        framework: keepsim
        env_id: Keep-v0
        robot_type: custom
        env_type: floor
      - id: missing-dep
        name: Needs a missing module
        framework: needs_missing
        env_id: Missing-v0
        robot_type: custom
        env_type: floor
    """
)


@pytest.fixture(scope="module")
def registry(tmp_path_factory: pytest.TempPathFactory) -> str:
    path = tmp_path_factory.mktemp("hosted") / "registry.yaml"
    path.write_text(REGISTRY)
    return str(path)


@pytest.fixture(scope="module")
def user_adapters() -> None:
    import hosted_adapters

    reg = envhub.AdapterRegistry()
    reg.register(hosted_adapters.MySimAdapter)
    reg.register(hosted_adapters.MissingDepAdapter)
    reg.register(hosted_adapters.KeepsActionsAdapter)


def test_cartpole_native_and_python_hosted_agree(registry):
    native = envhub.make_vec("cp-native", 4, registry=registry)
    hosted = envhub.make_vec("cp-python", 4, registry=registry, num_workers=2)
    try:
        o1, _ = native.reset(seed=11)
        o2, _ = hosted.reset(seed=11)
        np.testing.assert_allclose(o1, o2, rtol=0, atol=1e-6)
        rng = np.random.default_rng(0)
        for _ in range(300):
            a = rng.integers(0, 2, size=4)
            s1 = native.step(a)
            s2 = hosted.step(a)
            np.testing.assert_allclose(s1[0], s2[0], rtol=0, atol=1e-5)
            for k in (1, 2, 3):
                np.testing.assert_array_equal(s1[k], s2[k])
    finally:
        native.close()
        hosted.close()


def test_render_fps_of_python_hosted_envs(registry, user_adapters):
    """A Python-hosted env's `metadata["render_fps"]` reaches the client (from the worker's
    ready line); an env that declares none has no `render_fps`."""
    want = gymnasium.make("CartPole-v1").metadata["render_fps"]
    env = envhub.make("cp-python", registry=registry)
    try:
        assert env.metadata["render_fps"] == want
    finally:
        env.close()
    envs = envhub.make_vec("cp-python", 4, registry=registry, num_workers=2)
    try:
        assert envs.metadata["render_fps"] == want
    finally:
        envs.close()
    env = envhub.make("mysim-echo", registry=registry)
    try:
        assert "render_fps" not in env.metadata
    finally:
        env.close()


def test_max_episode_steps_from_the_entry(registry):
    env = envhub.make("cp-python-short", registry=registry)
    try:
        env.reset(seed=0)
        truncated = [env.step(i % 2)[3] for i in range(5)]
        assert truncated == [False] * 4 + [True]
    finally:
        env.close()


def test_lunar_lander_continuous_kwargs(registry):
    env = envhub.make("lunar-continuous", registry=registry)
    try:
        assert env.action_space.shape == (2,)
        obs, _ = env.reset(seed=1)
        assert obs.shape == (8,)
        obs, reward, *_ = env.step(np.zeros(2, np.float32))
        assert np.isfinite(reward)
    finally:
        env.close()


def test_gymnasium_robotics_dict_observations(registry):
    pytest.importorskip("gymnasium_robotics")
    env = envhub.make("point-maze", registry=registry)
    try:
        obs, _ = env.reset(seed=3)
        assert set(obs) == {"observation", "achieved_goal", "desired_goal"}
        assert obs["observation"].shape == (4,)
        obs, *_ = env.step(env.action_space.sample())
        assert obs["desired_goal"].shape == (2,)
    finally:
        env.close()


def test_fetch_matches_gymnasium_robotics_in_process(registry):
    """Fetch (gymnasium-robotics 1.4.2 under mujoco 3.17, with `robotics_compat`): the same
    seed and actions give the same Dict observations and rewards as the env made here."""
    pytest.importorskip("gymnasium_robotics")
    import gymnasium_robotics
    from envhub.worker.hosted import robotics_compat

    gymnasium.register_envs(gymnasium_robotics)
    robotics_compat.apply()
    ours, ref = envhub.make("fetch-reach", registry=registry), gymnasium.make("FetchReach-v4")
    try:
        ref.action_space.seed(2)
        o1, _ = ours.reset(seed=0)
        o2, _ = ref.reset(seed=0)
        for step in range(60):
            for key in ("observation", "achieved_goal", "desired_goal"):
                np.testing.assert_array_equal(o1[key], o2[key], err_msg=f"{key} at step {step}")
            a = ref.action_space.sample()
            (o1, r1, t1, u1, _), (o2, r2, t2, u2, _) = ours.step(a), ref.step(a)
            assert (r1, t1, u1) == (r2, t2, u2)
    finally:
        ours.close()
        ref.close()


def test_robotics_compat_is_scoped_and_idempotent():
    """The fix touches only gymnasium-robotics' `mujoco_utils`, and only where needed."""
    pytest.importorskip("gymnasium_robotics")
    import mujoco
    from envhub.worker.hosted import robotics_compat
    from gymnasium_robotics.utils import mujoco_utils

    needed = robotics_compat.apply()
    assert robotics_compat.apply() == needed
    hinge = np.int32(int(mujoco.mjtJoint.mjJNT_HINGE))
    assert hinge in (mujoco_utils.mujoco.mjtJoint.mjJNT_HINGE, mujoco_utils.mujoco.mjtJoint.mjJNT_SLIDE)
    assert mujoco_utils.mujoco.mj_name2id is mujoco.mj_name2id


@pytest.mark.parametrize(
    ("adapter", "entry", "module"),
    [("maniskill", "mani-pick", "mani_skill"), ("libero", "libero-10", "libero"), ("isaac_lab", "isaac-cartpole", "isaaclab")],
)
def test_unavailable_when_dependencies_are_missing(registry, adapter, entry, module):
    info = envhub.AdapterRegistry().get(adapter)
    assert info["host"] == "python"
    if info["available"]:
        pytest.skip(f"{adapter} is installed here")
    assert module in info["reason"] or "GPU" in info["reason"], info
    assert "pip install" in info["hint"] or "GPU" in info["hint"], info
    with pytest.raises(envhub.AdapterUnavailableError) as caught:
        envhub.make(entry, registry=registry)
    assert info["hint"] in str(caught.value)


# User adapters ----------------------------------------------------------------------------


def test_registry_loads_and_search_returns_the_user_entry(registry):
    reg = envhub.EnvRegistry(registry)
    entry = reg.get("mysim-echo")
    assert entry.framework == "mysim"
    hits = reg.search(framework="mysim")
    assert [e.id for e in hits] == ["mysim-echo"]


def test_user_adapter_unavailable_when_its_dependency_is_missing(registry, user_adapters):
    info = envhub.AdapterRegistry().get("needs_missing")
    assert not info["available"]
    assert "envhub_no_such_module_xyz" in info["reason"]
    assert info["hint"] == "pip install envhub-no-such-module-xyz"
    with pytest.raises(envhub.AdapterUnavailableError):
        envhub.make("missing-dep", registry=registry)


def test_user_adapter_make_receives_the_config_unchanged(registry, user_adapters, tmp_path):
    env = envhub.make(
        "mysim-echo",
        registry=registry,
        seed=7,
        render_mode="rgb_array",
        max_episode_steps=9,
        asset_path=str(tmp_path),
        scale=0.5,
    )
    try:
        obs, info = env.reset()
        assert info["seed"] == 7
        assert info["render_mode"] == "rgb_array"
        assert info["max_episode_steps"] == 9
        assert info["num_envs"] == 1
        assert info["asset_path"] == str(tmp_path)
        assert info["extra"] == repr([("gain", 2), ("scale", 0.5)])
        obs, reward, terminated, truncated, _ = env.step(np.array([0.5], np.float32))
        np.testing.assert_allclose(obs, [1.0, 0.5])
        assert reward == 1.0 and not terminated and not truncated
    finally:
        env.close()


def test_an_env_that_keeps_its_actions_reads_them_back_unchanged(registry, user_adapters):
    """The worker gives each env its own action array: one the env keeps still holds that
    action after later requests have reused the shared-memory sample it arrived in."""
    import hosted_adapters

    lag = hosted_adapters.KeepsActionsEnv.LAG
    envs = envhub.make_vec("keeps-actions", 2, num_workers=1, registry=registry)
    try:
        envs.reset(seed=0)
        sent = []
        for t in range(1, 41):
            actions = np.array([[t / 100], [-t / 100]], np.float32)
            sent.append(actions.copy())
            obs, *_ = envs.step(actions)
            assert obs[:, 0].tolist() == [t, t], obs
            if t > lag:
                np.testing.assert_array_equal(obs[:, 1], sent[t - 1 - lag][:, 0], err_msg=f"step {t}")
    finally:
        envs.close()


def test_python_exception_names_the_env_with_the_traceback(registry, user_adapters):
    env = envhub.make("mysim-echo", registry=registry)
    try:
        env.reset(seed=0)
        with pytest.raises(envhub.EnvFailedError) as caught:
            env.step(np.array([1.0], np.float32))
        text = str(caught.value)
        assert "Echo-v0" in text and "Traceback" in text and "boom: action above 0.99" in text, text
    finally:
        env.close()
    # The hub carries on.
    env = envhub.make("cp-python", registry=registry)
    env.reset(seed=0)
    env.step(0)
    env.close()


def test_killed_python_worker_is_worker_died(registry):
    env = envhub.make("cp-python", registry=registry)
    try:
        env.reset(seed=0)
        os.kill(env.worker_pid, signal.SIGKILL)
        with pytest.raises(envhub.WorkerDiedError):
            env.step(0)
    finally:
        env.close()


def test_adapters_from_the_hub_config(registry, tmp_path):
    """`adapters:` in envhub.yaml makes a user adapter permanent (a fresh process)."""
    (tmp_path / "envhub.yaml").write_text("adapters: [hosted_adapters:MySimAdapter]\n")
    script = textwrap.dedent(
        f"""\
        import numpy as np, envhub
        env = envhub.make("mysim-echo", registry={registry!r})
        env.reset(seed=0)
        obs, *_ = env.step(np.array([0.25], np.float32))
        assert abs(obs[1] - 0.25) < 1e-6, obs
        assert envhub.AdapterRegistry().get("mysim")["available"]
        env.close()
        print("ok")
        """
    )
    env = dict(os.environ)
    env.pop("ENVHUB_ADAPTERS", None)
    env["ENVHUB_CONFIG"] = str(tmp_path / "envhub.yaml")
    env["PYTHONPATH"] = os.pathsep.join([str(SUPPORT), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=120, cwd=REPO_ROOT)
    assert out.returncode == 0 and "ok" in out.stdout, out.stderr
