"""A wrapper for simulators that return torch tensors with a leading batch axis of 1
(ManiSkill3, Isaac Lab): numpy values without that axis, as a single Gymnasium env."""

from __future__ import annotations

from typing import Any

import numpy as np


def to_numpy(value: Any, squeeze: bool) -> Any:
    """Tensors (and dicts of them) as numpy arrays, dropping a leading axis of 1."""
    if isinstance(value, dict):
        return {k: to_numpy(v, squeeze) for k, v in value.items()}
    if hasattr(value, "detach"):
        value = value.detach().cpu().numpy()
    a = np.asarray(value)
    return a[0] if squeeze and a.ndim > 0 and a.shape[0] == 1 else a


class TorchToNumpy:
    """Gymnasium contract over an env whose values are batched torch tensors of one env."""

    def __init__(self, env: Any) -> None:
        self.env = env
        unwrapped = getattr(env, "unwrapped", env)
        self.observation_space = getattr(unwrapped, "single_observation_space", env.observation_space)
        self.action_space = getattr(unwrapped, "single_action_space", env.action_space)
        self.spec = getattr(env, "spec", None)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        obs, info = self.env.reset(seed=seed, options=options)
        return to_numpy(obs, True), to_numpy(info, True)

    def step(self, action: Any) -> Any:
        obs, reward, terminated, truncated, info = self.env.step(np.asarray(action)[None])
        return (
            to_numpy(obs, True),
            float(to_numpy(reward, True)),
            bool(to_numpy(terminated, True)),
            bool(to_numpy(truncated, True)),
            to_numpy(info, True),
        )

    def render(self) -> Any:
        return to_numpy(self.env.render(), True)

    def close(self) -> None:
        self.env.close()
