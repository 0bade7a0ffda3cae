"""Stepping a recorder and keeping what the session returned, episode by episode, for the
recording tests to compare with what LeRobot's loader reads back."""

from __future__ import annotations

import gymnasium
import numpy as np


def _leaf(obs, path: tuple[str, ...], i: int) -> np.ndarray:
    for key in path:
        obs = obs[key]
    return np.array(obs[i], copy=True)


class FrameTap(gymnasium.vector.VectorWrapper):
    """Between an env and its recorder: keeps what each `render()` of the env returned, and
    the env's calls in order, so that a test gets the frame the env rendered right after each
    reset and step (the frame of that observation) without rendering it a second time."""

    def __init__(self, env) -> None:
        super().__init__(env)
        self.calls: list[str] = []
        self.shown: list[np.ndarray] = []

    def reset(self, **kwargs):
        self.calls.append("reset")
        return self.env.reset(**kwargs)

    def step(self, actions):
        self.calls.append("step")
        return self.env.step(actions)

    def render(self):
        frames = self.env.render()
        self.calls.append("render")
        self.shown = [np.array(f, copy=True) for f in frames]
        return frames

    def after(self, call: str) -> list[np.ndarray]:
        """The frames rendered after `call`, which must be the env's last calls: `call`, then
        one `render()`."""
        assert self.calls == [call, "render"], f"the recorder called {self.calls} for one {call}"
        self.calls = []
        return self.shown


def drive(rec, steps: int, act, *, seed: int, same_step: bool = False, frames: FrameTap | None = None,
          paths: dict[str, tuple[str, ...]] | None = None) -> list[dict[str, list]]:
    """Steps `rec` and returns the episodes that ended, in the order they ended (by step, then
    env), each as lists of what the session returned: per frame the observation leaves
    (`paths`: feature -> keys into the observation), the action, reward, flags and (with
    `frames`, the tap under `rec`) the frame the env rendered for that observation."""
    paths = paths or {"observation.state": ()}
    obs, _ = rec.reset(seed=seed)
    n = rec.num_envs
    shown = frames.after("reset") if frames else None
    current: list[dict[str, list]] = [{} for _ in range(n)]
    fresh = np.zeros(n, dtype=bool)
    ended = []
    for _ in range(steps):
        actions = act(obs)
        kept_actions = np.array(actions, copy=True)
        nobs, rewards, term, trunc, _ = rec.step(actions)
        for i in range(n):
            if fresh[i]:
                continue  # the autoreset step
            ep = current[i]
            for name, path in paths.items():
                ep.setdefault(name, []).append(_leaf(obs, path, i))
            ep.setdefault("action", []).append(kept_actions[i])
            ep.setdefault("next.reward", []).append(float(rewards[i]))
            ep.setdefault("next.terminated", []).append(bool(term[i]))
            ep.setdefault("next.truncated", []).append(bool(trunc[i]))
            if frames:
                ep.setdefault("frame", []).append(np.array(shown[i], copy=True))
            if term[i] or trunc[i]:
                ended.append(ep)
                current[i] = {}
        done = np.logical_or(term, trunc)
        fresh = np.zeros(n, dtype=bool) if same_step else done
        obs = nobs
        shown = frames.after("step") if frames else None
    return ended


class Episodes:
    """What the session returned, per env, cut into the episodes it ended (in the order they
    ended: by step, then env)."""

    def __init__(self, n: int) -> None:
        self.current: list[dict[str, list]] = [{} for _ in range(n)]
        self.ended: list[dict[str, list]] = []

    def add(self, i: int, obs, action, reward, term, trunc, frame=None) -> None:
        ep = self.current[i]
        if frame is not None:
            ep.setdefault("frame", []).append(np.array(frame, copy=True))
        ep.setdefault("observation.state", []).append(np.array(obs, copy=True))
        ep.setdefault("action", []).append(np.array(action, copy=True))
        ep.setdefault("next.reward", []).append(float(reward))
        ep.setdefault("next.terminated", []).append(bool(term))
        ep.setdefault("next.truncated", []).append(bool(trunc))
        if term or trunc:
            self.ended.append(ep)
            self.current[i] = {}

    def cut(self, i: int) -> None:
        self.current[i] = {}
