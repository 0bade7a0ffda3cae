"""The suites of the catalog (Meta-World, robosuite, dm_control, MyoSuite), each in its own
Python environment, provisioned from PyPI by envhub (`envhub env sync NAME`, uv).

- Each suite's entries name ids the suite has, checked in the suite's interpreter.
- Entries run bit for bit like the suite in-process in its own interpreter: a seeded reset,
  then a few hundred steps of fixed actions (observations, rewards, flags, infos; nested
  infos with their dtypes), compared with `suite_runs.native` run in that interpreter.
- One client process, whose interpreter has none of the suites' packages, opens a task of
  each suite and a native MuJoCo env at once, steps them all and closes them.

A suite whose environment cannot be built here (no network to PyPI, no uv) is skipped with
the reason; under ENVHUB_SUITES_REQUIRED=1 (as `make test` sets) that is a failure.
"""

from __future__ import annotations

import importlib.util
import json
import os
import pickle
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from harness import REPO_ROOT, SUPPORT, import_envhub, mujoco_or_skip

envhub = import_envhub()

import suite_runs  # noqa: E402
from suite_envs import suite_python  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_SUITES_REQUIRED"))
# robosuite and LIBERO render offscreen through EGL (a GPU's or Mesa's).
os.environ.setdefault("MUJOCO_GL", "egl")


@pytest.fixture(scope="module", autouse=True)
def libero_config(tmp_path_factory: pytest.TempPathFactory):
    """LIBERO's config in a temporary folder (its runs and workers inherit it) unless the user
    has one: a test run should not leave one in the home folder."""
    if os.environ.get("LIBERO_CONFIG_PATH") or os.path.isfile(os.path.expanduser("~/.libero/config.yaml")):
        yield
        return
    os.environ["LIBERO_CONFIG_PATH"] = str(tmp_path_factory.mktemp("libero-config"))
    yield
    del os.environ["LIBERO_CONFIG_PATH"]
RUN_TIMEOUT_S = 600

#: The Python environment (`python_envs:`) of each framework, and the module that says the
#: suite is present.
SUITES = {"metaworld": "metaworld", "robosuite": "robosuite", "dm_control": "dm_control", "myosuite": "myosuite"}


def registry_file() -> dict[str, Any]:
    with open(REPO_ROOT / "configs" / "env_registry.yaml", encoding="utf-8") as f:
        return yaml.safe_load(f)


REGISTRY = registry_file()
# LIBERO joins where the catalog gives it an environment of its own.
LIBERO_ENV = (REGISTRY.get("frameworks") or {}).get("libero", {}).get("python_env")
if LIBERO_ENV:
    SUITES["libero"] = LIBERO_ENV
ENTRIES = {e["id"]: e for e in REGISTRY["environments"] if e["framework"] in SUITES}


def case(entry_id: str, seed: int, steps: int) -> dict[str, Any]:
    e = ENTRIES[entry_id]
    return {
        "entry": entry_id,
        "framework": e["framework"],
        "env_id": e["env_id"],
        "kwargs": e.get("kwargs", {}),
        "seed": seed,
        "steps": steps,
    }


def native_run(c: dict[str, Any], tmp_path: Path) -> dict[str, Any]:
    """`c` run with the suite's own API in its own interpreter."""
    python = suite_python(SUITES[c["framework"]])
    out = tmp_path / f"{c['entry']}.pkl"
    done = subprocess.run(
        [python, str(SUPPORT / "suite_runs.py"), "native", json.dumps(c), str(out)],
        capture_output=True,
        text=True,
        timeout=RUN_TIMEOUT_S,
        env={**os.environ, "MUJOCO_GL": "egl", "PYOPENGL_PLATFORM": "egl"},
    )
    assert done.returncode == 0, f"the in-process run of {c['entry']} failed:\n{done.stderr[-4000:]}"
    with open(out, "rb") as f:
        return pickle.load(f)


# The suites' own ids ------------------------------------------------------------------------

#: The environment of a suite's interpreter run directly, with this envhub importable as its
#: workers have it (a venv holds the suite only; workers reach envhub through their install's
#: overlay).
WITH_ENVHUB = {**os.environ, "PYTHONPATH": str(Path(envhub.__file__).resolve().parent.parent)}

