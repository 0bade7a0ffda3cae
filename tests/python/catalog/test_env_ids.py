"""Checks that every entry of `configs/env_registry.yaml` names an environment that exists.

Each framework is checked only where it is installed; otherwise its entries are skipped with
the reason. One test per entry (`pytest -k mujoco-ant` runs one), so a wrong id names itself.

- gymnasium:   `gymnasium.spec(env_id)`, with gymnasium_robotics registered when importable
- maniskill:   `import mani_skill.envs`, then `gymnasium.spec(env_id)`
- libero:      `env_id` (`<suite>` or `<suite>/<task>`) names a suite of LIBERO's `libero_task_map`
- isaac_lab:   `import isaaclab_tasks`, then `gymnasium.spec(env_id)`; when the package is
               installed but cannot be imported without a running Isaac Sim app, its sources
               are scanned for the `gym.register(id=...)` call instead
- custom_mjcf: the asset file exists and loads and steps in `mujoco`

Run: `python -m pytest tests/python/catalog/test_env_ids.py -q`
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import re
from pathlib import Path

import pytest

yaml = pytest.importorskip("yaml", reason="PyYAML is needed to read the registry: pip install pyyaml")

REPO_ROOT = Path(__file__).resolve().parents[3]
REGISTRY_PATH = REPO_ROOT / "configs" / "env_registry.yaml"

REQUIRED_FIELDS = {"id", "name", "framework", "env_id", "robot_type", "env_type"}
OPTIONAL_FIELDS = {"robot_model", "task_tags", "obs_type", "action_type", "description", "source"}
EXTENSION_FIELDS = {"kwargs", "max_episode_steps", "asset_path", "adapter", "python_env"}
ALLOWED = {
    "framework": {
        "gymnasium", "maniskill", "libero", "isaac_lab", "custom_mjcf", "rapier",
        "metaworld", "robosuite", "dm_control", "myosuite",
    },
    "robot_type": {"arm", "quadruped", "biped", "dexterous_hand", "mobile_base", "custom"},
    "env_type": {"tabletop", "floor", "terrain", "aerial", "aquatic"},
    "obs_type": {"state", "image", "state+image"},
    "action_type": {"continuous", "discrete"},
}
KEBAB_CASE = re.compile(r"^[a-z0-9]+(-[a-z0-9]+)*$")
TAG = re.compile(r"^[a-z0-9]+(-[a-z0-9]+)*$")

# Sources whose envs are cheap to create (no downloads, no GPU, under a second each).
CHEAP_GYMNASIUM_SOURCES = {"gymnasium", "gymnasium[mujoco]", "gymnasium[box2d]"}


def _load_entries() -> list[dict]:
    with REGISTRY_PATH.open(encoding="utf-8") as f:
        data = yaml.safe_load(f)
    assert isinstance(data, dict) and isinstance(data.get("environments"), list), (
        f"{REGISTRY_PATH}: expected a top-level `environments:` list"
    )
    return data["environments"]


ENTRIES = _load_entries()


def _entries(framework: str, pred=lambda e: True) -> list:
    """Entries of one framework as pytest params, each with the registry id as test id."""
    return [pytest.param(e, id=e["id"]) for e in ENTRIES if e["framework"] == framework and pred(e)]


def _import_or_skip(module: str, what: str):
    """Import `module` or skip: a framework can fail to import for reasons other than
    ImportError (missing GPU driver, an interactive first-run prompt), so catch everything."""
    try:
        return importlib.import_module(module)
    except Exception as exc:
        pytest.skip(f"{what} is not usable here (`import {module}` failed: {type(exc).__name__}: {exc})")


def _gymnasium():
    return pytest.importorskip("gymnasium", reason="gymnasium is not installed: pip install gymnasium")


def _gymnasium_robotics_available() -> bool:
    try:
        import gymnasium
        import gymnasium_robotics
    except Exception:
        return False
    gymnasium.register_envs(gymnasium_robotics)
    return True


GYMNASIUM_ROBOTICS = _gymnasium_robotics_available()


def _skip_unless_gymnasium_ready(entry: dict) -> None:
    if "gymnasium-robotics" in entry.get("source", "") and not GYMNASIUM_ROBOTICS:
        pytest.skip("gymnasium_robotics is not installed: pip install gymnasium-robotics")


# ─── The file itself ─────────────────────────────────────────────


def test_registry_schema():
    """Field names, allowed values, unique kebab-case ids — what the hub's loader enforces."""
    assert len(ENTRIES) >= 45, f"expected at least 45 entries, found {len(ENTRIES)}"
    seen: set[str] = set()
    problems: list[str] = []
    for i, e in enumerate(ENTRIES):
        where = f"entry {i} ({e.get('id', '?')})"
        missing = REQUIRED_FIELDS - e.keys()
        unknown = e.keys() - REQUIRED_FIELDS - OPTIONAL_FIELDS - EXTENSION_FIELDS
        if missing:
            problems.append(f"{where}: missing {sorted(missing)}")
        if unknown:
            problems.append(f"{where}: unknown fields {sorted(unknown)}")
        if not KEBAB_CASE.match(str(e.get("id", ""))):
            problems.append(f"{where}: id is not kebab-case")
        if e.get("id") in seen:
            problems.append(f"{where}: duplicate id")
        seen.add(e.get("id"))
        for field, allowed in ALLOWED.items():
            if field in e and e[field] not in allowed:
                problems.append(f"{where}: {field}={e[field]!r} not in {sorted(allowed)}")
        for field in ("name", "env_id", "robot_model", "description", "source", "asset_path", "adapter"):
            if field in e and not isinstance(e[field], str):
                problems.append(f"{where}: {field} must be a string")
        tags = e.get("task_tags", [])
        if not isinstance(tags, list) or not all(isinstance(t, str) and TAG.match(t) for t in tags):
            problems.append(f"{where}: task_tags must be a list of lowercase words, got {tags!r}")
        if "kwargs" in e and not isinstance(e["kwargs"], dict):
            problems.append(f"{where}: kwargs must be a mapping")
        steps = e.get("max_episode_steps", 1)
        if not isinstance(steps, int) or isinstance(steps, bool) or steps <= 0:
            problems.append(f"{where}: max_episode_steps must be a positive integer")
        if e.get("framework") == "custom_mjcf" and "asset_path" not in e:
            problems.append(f"{where}: a custom_mjcf entry needs asset_path")
    assert not problems, "\n".join(problems)


