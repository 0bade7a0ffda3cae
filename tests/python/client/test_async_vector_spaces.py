"""Spaces at the edges of what travels, through `envhub.AsyncVectorEnv` against Gymnasium's:
a `MultiDiscrete` with a 2-D `nvec` keeps its shape both ways (space, actions the env gets,
observations it returns); integer `Box` bounds at their dtype's limits stay those limits."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from harness import import_envhub
from vector_checks import STEP_TIMEOUT, assert_same

envhub = import_envhub()

NVEC = np.array([[2, 3, 4], [5, 6, 7]])


class GridEnv(gym.Env):
    """Acts and observes with a 2-D MultiDiscrete; checks the action's shape itself."""

    metadata = {"render_modes": []}

    def __init__(self) -> None:
        self.action_space = gym.spaces.MultiDiscrete(NVEC)
        self.observation_space = gym.spaces.MultiDiscrete(NVEC, start=-np.ones_like(NVEC))
        self.state = np.zeros_like(NVEC)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.state = self.np_random.integers(0, NVEC) - 1
        return self.state.copy(), {}

    def step(self, action: Any) -> Any:
        assert np.shape(action) == NVEC.shape, np.shape(action)
        self.state = (action % NVEC) - 1
        return self.state.copy(), float(np.sum(action)), False, False, {}


def test_a_2d_multi_discrete_keeps_its_shape():
    fns = [GridEnv for _ in range(3)]
    ours = envhub.AsyncVectorEnv(fns, num_workers=1, step_timeout=STEP_TIMEOUT)
    ref = gym.vector.AsyncVectorEnv(fns)
    try:
        assert ours.single_action_space == ref.single_action_space
        assert ours.single_observation_space == ref.single_observation_space
        assert ours.action_space == ref.action_space
        assert_same(ours.reset(seed=2), ref.reset(seed=2), "reset")
        ref.action_space.seed(0)
        for t in range(5):
            a = ref.action_space.sample()
            assert_same(ours.step(a), ref.step(a), f"step {t}")
    finally:
        ours.close()
        ref.close()


class IntBoxEnv(gym.Env):
    """Integer boxes whose bounds are their dtype's whole range."""

    metadata = {"render_modes": []}

    def __init__(self) -> None:
        i64 = np.iinfo(np.int64)
        self.observation_space = gym.spaces.Box(i64.min, i64.max, (3,), np.int64)
        self.action_space = gym.spaces.Box(np.iinfo(np.int32).min, np.iinfo(np.int32).max, (2,), np.int32)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        return np.array([np.iinfo(np.int64).min, 0, np.iinfo(np.int64).max]), {}

    def step(self, action: Any) -> Any:
        return np.array([int(action[0]), int(action[1]), np.iinfo(np.int64).max]), 0.0, False, False, {}


def test_integer_box_bounds_at_the_dtype_limits_come_back_as_gymnasium_has_them():
    # The spaces `make`/`make_vec` report are rebuilt from the Rust description, whose
    # bounds are doubles: 2**63 - 1 rounds up to 2**63 and wrapped to -2**63 in the cast.
    from envhub.wire.spaces import from_gymnasium, to_gymnasium

    for dtype in (np.int64, np.int32, np.int8, np.uint8):
        info = np.iinfo(dtype)
        box = gym.spaces.Box(info.min, info.max, (2,), dtype)
        got = to_gymnasium(from_gymnasium(box))
        assert got == box and got.dtype == box.dtype, dtype
        assert np.array_equal(got.low, box.low) and np.array_equal(got.high, box.high), (dtype, got)
        inner = gym.spaces.Box(np.array([info.min, info.min + 3]), np.array([info.max - 7, info.max]), (2,), dtype)
        assert to_gymnasium(from_gymnasium(inner)) == inner, dtype


def test_integer_box_bounds_at_the_dtype_limits_survive_the_drop_in():
    fns = [IntBoxEnv, IntBoxEnv]
    ours = envhub.AsyncVectorEnv(fns, num_workers=1, step_timeout=STEP_TIMEOUT)
    ref = gym.vector.AsyncVectorEnv(fns)
    try:
        assert ours.single_observation_space == ref.single_observation_space
        assert ours.single_action_space == ref.single_action_space
        assert ours.observation_space == ref.observation_space
        assert_same(ours.reset(seed=0), ref.reset(seed=0), "reset")
        a = np.array([[np.iinfo(np.int32).max, -5], [np.iinfo(np.int32).min, 7]], np.int32)
        assert_same(ours.step(a), ref.step(a), "step")
    finally:
        ours.close()
        ref.close()
