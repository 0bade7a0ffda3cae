"""A wrapper for simulators that return torch tensors with a leading batch axis of 1
(ManiSkill3, Isaac Lab): numpy values without that axis, as a single Gymnasium env."""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np


def to_numpy(value: Any, squeeze: bool) -> Any:
    """Tensors (and dicts of them) as numpy arrays, dropping a leading axis of 1; what is
    left with no axis becomes a Python scalar (`tensor([True])` -> `True`)."""
    if isinstance(value, dict):
        return {k: to_numpy(v, squeeze) for k, v in value.items()}
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    elif not isinstance(value, (np.ndarray, np.generic, bool, int, float)):
        return value  # text and other objects pass as they are
    a = np.asarray(value)
    if squeeze and a.ndim > 0 and a.shape[0] == 1:
        a = a[0]
    return a.item() if a.ndim == 0 else a


def _batched(action: Any) -> Any:
    """The action with a leading axis of 1, copied: the worker's action is a read-only view
    of shared memory that the next request overwrites, and torch would share it."""
    if isinstance(action, dict):
        return {k: _batched(v) for k, v in action.items()}
    return np.array(action, copy=True)[None]


def episode_limit(env: Any) -> int | None:
    """The step limit a wrapper in `env`'s chain applies (Gymnasium's `TimeLimit` and
    ManiSkill's `TimeLimitWrapper` both keep it in `_max_episode_steps`), or None."""
    while env is not None:
        limit = getattr(env, "_max_episode_steps", None)
        if isinstance(limit, (int, np.integer)) and limit > 0:
            return int(limit)
        env = getattr(env, "env", None)
    return None


class TorchToNumpy(gym.Env):
    """Gymnasium contract over an env whose values are batched torch tensors of one env.

    It is a `gymnasium.Env`, so the worker can add a `TimeLimit` over it; `spec` carries the
    limit the simulator's own wrappers apply, so the session reports it."""

    def __init__(self, env: Any, env_id: str | None = None) -> None:
        self.env = env
        unwrapped = getattr(env, "unwrapped", env)
        self.observation_space = getattr(unwrapped, "single_observation_space", env.observation_space)
        self.action_space = getattr(unwrapped, "single_action_space", env.action_space)
        self.metadata = dict(getattr(env, "metadata", None) or {})
        self.render_mode = getattr(env, "render_mode", None)
        limit = episode_limit(env)
        spec = getattr(env, "spec", None)
        if spec is not None:
            spec = dataclasses.replace(spec, max_episode_steps=limit or spec.max_episode_steps)
        elif env_id is not None:
            spec = gym.envs.registration.EnvSpec(id=env_id, max_episode_steps=limit)
        self.spec = spec
        self._closed = False

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        obs, info = self.env.reset(seed=seed, options=options)
        return to_numpy(obs, True), to_numpy(info, True)

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = self.env.step(_batched(action))
        return (
            to_numpy(obs, True),
            float(to_numpy(reward, True)),
            bool(to_numpy(terminated, True)),
            bool(to_numpy(truncated, True)),
            to_numpy(info, True),
        )

    def render(self) -> Any:
        frame = self.env.render()
        return None if frame is None else to_numpy(frame, True)

    def close(self) -> None:
        if not self._closed:
            self._closed = True
            self.env.close()
