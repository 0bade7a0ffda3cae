"""Benchmarks as catalog data: the `benchmarks:` mapping of the registry files, checked field
by field before anything starts.

A benchmark names what runs (one catalog entry per task, `entries:`, or one multi-task entry
and its tasks, `entry:` + `tasks:`) and the protocol each episode follows: how its initial
condition is chosen (`init`), settling steps, the horizon, the success rule, what the policy
is shown. A perturbation benchmark (LIBERO-PRO, LIBERO-Plus) adds `axes:`: each axis (one of
`axes.AXES`) runs the tasks under the entry options that perturb them, and its tasks carry
the axis (ids `<benchmark>/<axis>/<task>`). Every mistake is an error that names the valid
choices, closest first.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from difflib import get_close_matches
from typing import Any

from .policy import Task

__all__ = ["Benchmark", "BenchmarkError", "parse", "closest"]

FIELDS = {
    "description": "what it measures (text)",
    "entries": "catalog entry ids, one task each",
    "entry": "one catalog entry that runs every task (with `tasks`)",
    "tasks": "with `entry`: a task count (tasks 0..n-1), or a list of task indexes or names",
    "task_option": "the entry option that names the task (default `task`)",
    "task_reset_option": "with `entry`: the reset option that switches an env to a task (the adapter takes it, as "
    "Meta-World's `task`, and a list for `task_option`, a task per env): one session runs every task",
    "episodes_per_task": "episodes of each task (a positive integer)",
    "init": "how episode k starts: {init_states: true, seed: S (optional)} | {train_goals: {seed: S, benchmark: MT10}} | "
    "{seeds: [..]} | {seed_start: N}",
    "horizon": "policy steps per episode at most (after settling)",
    "settle": "{steps: N, action: [..]}: steps with a fixed action before the policy's first",
    "success": "{rule: any_step | last_step | none, key: success}",
    "stop_on_success": "end an episode at its first success (default: true with rule any_step)",
    "observation": "{keys: [..], flip: [..], resize: N or [H, W], video: key}",
    "action": "{sign: [i, ..]}: action dims sent as -1/+1 by their sign (a gripper)",
    "kwargs": "options the envs are made with",
    "python_env": "the catalog Python environment the policy runs in (optional)",
    "axes": "with `entry`: {axis: {options: {..}, tasks: ..}}: the tasks again under each perturbation axis (the entry "
    "options that perturb them; `tasks` as above, default the benchmark's)",
    "servers": "per server protocol (vla-eval, openpi), what its own harness sends (docs/guide/eval-report.md)",
    "source": "the registry file that declared it (set by the catalog)",
}
INIT_KINDS = ("init_states", "train_goals", "seeds", "seed_start")
RULES = ("any_step", "last_step", "none")
GOAL_SETS = ("MT1", "MT10", "MT25", "MT50")
#: Meta-World's train goals per task (`metaworld._N_GOALS`).
TRAIN_GOALS = 50


class BenchmarkError(ValueError):
    """A benchmark, task or protocol field that does not exist or does not fit; the
    message names the valid ones."""


def closest(word: str, valid: list[str], what: str) -> BenchmarkError:
    """`unknown <what> <word>; valid: <closest first>, <others>`."""
    near = get_close_matches(word, valid, n=len(valid), cutoff=0.0)[:5]
    rest = [v for v in valid if v not in near]
    listing = ", ".join(f"`{v}`" for v in near + rest)
    return BenchmarkError(f"unknown {what} `{word}`; valid: {listing}")


@dataclass(frozen=True)
class TaskSpec:
    """One task: its id, the entry that runs it, the options that pick it, its text, and its
    name (the value of the entry's task option; None with `entries`)."""

    id: str
    entry: str
    options: dict[str, Any]
    text: str
    index: int
    name: Any = None
    #: The perturbation axis the task runs under (`axes:`), else None.
    axis: str | None = None


@dataclass
class Benchmark:
    """A checked benchmark declaration (`raw` keeps it as written, for the results)."""

    name: str
    description: str
    tasks: list[TaskSpec]
    episodes_per_task: int
    init: dict[str, Any]
    horizon: int
    settle_steps: int
    settle_action: list[float] | None
    rule: str
    success_key: str
    stop_on_success: bool
    observation: dict[str, Any]
    action: dict[str, Any]
    kwargs: dict[str, Any]
    python_env: str | None
    source: str
    raw: dict[str, Any] = field(default_factory=dict)
    #: The reset option that switches an env to a task: one session runs every task.
    task_reset_option: str | None = None
    #: A perturbation benchmark's axes as checked: `{axis: {options: {..}, tasks: [..]}}`.
    axes: dict[str, dict[str, Any]] | None = None

    def task(self, spec: TaskSpec, text: str | None = None) -> Task:
        return Task(benchmark=self.name, id=spec.id, entry=spec.entry, text=text or spec.text, index=spec.index)

    def select(self, tasks: list[str] | None, episodes: int | None) -> Benchmark:
        """This benchmark narrowed to `tasks` (ids, or their last part: `0`, `reach-v3`) and
        `episodes` per task. With axes, an axis (`position`) picks its tasks, `<axis>/<task>`
        one task, and a task's last part (`0`) that task on every axis."""
        import copy

        out = copy.copy(self)
        if tasks:
            ids = {t.id: t for t in self.tasks}
            by: dict[str, list[TaskSpec]] = {}
            for t in self.tasks:
                last = t.id.rsplit("/", 1)[-1]
                for key in [last] if t.axis is None else [f"{t.axis}/{last}", t.axis, last]:
                    by.setdefault(key, []).append(t)
            picked: list[TaskSpec] = []
            for name in tasks:
                if name in ids:
                    chosen = [ids[name]]
                elif name in by:
                    # Without axes a last part names one task (the first, as ids are unique).
                    chosen = by[name] if by[name][0].axis else by[name][:1]
                else:
                    valid = [t.id for t in self.tasks] + sorted({t.axis for t in self.tasks if t.axis})
                    raise closest(name, valid, f"task of `{self.name}`")
                picked += [t for t in chosen if t not in picked]
            out.tasks = picked
        if episodes is not None:
            if episodes < 1:
                raise BenchmarkError(f"--episodes must be at least 1, not {episodes}")
            limit = self._episode_limit()
            if limit is not None and episodes > limit:
                raise BenchmarkError(f"`{self.name}` has {limit} initial conditions per task; --episodes {episodes} > {limit}")
            out.episodes_per_task = episodes
        return out

    def reseeded(self, offset: int) -> Benchmark:
        """The protocol under its `offset`-th seed (`--seeds N` runs offsets 0..N-1; 0 is the
        protocol itself): every seed the protocol draws from moved by `offset` (LIBERO's
        reset seed, Meta-World's goal set, the first reset seed, by a task's episodes per
        step); the fixed initial conditions (LIBERO's init states) stay."""
        import copy

        if offset == 0:
            return self
        out = copy.copy(self)
        init = dict(self.init)
        if "init_states" in init:
            init["seed"] = int(init.get("seed", 0)) + offset
        elif "train_goals" in init:
            init["train_goals"] = {**init["train_goals"], "seed": int(init["train_goals"]["seed"]) + offset}
        elif "seed_start" in init:
            init["seed_start"] = int(init["seed_start"]) + offset * self.episodes_per_task
        else:
            kind = next(iter(init), None)
            raise BenchmarkError(
                f"`{self.name}` has no seed to vary (`init: {kind or 'none'}`"
                f"{': a fixed list of seeds' if kind == 'seeds' else ''}); --seeds needs `init_states`, "
                "`train_goals` or `seed_start`"
            )
        out.init = init
        return out

    def _episode_limit(self) -> int | None:
        if "seeds" in self.init:
            return len(self.init["seeds"])
        return None

    def episode_init(self, k: int) -> dict[str, Any]:
        """The initial condition of episode `k` of a task: a reset option or seed."""
        if "init_states" in self.init:
            # With `seed`, every episode's reset reseeds the env (LIBERO's visual placement
            # draws from it): the episode does not depend on the ones run before it.
            seed = self.init.get("seed")
            return {"init_state": k} if seed is None else {"init_state": k, "seed": seed}
        if "train_goals" in self.init:
            return {"goal": goal_draws(self.init["train_goals"]["seed"], k + 1)[k]}
        if "seeds" in self.init:
            return {"seed": int(self.init["seeds"][k])}
        if "seed_start" in self.init:
            return {"seed": int(self.init["seed_start"]) + k}
        return {}

    def reset_options(self, spec: TaskSpec) -> dict[str, Any]:
        """The reset options that switch an env of a shared session to `spec`'s task."""
        if self.task_reset_option is None:
            return {}
        return {self.task_reset_option: spec.name}

    def session_options(self, specs: list[TaskSpec]) -> dict[str, Any]:
        """What the envs of a session are made with, env `i` to run `specs[i]`'s task first
        (a list of tasks, one per env, where envs switch tasks on reset)."""
        options = self.env_options(specs[0])
        if self.task_reset_option is not None and len({spec.id for spec in specs}) > 1:
            options[self.raw.get("task_option", "task")] = [spec.name for spec in specs]
        return options

    def env_options(self, spec: TaskSpec) -> dict[str, Any]:
        """What the envs of a task's session are made with."""
        options = {**self.kwargs, **spec.options}
        goals = self.init.get("train_goals")
        if goals is not None:
            options.setdefault("benchmark", goals.get("benchmark", "MT1"))
            options.setdefault("seed", goals["seed"])
        return options

    def protocol(self) -> dict[str, Any]:
        """The protocol as the results record it."""
        return {
            "source": self.source,
            "entry": self.raw.get("entry"),
            "episodes_per_task": self.episodes_per_task,
            "init": self.init,
            "horizon": self.horizon,
            "settle": {"steps": self.settle_steps, "action": self.settle_action} if self.settle_steps else None,
            "success": {"rule": self.rule, "key": self.success_key, "stop_on_success": self.stop_on_success},
            "observation": self.observation,
            "action": self.action,
            "kwargs": self.kwargs,
            "python_env": self.python_env,
            **({"axes": self.axes} if self.axes else {}),
        }


def goal_draws(seed: int, n: int) -> list[int]:
    """The train goals Meta-World's `RandomTaskSelectWrapper` picks on an env's first `n`
    resets when the env was seeded with `seed` (`env.seed(seed)`; the wrapper draws
    `np_random.choice(50)` from the env's generator, which nothing else draws from)."""
    from gymnasium.utils import seeding

    rng, _ = seeding.np_random(seed)
    return [int(rng.choice(TRAIN_GOALS)) for _ in range(n)]


# Checking -------------------------------------------------------------------------------------


def _int(name: str, value: Any, where: str, low: int = 1) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise BenchmarkError(f"{where}: `{name}` must be an integer >= {low}, not {value!r}")
    return value


def _mapping(name: str, value: Any, where: str) -> dict[str, Any]:
    if not isinstance(value, dict):
        raise BenchmarkError(f"{where}: `{name}` must be a mapping, not {value!r}")
    return value


def _keys(value: dict[str, Any], valid: list[str], where: str) -> None:
    for key in value:
        if key not in valid:
            raise closest(str(key), valid, f"field of {where}")


def _str_list(name: str, value: Any, where: str) -> list[str]:
    if isinstance(value, str):
        value = [value]
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise BenchmarkError(f"{where}: `{name}` must be a list of names, not {value!r}")
    return list(value)


def _init(value: Any, where: str) -> dict[str, Any]:
    value = _mapping("init", value, where)
    value = dict(value)
    seed = value.pop("seed", None) if "init_states" in value else None
    if len(value) != 1 or next(iter(value)) not in INIT_KINDS:
        key = next((k for k in value if k not in INIT_KINDS), None)
        if key is not None:
            raise closest(str(key), list(INIT_KINDS), f"`init` kind of {where}")
        raise BenchmarkError(
            f"{where}: `init` names exactly one of {', '.join(INIT_KINDS)}, not {sorted(value)}"
        )
    kind, arg = next(iter(value.items()))
    if kind == "init_states":
        if arg is not True:
            raise BenchmarkError(
                f"{where}: `init: {{init_states: true}}` (episode k from the task's init state k)"
            )
        if seed is None:
            return {"init_states": True}
        return {"init_states": True, "seed": _int("init.seed", seed, where, low=0)}
    if kind == "train_goals":
        arg = _mapping("init.train_goals", arg, where)
        _keys(arg, ["seed", "benchmark"], f"{where} `init.train_goals`")
        seed = _int("init.train_goals.seed", arg.get("seed"), where, low=0)
        bench = arg.get("benchmark", "MT1")
        if bench not in GOAL_SETS:
            raise closest(str(bench), list(GOAL_SETS), f"Meta-World benchmark in {where}")
        return {"train_goals": {"seed": seed, "benchmark": bench}}
    if kind == "seeds":
        if not isinstance(arg, list) or not arg or not all(isinstance(s, int) and not isinstance(s, bool) for s in arg):
            raise BenchmarkError(f"{where}: `init.seeds` must be a non-empty list of integers, not {arg!r}")
        return {"seeds": list(arg)}
    return {"seed_start": _int("init.seed_start", arg, where, low=0)}


def _task_names(tasks: Any, where: str, field: str = "tasks") -> list[int | str]:
    """A `tasks` value as its list of task indexes or names."""
    if isinstance(tasks, int) and not isinstance(tasks, bool):
        names: list[int | str] = list(range(_int(field, tasks, where)))
    elif isinstance(tasks, list) and tasks and all(isinstance(t, (int, str)) and not isinstance(t, bool) for t in tasks):
        names = list(tasks)
    else:
        raise BenchmarkError(
            f"{where}: `{field}` must be a task count or a list of task indexes or names, not {tasks!r}"
        )
    if len(set(map(str, names))) != len(names):
        raise BenchmarkError(f"{where}: `{field}` lists a task twice")
    return names


def _axes(value: Any, tasks: Any, where: str) -> dict[str, dict[str, Any]]:
    """`axes:` checked: every axis one of `axes.AXES`, with the entry options that perturb
    its tasks (`options`) and its tasks (`tasks`, else the benchmark's)."""
    from .axes import AXES

    value = _mapping("axes", value, where)
    if not value:
        raise BenchmarkError(f"{where}: `axes` is empty; name at least one of: {', '.join(AXES)}")
    out: dict[str, dict[str, Any]] = {}
    for axis, decl in value.items():
        if axis not in AXES:
            raise closest(str(axis), list(AXES), f"perturbation axis in {where}")
        decl = _mapping(f"axes.{axis}", decl if decl is not None else {}, where)
        _keys(decl, ["options", "tasks"], f"{where} `axes.{axis}`")
        options = dict(_mapping(f"axes.{axis}.options", decl.get("options") or {}, where))
        own = decl.get("tasks", tasks)
        if own is None:
            raise BenchmarkError(f"{where}: axis `{axis}` has no tasks; give `tasks` (the benchmark's or the axis's)")
        out[str(axis)] = {"options": options, "tasks": _task_names(own, where, f"axes.{axis}.tasks")}
    return out


def _tasks(name: str, decl: dict[str, Any], where: str) -> list[TaskSpec]:
    if ("entries" in decl) == ("entry" in decl):
        raise BenchmarkError(f"{where}: give either `entries` (one entry per task) or `entry` (with `tasks`)")
    if "entries" in decl:
        if "tasks" in decl or "task_option" in decl or "task_reset_option" in decl or "axes" in decl:
            raise BenchmarkError(
                f"{where}: `tasks`/`task_option`/`task_reset_option`/`axes` go with `entry`, not with `entries`"
            )
        entries = _str_list("entries", decl["entries"], where)
        if not entries:
            raise BenchmarkError(f"{where}: `entries` is empty")
        return [TaskSpec(id=e, entry=e, options={}, text=e, index=i) for i, e in enumerate(entries)]
    entry = decl["entry"]
    if not isinstance(entry, str):
        raise BenchmarkError(f"{where}: `entry` must be a catalog entry id, not {entry!r}")
    option = decl.get("task_option", "task")
    if not isinstance(option, str) or not option:
        raise BenchmarkError(f"{where}: `task_option` must be an option name, not {option!r}")
    tasks = decl.get("tasks")
    if "axes" in decl:
        if "task_reset_option" in decl:
            raise BenchmarkError(
                f"{where}: `axes` and `task_reset_option` do not go together (each axis's tasks are made with its options)"
            )
        specs: list[TaskSpec] = []
        for axis, spec in _axes(decl["axes"], tasks, where).items():
            for t in spec["tasks"]:
                options = {**spec["options"], option: t}
                spec_id = f"{name}/{axis}/{t}"
                specs.append(TaskSpec(spec_id, entry, options, str(t), len(specs), name=t, axis=axis))
        return specs
    if tasks is None:
        return [TaskSpec(id=name, entry=entry, options={}, text=entry, index=0)]
    names = _task_names(tasks, where)
    return [
        TaskSpec(id=f"{name}/{t}", entry=entry, options={option: t}, text=str(t), index=i, name=t)
        for i, t in enumerate(names)
    ]


def _observation(value: Any, where: str) -> dict[str, Any]:
    value = _mapping("observation", value, where)
    _keys(value, ["keys", "flip", "resize", "video"], f"{where} `observation`")
    out: dict[str, Any] = {}
    if "keys" in value:
        out["keys"] = _str_list("observation.keys", value["keys"], where)
    if "flip" in value:
        out["flip"] = _str_list("observation.flip", value["flip"], where)
    if "resize" in value:
        r = value["resize"]
        size = [r, r] if isinstance(r, int) else r
        if not (isinstance(size, list) and len(size) == 2 and all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in size)):
            raise BenchmarkError(f"{where}: `observation.resize` must be a side N or [H, W], not {r!r}")
        out["resize"] = size
    if "video" in value:
        if not isinstance(value["video"], str):
            raise BenchmarkError(f"{where}: `observation.video` must be an observation key, not {value['video']!r}")
        out["video"] = value["video"]
    return out


