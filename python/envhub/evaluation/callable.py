"""Python callables as policies: `function(observations, tasks) -> actions`, batched, in this
interpreter; `PerTask(factory)` for policies made per task (Meta-World's scripted experts)."""

from __future__ import annotations

import importlib
import importlib.util
import os
import queue
import sys
import threading
import time
from concurrent.futures import Future
from concurrent.futures import TimeoutError as FutureTimeout
from typing import Any, Callable, Sequence

import numpy as np

from .policy import Episode, PolicyError, Request, Task

__all__ = ["CallablePolicy", "PerTask", "Watchdog", "load"]

#: Seconds a policy call may take by default (`--policy-timeout`).
DEFAULT_TIMEOUT = 120.0


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


class Watchdog:
    """Runs a policy's calls one at a time in a thread of its own and waits `timeout` seconds
    for each. Python cannot stop a thread: a call past its deadline is abandoned (the thread
    finishes it whenever it returns, and its answer is dropped); until then every other call
    fails at once, naming the call that hangs. `timeout` None: calls run in the caller's
    thread, unbounded."""

    def __init__(self, name: str, timeout: float | None) -> None:
        if timeout is not None and not timeout > 0:
            raise ValueError(f"the policy timeout must be a positive number of seconds, not {timeout!r}")
        self.name, self.timeout = name, timeout
        self._calls: queue.SimpleQueue[tuple[Future, Callable[..., Any], tuple]] = queue.SimpleQueue()
        self._thread: threading.Thread | None = None
        self._hung: tuple[str, float] | None = None  # the abandoned call and when it began
        self._busy = threading.Event()

    def _serve(self) -> None:
        while True:
            future, fn, args = self._calls.get()
            try:
                value, error = fn(*args), None
            except BaseException as e:  # re-raised in the caller (KeyboardInterrupt too)
                value, error = None, e
            self._busy.clear()  # before the caller hears: its next call may set it again
            if error is None:
                future.set_result(value)
            else:
                future.set_exception(error)

    def call(self, what: str, fn: Callable[..., Any], *args: Any) -> Any:
        if self.timeout is None:
            return fn(*args)
        if self._hung is not None:
            if self._busy.is_set():
                call, began = self._hung
                raise PolicyError(
                    f"the policy {self.name} is still in its `{call}` call, which began "
                    f"{time.monotonic() - began:.0f} s ago and passed its {self.timeout:g} s deadline (--policy-timeout)"
                )
            self._hung = None
        if self._thread is None:
            self._thread = threading.Thread(target=self._serve, name="envhub-eval-policy", daemon=True)
            self._thread.start()
        future: Future = Future()
        began = time.monotonic()
        self._busy.set()
        self._calls.put((future, fn, args))
        try:
            return future.result(timeout=self.timeout)
        except FutureTimeout:
            if future.done():  # answered at the deadline
                return future.result()
            self._hung = (what, began)
            raise PolicyError(
                f"the policy {self.name} gave no answer to `{what}` within {self.timeout:g} s (--policy-timeout); "
                "the call is abandoned (an in-process policy cannot be interrupted)"
            ) from None

    @property
    def hung(self) -> bool:
        """A call passed its deadline and has not returned yet."""
        return self._hung is not None and self._busy.is_set()


class CallablePolicy:
    """The `Policy` the runner drives, over `target(observations, tasks)`: one call per batch,
    answers in request order (an array `(n, ...)` or a list). `target.reset(slot, episode)`
    and `target.end(slot, episode, result)` are called where it has them. Every call to the
    target has a deadline of `timeout` seconds (`Watchdog`; None: unbounded)."""

    def __init__(self, target: Any, name: str | None = None, timeout: float | None = None) -> None:
        if not callable(target):
            raise TypeError(f"a policy must be callable as policy(observations, tasks), not {type(target).__name__}")
        self.target = target
        self.name = name or getattr(target, "__qualname__", None) or type(target).__name__
        self.watchdog = Watchdog(f"`{self.name}`", timeout)

    def start(self, slot: int, episode: Episode) -> None:
        reset = getattr(self.target, "reset", None)
        if callable(reset):
            self.watchdog.call("reset", reset, slot, episode)

    def act(self, requests: Sequence[Request]) -> list[np.ndarray]:
        answer = self.watchdog.call(
            "act", self.target, [r.observation for r in requests], [r.episode.task for r in requests]
        )
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
            self.watchdog.call("end", end, slot, episode, result)

    def describe(self) -> dict[str, Any]:
        return {"kind": "callable", "name": self.name}

    def close(self) -> None:
        close = getattr(self.target, "close", None)
        if callable(close) and not self.watchdog.hung:  # a hung policy is left to the process's exit
            self.watchdog.call("close", close)
