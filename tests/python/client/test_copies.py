"""Bytes of observations copied on the way to the caller, counted (`VectorEnv.obs_bytes_copied`,
every copy counted) as the native path counts them: none in a step or a reset, final
observations included; a masked reset copies the rows of the envs it does not reset, and no
more; results past the pool's cap are copied once."""

from __future__ import annotations

import gc
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from harness import import_envhub
from vector_checks import STEP_TIMEOUT, slot_of

envhub = import_envhub()

SHAPE = (16, 16, 3)


class FrameEnv(gym.Env):
    """Frames that change every step, numeric infos, and episodes of 5 to 9 steps."""

    metadata = {"render_modes": []}

    def __init__(self) -> None:
        self.observation_space = gym.spaces.Box(0, 255, SHAPE, np.uint8)
        self.action_space = gym.spaces.Discrete(2)
        self.t, self.limit = 0, 5

    def frame(self) -> np.ndarray:
        return np.full(SHAPE, (self.t * 7 + self.limit) % 251, np.uint8)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.t, self.limit = 0, int(self.np_random.integers(5, 10))
        return self.frame(), {"limit": self.limit}

    def step(self, action: Any) -> Any:
        self.t += 1
        info = {"limit": self.limit, "progress": self.t / self.limit}
        return self.frame(), float(action), self.t >= self.limit, False, info


def make(mode: str, num_envs: int = 4) -> Any:
    return envhub.AsyncVectorEnv(
        [FrameEnv] * num_envs, num_workers=2, autoreset_mode=mode, step_timeout=STEP_TIMEOUT
    )


@pytest.mark.parametrize("mode", ["next_step", "same_step", "disabled"])
def test_steps_and_resets_copy_no_observation_bytes(mode):
    envs = make(mode)
    try:
        envs.reset(seed=1)
        ended = 0
        for t in range(40):
            _, _, terminated, _, info = envs.step(np.full(4, t % 2))
            ended += int(terminated.sum())
            if mode == "disabled" and terminated.any():
                assert envs.obs_bytes_copied == 0
                envs.reset(options={"reset_mask": terminated.copy()})
                kept = 4 - int(terminated.sum())
                assert envs.obs_bytes_copied == kept * int(np.prod(SHAPE))
                break
            if mode == "same_step" and terminated.any():
                final = info["final_obs"][terminated]
                assert all(slot_of(f) is not None for f in final), "final frames are views"
        assert ended > 0
        if mode != "disabled":
            assert envs.obs_bytes_copied == 0
    finally:
        envs.close()


def test_a_masked_reset_copies_only_the_envs_it_does_not_reset():
    ours, ref = make("disabled"), gym.vector.SyncVectorEnv([FrameEnv] * 4, autoreset_mode="Disabled")
    try:
        ours.reset(seed=2)
        ref.reset(seed=2)
        for t in range(3):
            got = ours.step(np.full(4, t % 2))[0]
            ref.step(np.full(4, t % 2))
        assert ours.obs_bytes_copied == 0
        mask = np.array([False, True, False, False])
        got, got_info = ours.reset(seed=[None, 5, None, None], options={"reset_mask": mask})
        want, want_info = ref.reset(seed=[None, 5, None, None], options={"reset_mask": mask})
        np.testing.assert_array_equal(got, want)
        assert got_info.keys() == want_info.keys()
        for key in want_info:
            np.testing.assert_array_equal(got_info[key], want_info[key])
        row = int(np.prod(SHAPE))
        assert ours.obs_bytes_copied == 3 * row, "the three envs kept, once each"
        assert slot_of(got) is not None, "the reset envs' rows stay where the worker wrote them"
    finally:
        ours.close()
        ref.close()


def test_results_past_the_cap_are_copied_once():
    slot_bytes = 16 * (4 * 4 + 8 + 3) + 8  # as test_zero_copy: 4 slots' worth
    envs = envhub.make_vec("gym-cartpole", 16, num_workers=2, pool_bytes=4 * slot_bytes)
    try:
        kept = [envs.reset(seed=0)[0]]
        for _ in range(10):
            kept.append(envs.step(envs.action_space.sample())[0])
        copies = [a for a in kept if slot_of(a) is None]
        assert copies, "the cap was never reached"
        assert envs.obs_bytes_copied == sum(a.nbytes for a in copies)
        del kept, copies
        gc.collect()
    finally:
        envs.close()