def parse(name: str, decl: Any, entries: set[str] | None = None) -> Benchmark:
    """A checked `Benchmark` from its declaration; `entries`, when given, are the catalog's
    ids the benchmark's entries must be among."""
    where = f"benchmark `{name}`"
    decl = _mapping(name, decl, where)
    _keys(decl, list(FIELDS), where)
    tasks = _tasks(name, decl, where)
    if entries is not None:
        for t in tasks:
            if t.entry not in entries:
                raise closest(t.entry, sorted(entries), f"catalog entry in {where}")
    episodes = _int("episodes_per_task", decl.get("episodes_per_task"), where)
    init = _init(decl["init"], where) if "init" in decl else {}
    if "seeds" in init and episodes > len(init["seeds"]):
        raise BenchmarkError(f"{where}: {episodes} episodes per task but {len(init['seeds'])} seeds")
    horizon = _int("horizon", decl.get("horizon"), where)
    settle = _mapping("settle", decl.get("settle") or {}, where)
    _keys(settle, ["steps", "action"], f"{where} `settle`")
    steps = _int("settle.steps", settle.get("steps", 0), where, low=0)
    action = settle.get("action")
    if steps and not (
        isinstance(action, list)
        and action
        and all(isinstance(a, (int, float)) and not isinstance(a, bool) and math.isfinite(a) for a in action)
    ):
        raise BenchmarkError(f"{where}: `settle.action` must be a list of finite numbers, not {action!r}")
    success = decl.get("success", {"rule": "none"})
    if isinstance(success, str):
        success = {"rule": success}
    success = _mapping("success", success, where)
    _keys(success, ["rule", "key"], f"{where} `success`")
    rule = success.get("rule", "any_step")
    if rule not in RULES:
        raise closest(str(rule), list(RULES), f"success rule in {where}")
    key = success.get("key", "success")
    if not isinstance(key, str):
        raise BenchmarkError(f"{where}: `success.key` must be an info key, not {key!r}")
    stop = decl.get("stop_on_success", rule == "any_step")
    if not isinstance(stop, bool):
        raise BenchmarkError(f"{where}: `stop_on_success` must be true or false, not {stop!r}")
    act = _mapping("action", decl.get("action") or {}, where)
    _keys(act, ["sign"], f"{where} `action`")
    if "sign" in act and not (isinstance(act["sign"], list) and all(isinstance(i, int) and not isinstance(i, bool) for i in act["sign"])):
        raise BenchmarkError(f"{where}: `action.sign` must be a list of action indexes, not {act['sign']!r}")
    kwargs = _mapping("kwargs", decl.get("kwargs") or {}, where)
    python_env = decl.get("python_env")
    if python_env is not None and not isinstance(python_env, str):
        raise BenchmarkError(f"{where}: `python_env` must be a catalog Python environment name, not {python_env!r}")
    reset_option = decl.get("task_reset_option")
    if reset_option is not None and (not isinstance(reset_option, str) or not reset_option):
        raise BenchmarkError(f"{where}: `task_reset_option` must be a reset option name, not {reset_option!r}")
    if reset_option is not None and decl.get("tasks") is None:
        raise BenchmarkError(f"{where}: `task_reset_option` switches between `tasks`; this benchmark lists none")
    if "servers" in decl:
        from .servers.layout import LayoutError, check

        try:
            check(decl["servers"], where)
        except LayoutError as e:
            raise BenchmarkError(str(e)) from None
    description = decl.get("description", "")
    if not isinstance(description, str):
        raise BenchmarkError(f"{where}: `description` must be text")
    return Benchmark(
        name=name,
        description=description,
        tasks=tasks,
        episodes_per_task=episodes,
        init=init,
        horizon=horizon,
        settle_steps=steps,
        settle_action=[float(a) for a in action] if steps else None,
        rule=rule,
        success_key=key,
        stop_on_success=stop,
        observation=_observation(decl.get("observation") or {}, where),
        action=dict(act),
        kwargs=dict(kwargs),
        python_env=python_env,
        source=str(decl.get("source", "")),
        raw=dict(decl),
        task_reset_option=reset_option,
        axes=_axes(decl["axes"], decl.get("tasks"), where) if "axes" in decl else None,
    )
