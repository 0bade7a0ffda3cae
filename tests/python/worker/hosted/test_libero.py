"""The `libero` adapter.

Everywhere: how env ids and the `task` option pick a suite's task, the catalog's LIBERO
entries, the Gymnasium spaces built from an observation dict, and the adapter's verdict on
this interpreter (what is missing and the fix).

Where LIBERO's code is installed (`make libero` builds .venv-libero; run this file with that
interpreter): the task names and suites against LIBERO's own, its first-import question
answered by the adapter's config file, and the spaces of a real robosuite observation.

Where the adapter is available (LIBERO, robosuite 1.4 and the scene assets): task 0 of each
of the five suites through envhub equals LIBERO's `OffScreenRenderEnv` stepped in this
process from the same initial state with the same actions, bit for bit. Skipped with the
reason otherwise; failed instead under ENVHUB_LIBERO_REQUIRED=1 (as `make py-test` sets when
.venv-libero exists), so an installed LIBERO cannot pass silently.
"""

from __future__ import annotations

import importlib.util
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import yaml
from harness import REPO_ROOT, import_envhub

envhub = import_envhub()

from envhub.worker.hosted import libero as adapter  # noqa: E402
from envhub.worker.hosted.libero_spec import (  # noqa: E402
    action_space,
    observation_space,
    outside,
    split_env_id,
    task_index,
)

# LIBERO's five suites (`libero_task_map`), 10 tasks each but libero_90's 90.
SUITES = {"libero_spatial": 10, "libero_object": 10, "libero_goal": 10, "libero_10": 10, "libero_90": 90}
REQUIRED = bool(os.environ.get("ENVHUB_LIBERO_REQUIRED"))
# robosuite renders offscreen through EGL (Mesa's or a GPU's), as the adapter sets in its workers.
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
HAS_LIBERO_CODE = importlib.util.find_spec("libero") is not None and importlib.util.find_spec("robosuite") is not None


def catalog() -> list[dict]:
    with open(REPO_ROOT / "configs" / "env_registry.yaml", encoding="utf-8") as f:
        return [e for e in yaml.safe_load(f)["environments"] if e["framework"] == "libero"]


@pytest.fixture(scope="module", autouse=True)
def libero_config(tmp_path_factory: pytest.TempPathFactory):
    """LIBERO's config in a temporary folder (the workers inherit it) unless one exists: the
    adapter writes it where missing, and a test run should not leave one in the home folder."""
    if os.path.isfile(adapter._config_file()):
        yield
        return
    os.environ["LIBERO_CONFIG_PATH"] = str(tmp_path_factory.mktemp("libero-config"))
    yield
    del os.environ["LIBERO_CONFIG_PATH"]


