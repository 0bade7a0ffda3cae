"""`libero`: the LIBERO task suites (robosuite under the hood)."""

from __future__ import annotations

from typing import Any

from .base import EnvAdapter


class LiberoAdapter(EnvAdapter):
    """LIBERO tasks, by `<suite>/<task index>` (`libero_10/0`) or `<suite>/<task name>`;
    `extra` goes to `OffScreenRenderEnv` (camera sizes, ...)."""

    name = "libero"
    frameworks = ["libero"]
    requires = ["libero", "robosuite"]
    description = "LIBERO task suites (robosuite), hosted in a Python worker"
    install_hint = "pip install robosuite==1.4.1 && pip install git+https://github.com/Lifelong-Robot-Learning/LIBERO"

    def make(self, env_id: str, config: Any) -> Any:
        import os

        from libero.libero import benchmark, get_libero_path
        from libero.libero.envs import OffScreenRenderEnv

        suite_name, _, task = env_id.partition("/")
        suites = benchmark.get_benchmark_dict()
        if suite_name not in suites:
            raise LookupError(f"LIBERO has no suite `{suite_name}`\nhint: suites are {', '.join(sorted(suites))}")
        suite = suites[suite_name]()
        names = suite.get_task_names()
        index = int(task) if task.isdigit() else names.index(task) if task in names else -1
        if not 0 <= index < len(names):
            raise LookupError(f"LIBERO suite `{suite_name}` has no task `{task}`\nhint: tasks: 0..{len(names) - 1} or {names}")
        t = suite.get_task(index)
        bddl = os.path.join(get_libero_path("bddl_files"), t.problem_folder, t.bddl_file)
        return _LiberoEnv(OffScreenRenderEnv(bddl_file_name=bddl, **config.extra))


class _LiberoEnv:
    """Gymnasium contract over LIBERO's robosuite env (dict observations of arrays)."""

    def __init__(self, env: Any) -> None:
        import gymnasium as gym
        import numpy as np

        self.env = env
        obs = env.reset()
        self.observation_space = gym.spaces.Dict(
            {
                k: gym.spaces.Box(-np.inf, np.inf, np.shape(v), np.asarray(v).dtype)
                for k, v in obs.items()
                if np.asarray(v).dtype.kind in "fiu"
            }
        )
        low, high = env.env.action_spec
        self.action_space = gym.spaces.Box(low, high, dtype=np.float64)
        self.spec = None

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        if seed is not None:
            self.env.seed(seed)
        obs = self.env.reset()
        return {k: obs[k] for k in self.observation_space.spaces}, {}

    def step(self, action: Any) -> Any:
        obs, reward, done, info = self.env.step(action)
        return {k: obs[k] for k in self.observation_space.spaces}, float(reward), bool(done), False, info

    def close(self) -> None:
        self.env.close()
