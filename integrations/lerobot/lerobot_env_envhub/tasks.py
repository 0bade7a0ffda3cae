"""What `--env.task` names: a LIBERO suite, Meta-World tasks, or any other catalog entry or
benchmark, resolved to LeRobot's `{group: {task_id: ...}}` layout without starting anything."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cache
from importlib import resources
from pathlib import Path
from typing import Any

#: LIBERO's suites and their task counts (LeRobot's `--env.task` names; the catalog's ids,
#: `libero-spatial`, name the same suites).
LIBERO_SUITES = {"libero_spatial": 10, "libero_object": 10, "libero_goal": 10, "libero_10": 10, "libero_90": 90}
#: The catalog's Meta-World benchmarks (their tasks come from the catalog).
METAWORLD_BENCHMARKS = ("metaworld-mt10", "metaworld-mt50", "metaworld-mt1")
REGISTRY = Path(__file__).with_name("registry.yaml")


class TaskError(ValueError):
    """`--env.task` names nothing the plugin can run; the message lists what it can."""


@dataclass
class Task:
    """One task of a group: the catalog entry that runs it and its options."""

    entry: str
    options: dict[str, Any] = field(default_factory=dict)
    #: LeRobot's `_max_episode_steps` (None: the session's episode limit).
    max_episode_steps: int | None = None
    #: LeRobot's task text (None: learned from the first reset's info).
    description: str | None = None
    name: str | None = None


@dataclass
class Plan:
    """`kind` (`libero`, `metaworld` or `catalog`) and the tasks of each group, in order."""

    kind: str
    groups: dict[str, list[Task]]


def registry_files(extra: list[str] | None = None) -> list[str]:
    """The catalog the plugin reads: envhub's built-in one, the plugin's entries, then the
    user's files."""
    return ["@default", str(REGISTRY), *(extra or [])]


@cache
def _metaworld_config() -> dict[str, Any]:
    """LeRobot's own Meta-World table (task texts, difficulty groups), read as data: its
    module imports Meta-World, which LeRobot's interpreter does not have here."""
    text = resources.files("lerobot.envs").joinpath("metaworld_config.json").read_text()
    return json.loads(text)


def libero_suite(name: str) -> str | None:
    """`libero_spatial` for `libero_spatial` or the catalog's `libero-spatial`."""
    suite = name.replace("-", "_")
    return suite if suite in LIBERO_SUITES else None


def metaworld_task(name: str, catalog: Any) -> str | None:
    """The Meta-World task (`push-v3`) a name means: the task itself, LeRobot's
    `metaworld-push-v3`, or a catalog entry of framework `metaworld` (`metaworld-push`)."""
    tasks = _metaworld_config()["TASK_DESCRIPTIONS"]
    bare = name.removeprefix("metaworld-")
    if bare in tasks:
        return bare
    if name in catalog.registry.list_ids():
        entry = catalog.registry.get(name)
        if entry.framework == "metaworld" and entry.kwargs.get("env_name") in tasks:
            return str(entry.kwargs["env_name"])
    return None


def resolve(task: str | None, catalog: Any, task_ids: list[int] | None = None) -> Plan:
    """The plan for `--env.task` (comma-separated names of one kind)."""
    if not task or not task.strip():
        raise TaskError("--env.task is required: a LIBERO suite (libero_spatial), Meta-World tasks (push-v3, "
                        "metaworld-mt10) or a catalog entry or benchmark (mujoco-hopper)")
    names = [t.strip() for t in task.split(",") if t.strip()]
    if all(libero_suite(n) for n in names):
        return Plan("libero", {libero_suite(n): _libero_tasks(libero_suite(n), task_ids) for n in names})  # type: ignore[misc]
    if all(_is_metaworld(n, catalog) for n in names):
        return Plan("metaworld", {n: _metaworld_tasks(n, catalog) for n in names})
    if len(names) == 1:
        return Plan("catalog", {names[0]: _catalog_tasks(names[0], catalog)})
    raise TaskError(f"--env.task `{task}` mixes kinds; name LIBERO suites, Meta-World tasks or one catalog entry")


def _libero_tasks(suite: str, task_ids: list[int] | None) -> list[Task]:
    total = LIBERO_SUITES[suite]
    ids = list(range(total)) if task_ids is None else sorted({int(t) for t in task_ids})
    bad = [t for t in ids if not 0 <= t < total]
    if bad:
        raise TaskError(f"task_ids {bad} out of range for `{suite}`: 0..{total - 1}")
    return [Task("lerobot-libero", {"suite": suite, "task": t}) for t in ids]


def _is_metaworld(name: str, catalog: Any) -> bool:
    groups = _metaworld_config()["DIFFICULTY_TO_TASKS"]
    return name in groups or name in METAWORLD_BENCHMARKS or metaworld_task(name, catalog) is not None


def _metaworld_tasks(name: str, catalog: Any) -> list[Task]:
    config = _metaworld_config()
    if name in config["DIFFICULTY_TO_TASKS"]:
        names = list(config["DIFFICULTY_TO_TASKS"][name])
    elif name in METAWORLD_BENCHMARKS:
        names = [spec.name for spec in catalog.get(name).tasks]
    else:
        names = [metaworld_task(name, catalog)]
    texts = config["TASK_DESCRIPTIONS"]
    return [Task("lerobot-metaworld", {"task": n}, 500, texts[n], n) for n in names]


def _catalog_tasks(name: str, catalog: Any) -> list[Task]:
    """Each task of a benchmark, or the entry alone."""
    if name in catalog.names():
        bench = catalog.get(name)
        return [Task(spec.entry, dict(bench.env_options(spec)), bench.horizon, spec.text, spec.id) for spec in bench.tasks]
    if name in catalog.registry.list_ids():
        entry = catalog.registry.get(name)
        return [Task(name, {}, None, entry.description, name)]
    from difflib import get_close_matches

    valid = [*LIBERO_SUITES, *METAWORLD_BENCHMARKS, *catalog.names(), *catalog.registry.list_ids()]
    near = get_close_matches(name, valid, n=5, cutoff=0.5)
    hint = f"; did you mean {', '.join(f'`{v}`' for v in near)}?" if near else ""
    raise TaskError(
        f"--env.task `{name}` is no LIBERO suite, Meta-World task, catalog entry or benchmark{hint}\n"
        "hint: `envhub envs` lists the entries, LeRobot's LIBERO suites are libero_spatial, libero_object, "
        "libero_goal, libero_10, libero_90"
    )
