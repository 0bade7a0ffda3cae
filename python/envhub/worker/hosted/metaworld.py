"""`metaworld` (alias `meta_world`): Meta-World 3.x tasks with a Sawyer arm, through the ids
Meta-World registers in Gymnasium (`Meta-World/MT1`, ...)."""

from __future__ import annotations

import functools
import warnings
from difflib import get_close_matches
from typing import Any

import gymnasium as gym

from .suites import SuiteAdapter, gym_make, unknown_id

#: The Meta-World id an entry names by its task alone (`reach-v3`).
MT1 = "Meta-World/MT1"
#: Meta-World's multi-task benchmarks whose train goals an env may take (`benchmark` option).
GOAL_SETS = ("MT1", "MT10", "MT25", "MT50")
#: Reset options the adapter reads (the others go to Meta-World, which ignores them).
GOAL = "goal"
TASK = "task"
#: Task envs an env keeps by default (MT10's ten): a task switched back to is not made again.
KEEP_TASKS = 10


class MetaWorldAdapter(SuiteAdapter):
    """Meta-World tasks: the env id is a Meta-World Gymnasium id (`Meta-World/MT1`, with the
    task in the option `env_name`, e.g. `reach-v3`) or a task name alone (`reach-v3`, for
    MT1). Meta-World draws its 50 train goal positions (tasks) when the env is made, from
    the option `seed` (else the session's seed, else 0): every env of a session gets the same
    goal set, and env `i` draws its goals on reset from a generator seeded with `seed + i`, so
    the envs of a vector session differ and each is reproducible. `benchmark: MT10` (or
    `MT25`, `MT50`) takes the goal set Meta-World's benchmark of that seed gives the task
    (they differ from MT1's: one generator draws every task's goals in turn), as
    `gym.make_vec("Meta-World/MT10", seed=...)` builds its envs. `reset(options={"goal": g})`
    starts the episode from train goal `g` (0..49) rather than a drawn one. `env_name` may be a
    list: env `i` of a session runs task `env_name[i mod n]` (with `benchmark: MT10` and MT10's
    ten tasks, the envs of `gym.make_vec("Meta-World/MT10")`).
    `reset(options={"task": "push-v3"})` switches an env made by task name to another task of
    its benchmark (any of the 50 for MT1) from that episode on: the task's env is made on first
    use in the worker, as an entry naming it would make it (same goal set, seed and options),
    so one session runs several tasks, each env its own; `keep_tasks: N` (default 10) bounds the
    task envs an env keeps. Meta-World ignores reset seeds; envhub says so once. `goal_seed_per_env: true` restores envhub's first
    behaviour (env `i` made with `seed + i`: its own goal set). The other options go to
    Meta-World (`reward_function_version`, `terminate_on_success`, `task_select`, `width`,
    `height`, `camera_name`, ...)."""

    name = "metaworld"
    frameworks = ["metaworld", "meta_world"]
    requires = ["metaworld", "mujoco"]
    description = "Meta-World 3.x manipulation tasks (Sawyer arm, MuJoCo 3.3), hosted in a Python worker"
    install_hint = "pip install metaworld==3.1.1 mujoco==3.3.0 packaging (the catalog's Python environment `metaworld`)"
    mujoco_series = ("3.3.",)
    python_env = "metaworld"

    def make(self, env_id: str, config: Any) -> Any:
        import metaworld

        kwargs = dict(config.extra)
        benchmark = kwargs.pop("benchmark", "MT1")
        per_env = kwargs.pop("goal_seed_per_env", False)
        if benchmark not in GOAL_SETS:
            raise unknown_id("Meta-World benchmark", str(benchmark), list(GOAL_SETS), f"one of {', '.join(GOAL_SETS)}")
        names = kwargs.get("env_name")
        if isinstance(names, list):
            # A task per env, as Meta-World's MT10 vector env has: env i runs names[i mod n].
            if not names or not all(isinstance(n, str) for n in names):
                raise TypeError(f"Meta-World option `env_name` must be a task name or a list of them, not {names!r}")
            kwargs["env_name"] = names[int(config.env_index or 0) % len(names)]
        if not env_id.startswith("Meta-World/"):
            if env_id not in metaworld.ALL_V3_ENVIRONMENTS:
                raise unknown_id(
                    "Meta-World",
                    env_id,
                    sorted(metaworld.ALL_V3_ENVIRONMENTS),
                    "a task name such as `reach-v3` (MT1), or `Meta-World/MT1` with the option `env_name`",
                )
            if kwargs.setdefault("env_name", env_id) != env_id:
                raise ValueError(
                    f"`{env_id}` names a task and the option `env_name` names `{kwargs['env_name']}`\n"
                    "hint: name the task in one place only"
                )
            env_id = MT1
        if env_id not in gym.registry:
            ids = [i for i in gym.registry if i.startswith("Meta-World/")]
            raise unknown_id("Meta-World", env_id, ids, f"Meta-World registers: {', '.join(ids)}")
        if env_id == MT1 and kwargs.get("env_name") not in metaworld.ALL_V3_ENVIRONMENTS:
            raise unknown_id(
                "Meta-World MT1",
                str(kwargs.get("env_name")),
                sorted(metaworld.ALL_V3_ENVIRONMENTS),
                "set the option `env_name` to a task: "
                + ", ".join(sorted(metaworld.ALL_V3_ENVIRONMENTS)[:8])
                + ", ...",
            )
        base = kwargs.get("seed", config.seed if config.seed is not None else 0)
        if isinstance(base, bool) or not isinstance(base, int):
            raise TypeError(f"Meta-World option `seed` must be an integer, not {base!r}")
        keep = kwargs.pop("keep_tasks", KEEP_TASKS)
        if isinstance(keep, bool) or not isinstance(keep, int) or keep < 1:
            raise TypeError(f"Meta-World option `keep_tasks` must be an integer >= 1, not {keep!r}")
        index = int(config.env_index or 0)

        def build(name: str | None) -> MetaWorldGoals:
            """The env of task `name`, made as `make` makes the env of an entry naming it."""
            task_kwargs = dict(kwargs) if name is None else {**kwargs, "env_name": name}
            if per_env:
                task_kwargs["seed"] = base + index
                return MetaWorldGoals(gym_make(env_id, config, task_kwargs))
            task_kwargs["seed"] = base
            if benchmark == "MT1" or env_id != MT1:
                env = gym_make(env_id, config, task_kwargs)
            else:
                env = _benchmark_env(benchmark, base, config, task_kwargs)
            if index:
                # Same goal set, another generator for the goals drawn on reset (Meta-World's `seed`).
                env.unwrapped.seed(base + index)
            return MetaWorldGoals(env)

        first = build(kwargs.get("env_name"))
        if env_id != MT1:
            return first
        if benchmark == "MT1":
            tasks = sorted(metaworld.ALL_V3_ENVIRONMENTS)
        else:
            from metaworld import env_dict

            tasks = list(getattr(env_dict, f"{benchmark}_V3"))
        return MetaWorldTasks(first, kwargs["env_name"], build, tasks, benchmark, keep)


