"""`EnvConfig`: how to create an env (RoboSmith's fields) plus envhub's session options."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["EnvConfig"]


def _jsonable(value: Any) -> Any:
    if isinstance(value, (np.ndarray, np.generic)):  # `X | Y` here would need 3.10
        return value.tolist()
    if isinstance(value, os.PathLike):
        return os.fspath(value)
    raise TypeError(f"{type(value).__name__} is not JSON serializable")


def to_json(value: Any) -> str:
    """JSON for the Rust side; numpy values and paths are converted."""
    return json.dumps(value, default=_jsonable)


@dataclass
class EnvConfig:
    """How to create an env.

    `extra` holds framework-specific options (merged over the registry entry's `kwargs`);
    `workers` and `autoreset_mode` shape a vector env's session. `strict_actions` refuses
    continuous actions outside the action space's bounds, which otherwise reach the env as
    Gymnasium passes them (NaN and infinite actions are refused either way).

    `env_index` is set by a worker before each `EnvAdapter.make`: the env's index in its
    session (so an adapter can build env `i` differently); None elsewhere. It is not sent to
    the Rust side.
    """

    render_mode: str | None = None
    seed: int | None = None
    max_episode_steps: int | None = None
    num_envs: int = 1
    asset_path: str | os.PathLike[str] | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    workers: int | None = None
    autoreset_mode: str = "next_step"
    strict_actions: bool = False
    env_index: int | None = None

    def to_json(self) -> str:
        """The config as the Rust `EnvConfig` reads it."""
        return to_json(
            {
                "render_mode": self.render_mode,
                "seed": self.seed,
                "max_episode_steps": self.max_episode_steps,
                "num_envs": self.num_envs,
                "asset_path": os.fspath(self.asset_path) if self.asset_path is not None else None,
                "extra": self.extra,
                "workers": self.workers,
                "autoreset_mode": self.autoreset_mode,
                "strict_actions": self.strict_actions,
            }
        )