def skip_or_fail(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_LIBERO_REQUIRED is set")
    pytest.skip(reason)


# Env ids and the `task` option --------------------------------------------------------------


@pytest.mark.parametrize(
    ("env_id", "extra", "expected"),
    [
        ("libero_10", {}, ("libero_10", 0)),
        ("libero_10", {"task": 4}, ("libero_10", 4)),
        ("libero_10", {"task": "7"}, ("libero_10", 7)),
        ("libero_goal", {"task": "open_the_middle_drawer_of_the_cabinet"}, ("libero_goal", "open_the_middle_drawer_of_the_cabinet")),
        ("libero_10/3", {}, ("libero_10", 3)),
        ("libero_10/3", {"task": 3}, ("libero_10", 3)),
        ("libero_object/pick_up_the_ketchup_and_place_it_in_the_basket", {}, ("libero_object", "pick_up_the_ketchup_and_place_it_in_the_basket")),
    ],
)
def test_env_id_names_a_suite_and_a_task(env_id, extra, expected):
    assert split_env_id(env_id, extra) == expected


@pytest.mark.parametrize(
    ("env_id", "extra", "error", "says"),
    [
        ("libero_10/3", {"task": 4}, ValueError, "name the task in one place only"),
        ("libero_10/", {}, LookupError, "`<suite>/<task index or name>`"),
        ("/3", {}, LookupError, "invalid LIBERO env id"),
        ("libero_10", {"task": True}, TypeError, "a task index or name"),
        ("libero_10", {"task": [1]}, TypeError, "a task index or name"),
    ],
)
def test_env_id_errors_say_how_to_write_it(env_id, extra, error, says):
    with pytest.raises(error) as caught:
        split_env_id(env_id, extra)
    assert says in str(caught.value)


TASKS = {
    "libero_spatial": ["pick_up_the_black_bowl_next_to_the_ramekin_and_place_it_on_the_plate", "pick_up_the_black_bowl_on_the_stove_and_place_it_on_the_plate"],
    "libero_goal": ["open_the_middle_drawer_of_the_cabinet", "turn_on_the_stove"],
}


def test_task_index_by_index_and_name():
    assert task_index("libero_goal", 1, TASKS) == 1
    assert task_index("libero_goal", "open_the_middle_drawer_of_the_cabinet", TASKS) == 0


def test_wrong_suite_names_the_closest_and_all():
    with pytest.raises(LookupError) as caught:
        task_index("libero_spacial", 0, TASKS)
    text = str(caught.value)
    assert "no suite `libero_spacial`; did you mean `libero_spatial`?" in text
    assert "suites: libero_spatial, libero_goal" in text


def test_wrong_task_names_the_closest_and_lists_the_tasks():
    with pytest.raises(LookupError) as caught:
        task_index("libero_goal", "turn_on_the_stoves", TASKS)
    text = str(caught.value)
    assert "did you mean `turn_on_the_stove`?" in text
    assert "0: open_the_middle_drawer_of_the_cabinet" in text and "1: turn_on_the_stove" in text
    with pytest.raises(LookupError, match=r"no task 2\nhint: tasks are 0\.\.1"):
        task_index("libero_goal", 2, TASKS)


@pytest.mark.parametrize("entry", catalog(), ids=lambda e: e["id"])
def test_catalog_entries_name_a_suite_whose_task_0_is_the_default(entry):
    suite, task = split_env_id(entry["env_id"], entry.get("kwargs") or {})
    assert suite in SUITES and task == 0
    assert entry["obs_type"] == "state+image"
    assert entry["max_episode_steps"] == 600


def test_catalog_has_every_suite():
    # LIBERO-PRO's entries (its own Python environment) run the same suites perturbed.
    assert sorted({split_env_id(e["env_id"], {})[0] for e in catalog()}) == sorted(SUITES)


# Spaces ------------------------------------------------------------------------------------


def robosuite_shaped_obs() -> dict:
    """Values of the types and shapes robosuite gives (not a simulator: a dict of arrays, for
    the space-building rules only)."""
    rng = np.random.default_rng(0)
    return {
        "robot0_joint_pos_cos": np.cos(rng.normal(size=7)),
        "robot0_joint_pos_sin": np.sin(rng.normal(size=7)),
        "robot0_eef_pos": rng.normal(size=3),
        "robot0_eef_quat": np.array([0.0, 0.0, 0.0, 1.0]),
        "agentview_image": rng.integers(0, 256, (32, 24, 3), dtype=np.uint8),
        "agentview_depth": rng.uniform(0, 1, (32, 24, 1)).astype(np.float32),
        "agentview_segmentation_instance": rng.integers(0, 9, (32, 24, 1), dtype=np.int32),
        "robot0_proprio-state": rng.normal(size=39),
    }


def test_spaces_are_ones_gymnasium_accepts():
    import gymnasium as gym
    from gymnasium.utils import passive_env_checker

    obs = robosuite_shaped_obs()
    space = observation_space(obs)
    passive_env_checker.check_observation_space(space)
    assert space["agentview_image"] == gym.spaces.Box(0, 255, (32, 24, 3), np.uint8)
    assert space["agentview_depth"] == gym.spaces.Box(0.0, 1.0, (32, 24, 1), np.float32)
    assert space["robot0_eef_quat"] == gym.spaces.Box(-1.0, 1.0, (4,), np.float64)
    assert space["robot0_joint_pos_cos"] == gym.spaces.Box(-1.0, 1.0, (7,), np.float64)
    assert space["robot0_eef_pos"] == gym.spaces.Box(-np.inf, np.inf, (3,), np.float64)
    info = np.iinfo(np.int32)
    assert space["agentview_segmentation_instance"] == gym.spaces.Box(info.min, info.max, (32, 24, 1), np.int32)
    assert outside(space, obs) == []
    assert space.contains(obs)
    # and envhub carries every part of it
    from envhub.wire.spaces import from_gymnasium

    assert sorted(k for k, _ in from_gymnasium(space)["spaces"]) == sorted(obs)


def test_the_old_space_is_what_gymnasium_refused():
    """The space the adapter used to build (uint8 with infinite bounds) is an error in Gymnasium."""
    import gymnasium as gym

    with pytest.raises(ValueError):
        gym.spaces.Box(-np.inf, np.inf, (4, 4, 3), np.uint8)


def test_a_value_outside_its_space_is_named():
    obs = robosuite_shaped_obs()
    space = observation_space(obs)
    obs["robot0_eef_quat"] = np.array([0.0, 0.0, 0.0, 2.0])
    assert outside(space, obs) == ["robot0_eef_quat"]


def test_action_space_is_robosuites_limits_as_float32():
    import gymnasium as gym

    assert action_space(-np.ones(7), np.ones(7)) == gym.spaces.Box(-1.0, 1.0, (7,), np.float32)


def test_render_mode_is_refused_with_where_the_images_are():
    with pytest.raises(ValueError, match="render into the observation, `<camera>_image`"):
        adapter.LiberoAdapter().make("libero_10", envhub.EnvConfig(render_mode="rgb_array"))


# This interpreter's verdict ----------------------------------------------------------------


def test_availability_names_what_is_missing_and_the_fix():
    ok, reason, hint = adapter.LiberoAdapter().availability()
    info = envhub.AdapterRegistry().get("libero")
    assert info["available"] == ok
    if ok:
        return
    assert reason == info["reason"] and hint == info["hint"]
    if not HAS_LIBERO_CODE:
        assert "`libero`" in reason and "make libero" in hint and "pip install" in hint
    elif "robosuite" in reason and "1.4" in reason:
        assert "make libero" in hint
    else:
        assert "scene assets are not installed" in reason and adapter.ASSET_MARKER in reason
        assert "download_assets()" in hint and "huggingface.co" in hint
    with open(REPO_ROOT / "configs" / "env_registry.yaml", encoding="utf-8") as f:
        frameworks = yaml.safe_load(f).get("frameworks") or {}
    if "libero" in frameworks:
        # The catalog runs LIBERO in a Python environment of its own (pyenv/test_suites.py runs
        # it there): making an entry does not depend on this interpreter.
        return
    with pytest.raises(envhub.AdapterUnavailableError) as caught:
        envhub.make("libero-spatial")
    assert hint in str(caught.value)


# LIBERO's code (no assets needed) ----------------------------------------------------------


def _libero_code() -> None:
    if not HAS_LIBERO_CODE:
        skip_or_fail(f"LIBERO is not installed for {sys.executable} (`make libero` builds .venv-libero)")


def test_suites_and_tasks_are_liberos_own():
    _libero_code()
    adapter.ensure_config()
    from libero.libero import benchmark
    from libero.libero.benchmark.libero_suite_task_map import libero_task_map

    assert {s: len(t) for s, t in libero_task_map.items()} == SUITES
    for suite in SUITES:
        tasks = benchmark.get_benchmark(suite)()
        assert tasks.get_task_names() == libero_task_map[suite]  # task order 0 is the map's order
        assert os.path.isfile(tasks.get_task_bddl_file_path(0))
    name = libero_task_map["libero_10"][5]
    assert task_index(*split_env_id(f"libero_10/{name}", {}), libero_task_map) == 5


def test_first_import_asks_nothing(tmp_path):
    """LIBERO asks on stdin where its files go on first import; the adapter writes LIBERO's
    defaults first, so a worker (no terminal) imports it."""
    _libero_code()
    code = textwrap.dedent(
        """
        from envhub.worker.hosted.libero import ensure_config
        path = ensure_config()
        from libero.libero import get_libero_path
        import os
        print(path, os.path.isdir(get_libero_path("bddl_files")), os.path.isdir(get_libero_path("init_states")))
        """
    )
    env = {**os.environ, "LIBERO_CONFIG_PATH": str(tmp_path / "libero")}
    done = subprocess.run([sys.executable, "-c", code], env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split()[-3:] == [str(tmp_path / "libero" / "config.yaml"), "True", "True"]


def test_spaces_of_a_real_robosuite_observation():
    """robosuite's own `Lift` (its assets ship with it), rendered offscreen like LIBERO's envs."""
    _libero_code()
    import robosuite

    env = robosuite.make(
        "Lift",
        robots="Panda",
        has_renderer=False,
        has_offscreen_renderer=True,
        use_camera_obs=True,
        camera_names=["agentview", "robot0_eye_in_hand"],
        camera_heights=32,
        camera_widths=32,
    )
    obs = env.reset()
    space = observation_space(obs)
    assert space["agentview_image"].dtype == np.uint8 and space["agentview_image"].shape == (32, 32, 3)
    assert obs["agentview_image"].std() > 0  # something was rendered
    assert outside(space, obs) == []
    for _ in range(5):
        obs, _, _, _ = env.step(np.zeros(env.action_dim))
        assert outside(space, obs) == []
    assert action_space(*env.action_spec).shape == (env.action_dim,)


# Real LIBERO through envhub ----------------------------------------------------------------


@pytest.fixture(scope="module")
def libero_ready() -> None:
    _libero_code()
    info = envhub.AdapterRegistry().get("libero")
    if not info["available"]:
        skip_or_fail(f"the libero adapter is unavailable: {info['reason']} (hint: {info['hint']})")


CAMERA = {"camera_heights": 64, "camera_widths": 64}
STEPS = 20


def reference(suite: str, task: int):
    """LIBERO's own env for `suite`'s task `task`, as the adapter makes it (assets where the
    adapter finds them)."""
    adapter.use_assets()
    from libero.libero import benchmark
    from libero.libero.envs import OffScreenRenderEnv

    tasks = benchmark.get_benchmark(suite)()
    # The adapter's env starts each episode on a LIBERO env built for it (`FreshScenes`: its
    # kitchens keep state across resets), as this one is: made, then seeded and reset.
    env = OffScreenRenderEnv(bddl_file_name=tasks.get_task_bddl_file_path(task), ignore_done=True, **CAMERA)
    return env, tasks.get_task_init_states(task)


@pytest.mark.parametrize("entry", catalog(), ids=lambda e: e["id"])
def test_matches_libero_in_process(libero_ready, entry):
    suite = entry["env_id"]
    ours = envhub.make(entry["id"], **CAMERA)
    ref, init_states = reference(suite, 0)
    try:
        obs, info = ours.reset(seed=5, options={"init_state": 0})
        ref.seed(5)
        ref.reset()
        ref_obs = ref.set_init_state(init_states[0])
        assert info["task"] == entry_task_name(suite) and info["init_state"] == 0
        assert ours.observation_space.contains(obs)
        for k in ours.observation_space.spaces:
            np.testing.assert_array_equal(obs[k], ref_obs[k], err_msg=f"reset, key {k}")
        rng = np.random.default_rng(1)
        for t in range(STEPS):
            a = rng.uniform(-1, 1, ours.action_space.shape).astype(np.float32)
            obs, reward, terminated, truncated, _ = ours.step(a)
            ref_obs, ref_reward, ref_done, _ = ref.step(a.astype(np.float64))
            assert (reward, terminated, truncated) == (float(ref_reward), bool(ref_done), False), f"step {t}"
            for k in ours.observation_space.spaces:
                np.testing.assert_array_equal(obs[k], ref_obs[k], err_msg=f"step {t}, key {k}")
    finally:
        ours.close()
        ref.close()


def entry_task_name(suite: str) -> str:
    from libero.libero.benchmark.libero_suite_task_map import libero_task_map

    return libero_task_map[suite][0]


def test_task_option_and_init_state_errors(libero_ready):
    with pytest.raises(envhub.EnvHubError, match="did you mean"):
        envhub.make("libero-goal", task="turn_on_the_stoves", **CAMERA)
    env = envhub.make("libero-goal", task="turn_on_the_stove", **CAMERA)
    try:
        _, info = env.reset(seed=0)
        assert info["task"] == "turn_on_the_stove" and "init_state" not in info
        with pytest.raises(envhub.EnvHubError, match="init_state"):
            env.reset(options={"init_state": 10_000})
    finally:
        env.close()
