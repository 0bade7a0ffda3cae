"""Python callables as policies: `function(observations, tasks) -> actions`, batched, in this
interpreter; `PerTask(factory)` for policies made per task (Meta-World's scripted experts)."""

from __future__ import annotations

import importlib
import importlib.util
import os
import sys
from typing import Any, Callable, Sequence

import numpy as np

from .policy import Episode, Request, Task

__all__ = ["CallablePolicy", "PerTask", "load"]


def load(spec: str) -> Any:
    """The object `module:name` (or `path/to/file.py:name`) names; a class is instantiated."""
    module_name, sep, attr = spec.rpartition(":")
    if not sep or not module_name or not attr:
        raise ValueError(f"--policy `{spec}`: write `module:function` or `path/to/file.py:function`")
    if module_name.endswith(".py"):
        path = os.path.abspath(module_name)
        if not os.path.isfile(path):
            raise FileNotFoundError(f"--policy `{spec}`: no file {path}")
        name = "envhub_policy_" + os.path.splitext(os.path.basename(path))[0]
        s = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(s)  # type: ignore[arg-type]
        sys.modules[name] = module
        s.loader.exec_module(module)  # type: ignore[union-attr]
    else:
        if "" not in sys.path and os.getcwd() not in sys.path:
            sys.path.insert(0, os.getcwd())
        module = importlib.import_module(module_name)
    try:
        target = getattr(module, attr)
    except AttributeError:
        names = [n for n in dir(module) if not n.startswith("_")]
        from .benchmarks import closest

        raise closest(attr, names, f"name in `{module_name}`") from None
    return target() if isinstance(target, type) else target


class PerTask:
    """A batched policy from a factory: `factory(task)` makes each task's agent once (its
    `get_action(obs)`, or the agent itself called on one observation)."""

    def __init__(self, factory: Callable[[Task], Any]) -> None:
        self.factory = factory
        self.agents: dict[str, Any] = {}

    def __call__(self, observations: Sequence[Any], tasks: Sequence[Task]) -> list[np.ndarray]:
        out = []
        for obs, task in zip(observations, tasks, strict=True):
            agent = self.agents.get(task.id)
            if agent is None:
                agent = self.agents[task.id] = self.factory(task)
            act = getattr(agent, "get_action", agent)
            out.append(np.asarray(act(obs)))
        return out


class CallablePolicy:
    """The `Policy` the runner drives, over `target(observations, tasks)`: one call per batch,
    answers in request order (an array `(n, ...)` or a list). `target.reset(slot, episode)`
    and `target.end(slot, episode, result)` are called where it has them."""

    def __init__(self, target: Any, name: str | None = None) -> None:
        if not callable(target):
            raise TypeError(f"a policy must be callable as policy(observations, tasks), not {type(target).__name__}")
        self.target = target
        self.name = name or getattr(target, "__qualname__", None) or type(target).__name__

    def start(self, slot: int, episode: Episode) -> None:
        reset = getattr(self.target, "reset", None)
        if callable(reset):
            reset(slot, episode)

    def act(self, requests: Sequence[Request]) -> list[np.ndarray]:
        answer = self.target([r.observation for r in requests], [r.episode.task for r in requests])
        if isinstance(answer, np.ndarray) or isinstance(answer, (list, tuple)):
            if len(answer) != len(requests):
                raise ValueError(
                    f"the policy answered {len(answer)} actions for a batch of {len(requests)} observations"
                )
            return list(answer)
        raise TypeError(f"the policy returned {type(answer).__name__}; it must return one action per observation")

    def end(self, slot: int, episode: Episode, result: dict[str, Any]) -> None:
        end = getattr(self.target, "end", None)
        if callable(end):
            end(slot, episode, result)

    def describe(self) -> dict[str, Any]:
        return {"kind": "callable", "name": self.name}

    def close(self) -> None:
        close = getattr(self.target, "close", None)
        if callable(close):
            close()
