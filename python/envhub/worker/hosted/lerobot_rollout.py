"""What LeRobot 0.6.1's evaluation does around each env, for the `lerobot_*` adapters.

`lerobot-eval` with `use_async_envs` and more than one env per task wraps each env so that,
once its episode ended, it replays the terminal transition instead of stepping (and
autoresetting) the simulator until a reset that carries the option `lerobot_new_rollout`.
Which envs freeze changes what a later rollout of the same env starts from (LIBERO's
`init_state_id` advances at every reset), so the adapters do the same in the worker when the
session asks (`freeze_after_episode_end: true`) and the episodes stay LeRobot's.
"""

from __future__ import annotations

from typing import Any, SupportsFloat

import gymnasium as gym

#: The reset option LeRobot's `rollout()` passes to start a new rollout.
NEW_ROLLOUT_OPTION = "lerobot_new_rollout"


class FrozenAfterEnd(gym.Wrapper):
    """Replays an ended episode's last transition (reward 0) on every later step, and its
    observation and info on a reset without `lerobot_new_rollout`, as LeRobot's wrapper."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self._last: tuple[Any, SupportsFloat, bool, bool, dict[str, Any]] | None = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        if self._last is not None and not (options or {}).get(NEW_ROLLOUT_OPTION):
            obs, _, _, _, info = self._last
            return obs, info
        self._last = None
        return self.env.reset(seed=seed, options=options)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        if self._last is not None:
            return self._last
        obs, reward, terminated, truncated, info = self.env.step(action)
        if terminated or truncated:
            # The worker writes observations into shared memory and keeps nothing: a copy
            # of the values the simulator may change in place.
            self._last = (_copied(obs), 0.0, terminated, truncated, info)
        return obs, reward, terminated, truncated, info


def _copied(value: Any) -> Any:
    import numpy as np

    if isinstance(value, dict):
        return {k: _copied(v) for k, v in value.items()}
    return np.array(value, copy=True)


def take_flag(options: dict[str, Any], name: str) -> bool:
    """Pops a boolean option, refusing anything but a bool."""
    value = options.pop(name, False)
    if not isinstance(value, bool):
        raise TypeError(f"option `{name}` must be true or false, not {value!r}")
    return value


def check_unknown(options: dict[str, Any], known: list[str], what: str) -> None:
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ValueError(f"unknown {what} options {unknown}\nhint: valid options: {', '.join(sorted(known))}")
