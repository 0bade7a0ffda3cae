"""User adapters for the Python-hosted adapter tests (importable by the worker processes)."""

from __future__ import annotations

from typing import Any

import envhub
import gymnasium as gym
import numpy as np

#: What the last `make` received, per process (the test reads it back through `info`).
RECEIVED: dict[str, Any] = {}


class EchoEnv(gym.Env):
    """Observation: a counter and the last action; reports its config in the reset info."""

    def __init__(self, config: Any) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.config = config
        self.t = 0

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.t = 0
        c = self.config
        info = {
            "seed": -1 if c.seed is None else c.seed,
            "render_mode": str(c.render_mode),
            "max_episode_steps": -1 if c.max_episode_steps is None else c.max_episode_steps,
            "num_envs": c.num_envs,
            "asset_path": str(c.asset_path),
            "extra": repr(sorted(c.extra.items())),
        }
        return np.zeros(2, np.float32), info

    def step(self, action: Any) -> Any:
        self.t += 1
        if float(action[0]) > 0.99:
            raise ValueError("boom: action above 0.99")
        return np.array([self.t, float(action[0])], np.float32), 1.0, False, False, {}


class MySimAdapter(envhub.EnvAdapter):
    name = "mysim"
    frameworks = ["mysim"]
    requires = ["numpy"]
    description = "a test simulator"

    def make(self, env_id: str, config: Any) -> Any:
        return EchoEnv(config)


class MissingDepAdapter(envhub.EnvAdapter):
    name = "needs_missing"
    frameworks = ["needs_missing"]
    requires = ["envhub_no_such_module_xyz"]
    description = "depends on a module that is not installed"
    install_hint = "pip install envhub-no-such-module-xyz"


class KeepsActionsEnv(gym.Env):
    """Keeps every action it is given, as "previous action" features do, and reports the
    action of `LAG` steps ago: observation `[t, that action]` (0 before step `LAG + 1`)."""

    LAG = 5

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float32)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.kept: list[Any] = []

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.kept = []
        return np.zeros(2, np.float32), {}

    def step(self, action: Any) -> Any:
        self.kept.append(action)  # the array itself, not a copy of it
        t = len(self.kept)
        old = float(self.kept[t - 1 - self.LAG][0]) if t > self.LAG else 0.0
        return np.array([t, old], np.float32), 0.0, False, False, {}


class KeepsActionsAdapter(envhub.EnvAdapter):
    name = "keepsim"
    frameworks = ["keepsim"]
    requires = ["numpy"]
    description = "an env that keeps the actions it is given"

    def make(self, env_id: str, config: Any) -> Any:
        return KeepsActionsEnv()


class MixedInfoEnv(gym.Env):
    """Infos of every kind a hosted env reports, seeded: numbers every step, a key only some
    envs and steps have, and now and then text (which no typed column holds). Episodes end
    after 5 to 9 steps."""

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (3,), np.float64)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.t = 0
        self.length = 5

    def _info(self) -> dict[str, Any]:
        info: dict[str, Any] = {"t": self.t, "x": float(self.t) / 3.0, "ok": self.t % 2 == 0, "e": np.float64(-self.t)}
        if self.np_random.random() < 0.3:
            info["bonus"] = float(self.np_random.random())
        if self.np_random.random() < 0.1:
            info["note"] = f"step {self.t}"
        return info

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.t = 0
        self.length = int(self.np_random.integers(5, 10))
        return np.zeros(3), self._info()

    def step(self, action: Any) -> Any:
        self.t += 1
        obs = np.array([self.t, float(action[0]), self.np_random.random()])
        return obs, float(action[0]), self.t >= self.length, False, self._info()


class MixedInfoAdapter(envhub.EnvAdapter):
    name = "mixed_infos"
    frameworks = ["mixed_infos"]
    requires = ["numpy"]
    description = "an env whose infos mix numbers, sometimes-present keys and text"

    def make(self, env_id: str, config: Any) -> Any:
        return MixedInfoEnv()