def _first(pred) -> str:
    return next(e["id"] for e in ENTRIES if pred(e))


def test_task_matching_anchors():
    """Task matching breaks ties by file order; these entries must come first in their class."""
    assert _first(
        lambda e: e["robot_type"] == "quadruped" and {"run", "forward"} <= set(e.get("task_tags", []))
    ) == "mujoco-ant"
    assert _first(
        lambda e: e["robot_type"] == "arm"
        and e["env_type"] == "tabletop"
        and {"pick", "place"} <= set(e.get("task_tags", []))
    ) == "fetch-pick-and-place"


# ─── gymnasium / gymnasium-robotics ──────────────────────────────


@pytest.mark.parametrize("entry", _entries("gymnasium"))
def test_gymnasium_env_id_exists(entry):
    gymnasium = _gymnasium()
    _skip_unless_gymnasium_ready(entry)
    try:
        gymnasium.spec(entry["env_id"])
    except gymnasium.error.Error as exc:
        pytest.fail(f"{entry['id']}: `{entry['env_id']}` is not registered in gymnasium {gymnasium.__version__}: {exc}")


def _constructor_params(spec) -> tuple[set[str], bool]:
    """Named parameters of the env's constructor, and whether it also takes **kwargs."""
    from gymnasium.envs.registration import load_env_creator

    creator = spec.entry_point if callable(spec.entry_point) else load_env_creator(spec.entry_point)
    target = creator.__init__ if inspect.isclass(creator) else creator
    params = inspect.signature(target).parameters.values()
    named = {p.name for p in params if p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD)}
    return named, any(p.kind == p.VAR_KEYWORD for p in params)


@pytest.mark.parametrize("entry", _entries("gymnasium", lambda e: bool(e.get("kwargs"))))
def test_gymnasium_kwargs_name_constructor_parameters(entry):
    """Every kwargs key is a named parameter of the env class (a typo would vanish into **kwargs)."""
    gymnasium = _gymnasium()
    _skip_unless_gymnasium_ready(entry)
    spec = gymnasium.spec(entry["env_id"])
    try:
        named, _ = _constructor_params(spec)
    except gymnasium.error.DependencyNotInstalled as exc:
        pytest.skip(f"{entry['id']}: the env's dependencies are missing: {exc}")
    unknown = set(entry["kwargs"]) - named
    assert not unknown, f"{entry['id']}: kwargs {sorted(unknown)} are not parameters of {spec.entry_point}"


@pytest.mark.parametrize(
    "entry", _entries("gymnasium", lambda e: e.get("source", "") in CHEAP_GYMNASIUM_SOURCES)
)
def test_gymnasium_make_with_kwargs(entry, tmp_path, monkeypatch):
    """Cheap entries (classic control, Box2D, MuJoCo locomotion) are created with their kwargs,
    and the action space they get is the kind the entry declares."""
    gymnasium = _gymnasium()
    monkeypatch.chdir(tmp_path)  # MuJoCo writes compiler warnings to ./MUJOCO_LOG.TXT
    if entry["source"] == "gymnasium[box2d]":
        pytest.importorskip("Box2D", reason="Box2D is not installed: pip install 'gymnasium[box2d]'")
    if entry["source"] == "gymnasium[mujoco]":
        pytest.importorskip("mujoco", reason="mujoco is not installed: pip install 'gymnasium[mujoco]'")
    env = gymnasium.make(entry["env_id"], **entry.get("kwargs", {}))
    try:
        env.reset(seed=0)
        env.step(env.action_space.sample())
        expected = {"discrete": gymnasium.spaces.Discrete, "continuous": gymnasium.spaces.Box}
        kind = entry.get("action_type", "continuous")
        assert isinstance(env.action_space, expected[kind]), (
            f"{entry['id']}: declared {kind} actions but `{entry['env_id']}` with kwargs "
            f"{entry.get('kwargs', {})} gives {env.action_space}"
        )
    finally:
        env.close()


