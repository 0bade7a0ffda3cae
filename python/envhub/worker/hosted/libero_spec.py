"""What the `libero` adapter decides without LIBERO: which suite and task an env id and its
options name, and the Gymnasium spaces of a LIBERO observation dict.

Kept apart from `libero.py` so that it is tested where LIBERO is not installed; the task
lists it checks names against come from LIBERO itself (`libero_task_map`).
"""

from __future__ import annotations

from difflib import get_close_matches
from typing import Any

# The env-id part, or the `task` option, when neither names a task: a suite's first task.
DEFAULT_TASK = 0


def split_env_id(env_id: str, extra: dict[str, Any]) -> tuple[str, int | str]:
    """`(suite, task)` for `env_id` (`libero_10` or `libero_10/<task index or name>`) and the
    entry's options (`task`: an index or a name; `suite`: another suite in place of the id's,
    as a perturbation benchmark's axis names LIBERO-PRO's `libero_goal_swap` for an entry of
    `libero_goal`). A bare suite means its task `task`, else task 0; naming the task in both
    places is an error unless they agree."""
    suite, sep, in_id = env_id.partition("/")
    other = extra.get("suite")
    if other is not None:
        if not isinstance(other, str) or not other or "/" in other:
            raise TypeError(f"LIBERO option `suite` must be a suite name such as `libero_goal_swap`, not {other!r}")
        suite = other
    if not suite or (sep and not in_id):
        raise LookupError(
            f"invalid LIBERO env id `{env_id}`\nhint: write `<suite>` (task 0, or the `task` option) "
            "or `<suite>/<task index or name>`, e.g. `libero_10` or `libero_10/3`"
        )
    from_id: int | str | None = (int(in_id) if in_id.isdigit() else in_id) if sep else None
    option = extra.get("task")
    if isinstance(option, bool) or (option is not None and not isinstance(option, (int, str))):
        raise TypeError(f"LIBERO option `task` must be a task index or name, not {option!r}")
    if isinstance(option, str) and option.isdigit():
        option = int(option)
    if from_id is not None and option is not None and from_id != option:
        raise ValueError(
            f"`{env_id}` names task {from_id!r} and the option `task` names {option!r}\n"
            "hint: name the task in one place only"
        )
    task = from_id if from_id is not None else option
    return suite, DEFAULT_TASK if task is None else task


def task_index(suite: str, task: int | str, task_map: dict[str, list[str]]) -> int:
    """The index in `task_map[suite]` (LIBERO's task order) of `task`, an index or a name; a
    wrong suite or task is an error that lists the valid ones, closest first."""
    if suite not in task_map:
        close = get_close_matches(suite, list(task_map), n=2, cutoff=0.75)
        guess = f"; did you mean {' or '.join(f'`{c}`' for c in close)}?" if close else ""
        raise LookupError(f"LIBERO has no suite `{suite}`{guess}\nhint: suites: {', '.join(task_map)}")
    names = task_map[suite]
    if isinstance(task, int):
        if 0 <= task < len(names):
            return task
        raise LookupError(
            f"LIBERO suite `{suite}` has no task {task}\nhint: tasks are 0..{len(names) - 1}, or a name such as `{names[0]}`"
        )
    if task in names:
        return names.index(task)
    close = get_close_matches(task, names, n=3, cutoff=0.4)
    guess = f"; did you mean {' or '.join(f'`{c}`' for c in close)}?" if close else ""
    listing = "\n".join(f"  {i}: {n}" for i, n in enumerate(names))
    raise LookupError(f"LIBERO suite `{suite}` has no task `{task}`{guess}\nhint: its tasks:\n{listing}")


def observation_space(obs: dict[str, Any]) -> Any:
    """A `Dict` space for robosuite's observation dict: camera images (`*_image`, uint8)
    `Box(0, 255)`, depth maps (`*_depth`, normalised by robosuite) `Box(0, 1)`, segmentation
    maps their integer type's range, unit quantities (quaternions, joint cos/sin) `[-1, 1]`
    and the other states (positions, velocities) unbounded floats. Keys robosuite gives
    non-numeric values are left out."""
    import gymnasium as gym
    import numpy as np

    spaces = {}
    for key, value in obs.items():
        v = np.asarray(value)
        if v.dtype.kind not in "fiub":
            continue
        spaces[key] = _box(key, v)
    space = gym.spaces.Dict(spaces)
    checked(space, "observation")
    return space


def _box(key: str, v: Any) -> Any:
    import gymnasium as gym
    import numpy as np

    if v.dtype == np.uint8:
        return gym.spaces.Box(0, 255, v.shape, np.uint8)
    if v.dtype.kind in "iu":
        info = np.iinfo(v.dtype)
        return gym.spaces.Box(info.min, info.max, v.shape, v.dtype)
    if v.dtype.kind == "b":
        return gym.spaces.MultiBinary(v.shape)
    if key.endswith("_depth"):
        return gym.spaces.Box(0.0, 1.0, v.shape, v.dtype)
    if key.endswith(("_quat", "_cos", "_sin")):
        return gym.spaces.Box(-1.0, 1.0, v.shape, v.dtype)
    return gym.spaces.Box(-np.inf, np.inf, v.shape, v.dtype)


def action_space(low: Any, high: Any) -> Any:
    """robosuite's `action_spec` as a float32 Box (its limits are +-1 for every controller)."""
    import gymnasium as gym
    import numpy as np

    space = gym.spaces.Box(np.asarray(low, np.float32), np.asarray(high, np.float32), dtype=np.float32)
    checked(space, "action")
    return space


def checked(space: Any, kind: str) -> Any:
    """`space` after Gymnasium's own checks (`passive_env_checker`), which raise on a space
    Gymnasium would refuse."""
    from gymnasium.utils import passive_env_checker as checker

    if kind == "observation":
        checker.check_observation_space(space)
    else:
        checker.check_action_space(space)
    return space


def outside(space: Any, obs: dict[str, Any]) -> list[str]:
    """The keys of `obs` whose values are outside their part of `space` (empty: all inside)."""
    import numpy as np

    return [k for k, s in space.spaces.items() if not s.contains(np.asarray(obs[k]))]


def control_rate(env: Any) -> int | float | None:
    """robosuite's steps per second of simulated time (`control_freq`, 20 by default)."""
    rate = getattr(env, "control_freq", None)
    if not isinstance(rate, (int, float)) or rate <= 0:
        return None
    return int(rate) if float(rate).is_integer() else float(rate)