@functools.lru_cache(maxsize=4)
def _goal_set(benchmark: str, seed: int) -> tuple[Any, list[Any]]:
    """(task classes, train goals) of Meta-World's benchmark of that seed. Drawing them makes
    every task's env and resets it 50 times (MT10: about 13 s here), so every worker of
    every session would pay it: they are kept in a file per benchmark, seed and Meta-World
    version in this user's private folder (`envhub.wire.private_dir`; written whole, then
    renamed into place)."""
    import os
    import pickle
    import tempfile
    from importlib import metadata

    import metaworld
    from metaworld import env_dict

    from ...wire import private_dir

    classes = getattr(env_dict, f"{benchmark}_V3")
    # Unpickled: so only in a folder no other user can have made or write in.
    folder = private_dir.runtime_dir("metaworld")
    path = os.path.join(folder, f"{benchmark}-seed{seed}-{metadata.version('metaworld')}.pkl")
    try:
        with open(path, "rb") as f:
            return classes, pickle.load(f)
    except (OSError, pickle.UnpicklingError, EOFError):
        pass
    tasks = getattr(metaworld, benchmark)(seed=seed).train_tasks
    fd, tmp = tempfile.mkstemp(dir=folder)
    with os.fdopen(fd, "wb") as f:
        pickle.dump(tasks, f)
    os.replace(tmp, path)
    return classes, tasks