# ─── ManiSkill3 ──────────────────────────────────────────────────


@pytest.mark.parametrize("entry", _entries("maniskill"))
def test_maniskill_env_id_exists(entry):
    gymnasium = _gymnasium()
    _import_or_skip("mani_skill.envs", "ManiSkill (pip install mani-skill)")
    from mani_skill.utils.registration import REGISTERED_ENVS

    env_id = entry["env_id"]
    if env_id in REGISTERED_ENVS:
        return
    try:
        gymnasium.spec(env_id)
    except gymnasium.error.Error:
        pytest.fail(f"{entry['id']}: `{env_id}` is not a registered ManiSkill task")


# ─── LIBERO ──────────────────────────────────────────────────────


@pytest.mark.parametrize("entry", _entries("libero"))
def test_libero_suite_exists(entry, tmp_path, monkeypatch):
    if importlib.util.find_spec("libero") is None:
        pytest.skip("LIBERO is not installed here (`make libero` builds .venv-libero)")
    from envhub.worker.hosted import libero

    if not os.path.isfile(libero._config_file()):
        monkeypatch.setenv("LIBERO_CONFIG_PATH", str(tmp_path))  # not the home folder's
    libero.ensure_config()  # else LIBERO's first import asks on stdin where its files go
    task_map = _import_or_skip("libero.libero.benchmark.libero_suite_task_map", "LIBERO").libero_task_map
    suite = entry["env_id"].partition("/")[0]
    # LIBERO's benchmark dict also lists `libero_100`, which has no tasks: the map is what runs.
    assert suite in task_map, f"{entry['id']}: `{suite}` is not a LIBERO suite; known: {sorted(task_map)}"


# ─── Isaac Lab ───────────────────────────────────────────────────

_ISAAC_REGISTER_ID = re.compile(r"""gym\.register\(\s*id\s*=\s*["']([^"']+)["']""")


def _isaac_lab_task_ids_from_sources(package_dir: Path) -> set[str]:
    ids: set[str] = set()
    for path in package_dir.rglob("*.py"):
        ids.update(_ISAAC_REGISTER_ID.findall(path.read_text(encoding="utf-8", errors="replace")))
    return ids


@pytest.mark.parametrize("entry", _entries("isaac_lab"))
def test_isaac_lab_env_id_exists(entry):
    gymnasium = _gymnasium()
    spec = importlib.util.find_spec("isaaclab_tasks")
    if spec is None or not spec.submodule_search_locations:
        pytest.skip("Isaac Lab is not installed (no `isaaclab_tasks` package)")
    env_id = entry["env_id"]
    try:
        importlib.import_module("isaaclab_tasks")
    except Exception:
        ids = set()
        for location in spec.submodule_search_locations:
            ids |= _isaac_lab_task_ids_from_sources(Path(location))
        assert env_id in ids, f"{entry['id']}: no `gym.register(id={env_id!r})` in isaaclab_tasks"
        return
    try:
        gymnasium.spec(env_id)
    except gymnasium.error.Error:
        pytest.fail(f"{entry['id']}: `{env_id}` is not registered by isaaclab_tasks")


# ─── custom MJCF ─────────────────────────────────────────────────


@pytest.mark.parametrize("entry", _entries("custom_mjcf"))
def test_custom_mjcf_asset_loads(entry):
    asset = Path(entry["asset_path"])
    if not asset.is_absolute():
        asset = REGISTRY_PATH.parent / asset
    assert asset.is_file(), f"{entry['id']}: asset_path {entry['asset_path']!r} -> {asset} does not exist"

    mujoco = pytest.importorskip("mujoco", reason="mujoco is not installed: pip install mujoco")
    np = pytest.importorskip("numpy")
    model = mujoco.MjModel.from_xml_path(str(asset))
    assert model.nu > 0, f"{entry['id']}: the model has no actuators"
    assert mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, "torso") >= 0, "the model needs a `torso` body"

    data = mujoco.MjData(model)
    rng = np.random.default_rng(0)
    low, high = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    for _ in range(500):
        data.ctrl[:] = rng.uniform(low, high)
        mujoco.mj_step(model, data)
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel)), "simulation diverged"
