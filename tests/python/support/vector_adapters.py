"""A user adapter whose `make_vec` returns a small vector env, for the tests of vector envs
served whole by a Python worker (importable by the worker processes)."""

from __future__ import annotations

from typing import Any

import envhub
import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

#: How many steps back `CounterVectorEnv` reports a kept action from (`info["lagged"]`).
LAG = 5


class CounterVectorEnv(gym.vector.VectorEnv):
    """Env `i` counts its steps and sums its actions; its episode ends (terminated) after
    `2 + i` steps and restarts in the same step (SAME_STEP: the last observation in
    `info["final_obs"]`). Dict observations; per-env info `t` and a batch-wide `calls`."""

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, num_envs: int, raise_in_step: bool) -> None:
        self.num_envs = num_envs
        self.raise_in_step = raise_in_step
        self.single_observation_space = gym.spaces.Dict(
            {
                "t": gym.spaces.Box(0, 100, (1,), np.int64),
                "sum": gym.spaces.Box(-np.inf, np.inf, (2,), np.float32),
            }
        )
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (2,), np.float32)
        self.observation_space = gym.vector.utils.batch_space(self.single_observation_space, num_envs)
        self.action_space = gym.vector.utils.batch_space(self.single_action_space, num_envs)
        self.t = np.zeros(num_envs, np.int64)
        self.sum = np.zeros((num_envs, 2), np.float32)
        self.calls = 0
        # Every action batch as given (not copied), as "previous action" features keep them.
        self.kept: list[Any] = []

    def _obs(self) -> dict[str, np.ndarray]:
        return {"t": self.t[:, None].copy(), "sum": self.sum.copy()}

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> Any:
        mask = (options or {}).pop("reset_mask", np.ones(self.num_envs, np.bool_))
        self.t[mask] = 0
        self.sum[mask] = 0.0
        return self._obs(), {"seed": np.full(self.num_envs, -1 if seed is None else seed)}

    def step(self, actions: Any) -> Any:
        self.calls += 1
        if self.raise_in_step:
            raise ValueError("boom: the vector env failed in step")
        self.t += 1
        self.sum += actions
        self.kept.append(actions)
        terminated = self.t >= 2 + np.arange(self.num_envs)
        rewards = self.t.astype(np.float64)
        info: dict[str, Any] = {"t": self.t.copy(), "_t": np.ones(self.num_envs, np.bool_), "calls": self.calls}
        if len(self.kept) > LAG:
            # Each env's first action value of LAG steps ago, read from the kept batch now.
            info["lagged"] = self.kept[-1 - LAG][:, 0].astype(np.float64)
        if terminated.any():
            final = self._obs()
            info["final_obs"] = np.array(
                [{k: v[i] for k, v in final.items()} if terminated[i] else None for i in range(self.num_envs)],
                dtype=object,
            )
            info["_final_obs"] = terminated.copy()
            self.t[terminated] = 0
            self.sum[terminated] = 0.0
        return self._obs(), rewards, terminated, np.zeros(self.num_envs, np.bool_), info


class CounterVectorAdapter(envhub.EnvAdapter):
    """`Counter-v0`: a `CounterVectorEnv` for the worker's envs (`raise_in_step: true` in the
    entry's kwargs makes its step raise)."""

    name = "vec_counter"
    frameworks = ["vec_counter"]
    requires = ["numpy"]
    description = "a vector env for tests"

    def make_vec(self, env_id: str, config: Any) -> Any:
        return CounterVectorEnv(config.num_envs, bool(config.extra.get("raise_in_step", False)))