# In the suite's interpreter, with `entries` defined: prints the ids of entries it lacks.
CHECK_IDS = {
    "metaworld": "import metaworld; names = set(metaworld.ALL_V3_ENVIRONMENTS); "
    "print(json.dumps([e['id'] for e in entries if e['kwargs']['env_name'] not in names]))",
    "robosuite": "import robosuite; names = set(robosuite.ALL_ENVIRONMENTS); "
    "print(json.dumps([e['id'] for e in entries if e['env_id'] not in names]))",
    "dm_control": "import gymnasium as gym, shimmy; "
    "print(json.dumps([e['id'] for e in entries if e['env_id'] not in gym.registry]))",
    "myosuite": "import gymnasium as gym, myosuite; "
    "print(json.dumps([e['id'] for e in entries if e['env_id'] not in gym.registry]))",
    # LIBERO asks on stdin at its first import without a config: the adapter writes one first.
    "libero": "from envhub.worker.hosted.libero import ensure_config; ensure_config(); "
    "from libero.libero.benchmark.libero_suite_task_map import libero_task_map as m; "
    "print(json.dumps([e['id'] for e in entries if e['env_id'].partition('/')[0] not in m]))",
}


def test_catalog_has_the_suites():
    """At least 10 Meta-World MT1 tasks, 10 dm_control domain-task pairs, robosuite's Lift,
    Stack, Door, NutAssemblySquare, PickPlaceCan and a two-arm task, 4 MyoSuite tasks."""
    by = {f: [e for e in ENTRIES.values() if e["framework"] == f] for f in SUITES}
    assert len(by["metaworld"]) >= 10 and len(by["dm_control"]) >= 10 and len(by["myosuite"]) >= 4
    robosuite = {e["env_id"] for e in by["robosuite"]}
    assert {"Lift", "Stack", "Door", "NutAssemblySquare", "PickPlaceCan"} <= robosuite
    assert any(t.startswith("TwoArm") for t in robosuite)
    for framework, env in SUITES.items():
        assert REGISTRY["frameworks"][framework] == {"python_env": env}
        assert REGISTRY["python_envs"][env]["requirements"]