def _benchmark_env(benchmark: str, seed: int, config: Any, kwargs: dict[str, Any]) -> Any:
    """One task's env as Meta-World's `make_mt_envs` builds it for `Meta-World/<benchmark>`
    (its class, the benchmark's train goals of that task, seeded with `seed`)."""
    import metaworld

    kwargs = dict(kwargs)
    name = kwargs.pop("env_name")
    kwargs.pop("seed")
    classes, goals = _goal_set(benchmark, seed)
    if name not in classes:
        raise unknown_id(f"Meta-World {benchmark}", name, sorted(classes), f"{benchmark}'s tasks")
    tasks = [t for t in goals if t.env_name == name]
    return metaworld._init_each_env(
        env_cls=classes[name],
        tasks=tasks,
        seed=seed,
        env_id=list(classes).index(name),
        num_tasks=len(classes),
        max_episode_steps=config.max_episode_steps or None,
        render_mode=config.render_mode,
        **kwargs,
    )


_SEED_WARNED = False


class MetaWorldGoals(gym.Wrapper):
    """Meta-World's env with the reset option `goal` (a train goal by index) and a warning,
    once per process, that a reset seed changes nothing in Meta-World."""

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        global _SEED_WARNED
        if seed is not None and not _SEED_WARNED:
            _SEED_WARNED = True
            warnings.warn(
                "Meta-World ignores reset seeds: its goals come from the option `seed` when the env is made "
                "(and `reset(options={'goal': g})` picks train goal g)",
                stacklevel=2,
            )
        options = dict(options or {})
        if TASK in options:
            raise ValueError(
                f"the reset option `task` picks the task of an env made by task name (`reach-v3`, or "
                f"`{MT1}` with `env_name`), not of `{self.env.spec.id if self.env.spec else self.env}`"
            )
        if GOAL not in options:
            return self.env.reset(seed=seed, options=options or None)
        goal = options.pop(GOAL)
        select = _task_selector(self.env)
        n = len(select.tasks)
        if isinstance(goal, bool) or not isinstance(goal, int) or not 0 <= goal < n:
            raise ValueError(f"invalid Meta-World `goal` {goal!r}\nhint: an index 0..{n - 1} into the task's train goals")
        unwrapped: Any = self.env.unwrapped  # Meta-World's env, with its `set_task`
        unwrapped.set_task(select.tasks[goal])
        sampling = select.sample_tasks_on_reset
        select.toggle_sample_tasks_on_reset(False)
        try:
            return self.env.reset(seed=seed, options=options or None)
        finally:
            select.toggle_sample_tasks_on_reset(sampling)


class MetaWorldTasks(gym.Wrapper):
    """An env whose task a reset may change: `reset(options={"task": "push-v3"})` makes that
    task's env on first use (as an entry naming the task would: the same goal set, seed and
    options) and steps it from then on. The env keeps the envs of its last `keep` tasks, so
    a task switched back to goes on with its goal generator where it was; an older one is
    closed, and made again from the start when named again. Every task's observation and
    action spaces are the first task's (Meta-World's v3 tasks share them)."""

    def __init__(self, env: Any, task: str, build: Any, tasks: list[str], benchmark: str, keep: int) -> None:
        super().__init__(env)
        self._observation_space = env.observation_space
        self._action_space = env.action_space
        self.task = task
        self._envs: dict[str, Any] = {task: env}  # least recently used first
        self._build, self._tasks, self._benchmark, self._keep = build, tasks, benchmark, keep

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        options = dict(options or {})
        name = options.pop(TASK, None)
        if name is not None:
            self._switch(name)
        return self.env.reset(seed=seed, options=options or None)

    def _switch(self, name: Any) -> None:
        if not isinstance(name, str) or name not in self._tasks:
            near = get_close_matches(str(name), self._tasks, n=len(self._tasks), cutoff=0.0)[:5]
            valid = near + [t for t in self._tasks if t not in near]
            raise ValueError(
                f"reset option `task`: {name!r} is not a task of Meta-World's {self._benchmark}; "
                f"valid: {', '.join(valid)}"
            )
        env = self._envs.pop(name, None)
        if env is None:
            env = self._build(name)
            if env.observation_space != self._observation_space or env.action_space != self._action_space:
                env.close()
                raise ValueError(
                    f"Meta-World task `{name}` has other spaces than `{self.task}` "
                    f"({env.observation_space}, {env.action_space})"
                )
        self._envs[name] = env
        while len(self._envs) > self._keep:
            oldest = next(iter(self._envs))
            self._envs.pop(oldest).close()
        self.env, self.task = env, name

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()


def _task_selector(env: Any) -> Any:
    """The wrapper of Meta-World's that holds the task's train goals (`tasks`)."""
    while env is not None:
        if hasattr(env, "tasks") and hasattr(env, "toggle_sample_tasks_on_reset"):
            return env
        env = getattr(env, "env", None)
    raise ValueError("this Meta-World env holds no train goals (option `task_select`?)")
