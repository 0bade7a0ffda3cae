"""An env that draws its own state: each frame is an image that the frame's state (episode,
step) names, so a test compares every decoded frame with the image the env drew."""

from __future__ import annotations

import gymnasium
import numpy as np
from gymnasium import spaces

KEY = "observation.images.pixels"
STEPS = 6  # an episode's frames


def image(ep: int, t: int) -> np.ndarray:
    """The frame of step `t` of episode `ep`: smooth gradients that move with both."""
    y, x = np.mgrid[0:48, 0:64]
    return np.stack([x * 2 + t * 5, y * 3 + ep * 23 % 100, (x + y) * 2 + t], -1).astype(np.uint8)


class Drawn(gymnasium.Env):
    """An env whose state says (episode, step) and whose camera draws `image` of them; each
    env of a vector env counts its own episodes from `first`."""

    metadata = {"render_fps": 10}

    def __init__(self, first: int = 0) -> None:
        self.observation_space = spaces.Dict({
            "state": spaces.Box(-1e6, 1e6, (2,), np.float32),
            "pixels": spaces.Box(0, 255, (48, 64, 3), np.uint8),
        })
        self.action_space = spaces.Box(-1, 1, (1,), np.float32)
        self.ep = first - 1
        self.t = 0

    def _obs(self) -> dict:
        return {"state": np.array([self.ep, self.t], np.float32), "pixels": image(self.ep, self.t)}

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.ep += 1
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        return self._obs(), 1.0, False, self.t >= STEPS, {}