@pytest.mark.parametrize("framework", sorted(SUITES))
def test_entries_name_ids_the_suite_has(framework):
    python = suite_python(SUITES[framework])
    entries = [e for e in ENTRIES.values() if e["framework"] == framework]
    code = f"import json; entries = json.loads({json.dumps(json.dumps(entries))}); {CHECK_IDS[framework]}"
    done = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=RUN_TIMEOUT_S, env=WITH_ENVHUB)
    assert done.returncode == 0, done.stderr[-3000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []


@pytest.mark.parametrize("framework", sorted(SUITES))
def test_suite_runs_on_the_python_it_names(framework):
    """A suite's environment is based on the CPython its `python:` names (dm_control's is not
    the hub's 3.11: the worker's compiled module is built for the stable ABI)."""
    env = SUITES[framework]
    python = suite_python(env)
    code = "import sys, envhub._envhub; print('%d.%d' % sys.version_info[:2])"
    done = subprocess.run([python, "-c", code], capture_output=True, text=True, timeout=RUN_TIMEOUT_S, env=WITH_ENVHUB)
    assert done.returncode == 0, done.stderr[-3000:]
    want = REGISTRY["python_envs"][env].get("python")
    if want:
        assert done.stdout.strip() == want


@pytest.mark.parametrize(
    ("query", "expected"),
    [
        ("open a drawer with a Sawyer arm", "metaworld-drawer-open"),
        ("lift a cube with a Panda", "robosuite-lift"),
    ],
)
def test_match_finds_the_suites(query, expected):
    found = envhub.match_task_to_env(envhub.TaskSpec(task_description=query), strict=True)
    assert found.entry.id == expected, found.match_reason


# Bit for bit like the suite in-process -----------------------------------------------------

CASES = [
    case("metaworld-drawer-open", 7, 600),  # crosses Meta-World's 500-step limit
    case("metaworld-pick-place", 3, 300),
    case("metaworld-reach", 11, 300),
    case("dmc-cheetah-run", 7, 300),
    case("dmc-humanoid-walk", 5, 300),
    case("dmc-manipulator-bring-ball", 2, 300),
    case("myo-elbow-pose", 7, 300),  # 100-step episodes: three resets
    case("myo-hand-reach", 4, 250),
    case("robosuite-lift", 7, 200),
    case("robosuite-two-arm-lift", 3, 100),
    case("robosuite-lift-camera", 5, 30),
]



def libero_case(entry_id: str, seed: int, steps: int) -> dict[str, Any]:
    """LIBERO's task 0 of a suite from its fixed initial state 0, agentview and wrist images."""
    cameras = {"camera_heights": 64, "camera_widths": 64}
    return {**case(entry_id, seed, steps), "kwargs": cameras, "options": cameras, "init_state": 0}


if LIBERO_ENV:
    CASES += [libero_case("libero-spatial", 5, 40), libero_case("libero-goal", 2, 40)]


# slow (robosuite and LIBERO cases): each runs twice, in the suite's interpreter and through
# envhub, and each run builds the scene (robosuite's model compiled from XML, LIBERO's assets,
# cameras rendered offscreen); the step counts are the ones the comparisons need (resets
# and limits crossed, see CASES).
@pytest.mark.parametrize(
    "c",
    [pytest.param(c, marks=pytest.mark.slow) if c["framework"] in ("robosuite", "libero") else c for c in CASES],
    ids=[c["entry"] for c in CASES],
)
def test_entry_runs_bit_for_bit_like_the_suite(c, tmp_path):
    ref = native_run(c, tmp_path)
    got = suite_runs.envhub_run(c)
    values, diffs = suite_runs.compare(ref, got)
    assert not diffs, f"{c['entry']}: {len(diffs)} differences, first: {diffs[:5]}"
    assert len(got["reward"]) == c["steps"] and values > 0
    print(
        f"{c['entry']}: {c['steps']} steps, {len(ref['resets'])} resets, {values} observation values equal; "
        f"{c['steps'] / ref['seconds']:.0f} steps/s in-process, {c['steps'] / got['seconds']:.0f} through envhub"
    )


def hard_resets(suite: str, task: str, caching: str = "cached") -> dict[str, Any]:
    """tests/python/support/hard_resets.py's `task` in the interpreter of the catalog's Python
    environment `suite`, plain and with the caches (`caching`: `cached`, or `repeat` as LIBERO's
    adapter installs them): the same observations, camera images included."""
    python = suite_python(suite)
    runs = {}
    for name, mode in (("plain", "plain"), ("cached", caching)):
        done = subprocess.run(
            [python, str(SUPPORT / "hard_resets.py"), task, mode],
            capture_output=True,
            text=True,
            timeout=RUN_TIMEOUT_S,
            env=WITH_ENVHUB,
        )
        assert done.returncode == 0, f"{suite} {task}, {mode}: failed\n{done.stderr[-4000:]}"
        runs[name] = json.loads(done.stdout.strip().splitlines()[-1])
    assert runs["cached"]["digest"] == runs["plain"]["digest"], f"{suite} {task}: observations differ with the caches"
    return runs


# slow (this and the next two): robosuite's scene built, and its cameras rendered, at every
# reset of two runs.
@pytest.mark.slow
def test_robosuite_hard_resets_compile_a_repeated_scene_once():
    """robosuite 1.5 with the worker's caches against robosuite without them: over four resets
    of a scene that does not change, each XML compiled twice (met once, an XML is not kept),
    not five times; each camera rendered to learn its shape once, not 9 times; its render
    contexts are robosuite's own."""
    runs = hard_resets(SUITES["robosuite"], "stack")
    # robosuite.make builds the scene once and each of the 4 resets again: robot and scene.
    # Two cameras: one check each at the build, two each per reset; a frame each per reset
    # and step.
    assert runs["plain"] == {**runs["plain"], "contexts": 5, "compiles": 10, "renders": 2 + 4 * 4 + 16}
    assert runs["cached"] == {**runs["cached"], "contexts": 5, "compiles": 4, "renders": 2 + 16}


def libero_python() -> str:
    if not LIBERO_ENV:
        pytest.skip("the catalog names no Python environment for LIBERO")
    return LIBERO_ENV


@pytest.mark.slow
def test_libero_robosuite_hands_a_repeated_scenes_render_context_on():
    """robosuite 1.4 (LIBERO's interpreter) with the worker's caches as LIBERO's adapter
    installs them (every scene built again): over the build and four resets of a scene that
    does not change, its render context built once, not five times, and its cameras rendered
    for their shapes once (18 frames rendered, not 34). (The default, a context kept from a
    scene's second build on: `lift` below.)"""
    runs = hard_resets(libero_python(), "stack", caching="repeat")
    assert runs["plain"]["contexts"] == 5 and runs["cached"]["contexts"] == 1, runs
    assert runs["plain"]["renders"] == 34 and runs["cached"]["renders"] == 18, runs


@pytest.mark.slow
def test_render_contexts_dropped_from_the_pool_leave_the_others_whole():
    """Three scenes that repeat, interleaved, with a pool of two (robosuite 1.4): a context
    dropped is freed under its own GL context, and the images stay bit for bit (freed under
    the current one, MuJoCo would delete that one's textures: the images of its next use
    would differ)."""
    runs = hard_resets(libero_python(), "lift")
    assert runs["plain"]["contexts"] == 10 and runs["cached"]["contexts"] == 8, runs


def test_nested_infos_arrive_with_their_dtypes():
    """MyoSuite's infos: dicts of numpy arrays and scalars, as the suite gives them."""
    c = case("myo-elbow-pose", 1, 3)
    suite_python("myosuite")
    with envhub.make(c["entry"]) as env:
        _, info = env.reset(seed=1)
        _, _, _, _, info = env.step(env.action_space.sample())
    assert isinstance(info["obs_dict"], dict) and isinstance(info["rwd_dict"], dict)
    assert info["obs_dict"]["qpos"].dtype == np.float64 and info["obs_dict"]["qpos"].shape == (1,)
    assert isinstance(info["solved"], np.bool_) and isinstance(info["pose"], np.float64)


# One client, many interpreters -------------------------------------------------------------


# slow: five (six with LIBERO) workers in five interpreters start, each importing its suite;
# the 40 steps are few next to that.
@pytest.mark.slow
def test_one_client_opens_every_suite_and_a_native_env_at_once():
    """Meta-World, MyoSuite, dm_control, robosuite (and LIBERO, where the catalog has its
    environment) tasks and a native MuJoCo env, open together in this process, whose
    interpreter has none of the suites' packages."""
    for module in ("metaworld", "myosuite", "dm_control", "shimmy", "robosuite", "libero"):
        assert importlib.util.find_spec(module) is None, f"this test needs a client without `{module}`"
    for env in SUITES.values():
        suite_python(env)
    mujoco_or_skip(envhub)
    ids = ["metaworld-door-open", "myo-finger-reach", "dmc-walker-walk", "robosuite-door", "mujoco-ant"]
    options: dict[str, dict[str, Any]] = {}
    if LIBERO_ENV:
        ids.append("libero-object")
        options["libero-object"] = {"camera_heights": 32, "camera_widths": 32}
    envs = [envhub.make(i, **options.get(i, {})) for i in ids]
    try:
        for i, env in enumerate(envs):
            env.reset(seed=i)
        for t in range(40):
            for env in envs:
                space = env.action_space
                a = suite_runs.action(t, np.asarray(space.low), np.asarray(space.high), space.dtype)
                obs, reward, terminated, truncated, _ = env.step(a)
                # Shapes and keys, not bounds: Meta-World's observations leave its own space.
                if isinstance(obs, dict):
                    assert set(obs) == set(env.observation_space.spaces)
                else:
                    assert obs.shape == env.observation_space.shape and np.isfinite(obs).all()
                assert np.isfinite(reward)
                if terminated or truncated:
                    env.reset()
    finally:
        for env in envs:
            env.close()
