"""What the evaluation asks of a policy, whatever runs it: a Python callable in this
interpreter, a vla-eval model server, or an OpenPI policy server.

The runner calls `act` with a batch of requests, one per env whose policy must choose (an
episode's first step after settling, or an env whose action chunk is used up). Each request
carries everything its answer may depend on (its episode, the step within it, the
observation as the benchmark's protocol shows it), so a deterministic policy gives the same
actions whatever the batch holds: 1 env or 16, local or remote.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, Sequence

import numpy as np


@dataclass(frozen=True)
class Task:
    """One task of a benchmark: `id` is the catalog's task id (`libero-spatial/0`,
    `metaworld-reach`), `entry` the registry entry that runs it, `text` the task's language
    instruction or description (what language-conditioned policies read), `index` its place
    in the benchmark's task list."""

    benchmark: str
    id: str
    entry: str
    text: str
    index: int


@dataclass(frozen=True)
class Episode:
    """One episode of an evaluation: its task, its index within the task, and the initial
    condition the protocol chose for it (`{"init_state": k}`, `{"seed": s}`, ...)."""

    task: Task
    index: int
    init: dict[str, Any] = field(default_factory=dict)

    @property
    def key(self) -> str:
        """`<task id>#<episode index>`: the episode's name in results and resumes."""
        return f"{self.task.id}#{self.index}"


@dataclass
class Request:
    """An env's turn to be given actions: `slot` the env's index in the session (stable for
    the episode), `step` the episode's step count after settling (0 for its first action),
    `observation` what the protocol shows the policy (a numpy array, or a dict of them)."""

    slot: int
    episode: Episode
    step: int
    observation: Any


class Policy(Protocol):
    """A policy as the runner drives it. `act` returns one answer per request, in order: an
    action (the env's action shape) or an action chunk (`(k, *action_shape)`, executed one
    action per step before the env's next request). `start`/`end` bracket each episode on a
    slot (servers keep per-episode state, e.g. vla-eval's EPISODE_START/EPISODE_END).
    An exception from `act` fails the episodes of that batch with its message."""

    def start(self, slot: int, episode: Episode) -> None: ...

    def act(self, requests: Sequence[Request]) -> list[np.ndarray]: ...

    def end(self, slot: int, episode: Episode, result: dict[str, Any]) -> None: ...

    def describe(self) -> dict[str, Any]:
        """What the results record of the policy: kind, name, version, address."""
        ...

    def close(self) -> None: ...


class PolicyError(RuntimeError):
    """A policy that failed its episodes (disconnected, stalled past its timeout, answered
    something that is not an action); the message says which and what was expected."""


class PolicyLoadError(PolicyError):
    """The policy `module:function` names cannot be loaded (no such module, file or name): a
    usage error, found before any episode runs."""


def policy_traceback(error: BaseException) -> str:
    """The traceback of an exception a policy raised, from the policy's own frames (the
    evaluation's frames above them left out): what a failed episode's error shows."""
    import os
    import traceback

    here = os.path.dirname(os.path.abspath(__file__))
    frames = [f for f in traceback.extract_tb(error.__traceback__) if not os.path.abspath(f.filename).startswith(here)]
    lines = ["Traceback (most recent call last):\n", *traceback.format_list(frames)]
    lines += traceback.format_exception_only(type(error), error)
    return "".join(lines).rstrip()
