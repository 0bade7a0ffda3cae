"""Camera observations from a Python worker (another interpreter) reach the caller without a
copy on the way: a 224×224×3 uint8 frame is written once by the worker into its row of the
shared-memory batch slot and the caller's array views that row, for one env and for a
batch; the bytes are the env's, and arrays kept from earlier steps stay unchanged."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from harness import import_envhub
from vector_checks import STEP_TIMEOUT, assert_same, in_shared_memory, slot_of

envhub = import_envhub()

SHAPE = (224, 224, 3)


class CameraEnv(gym.Env):
    """An env whose observation is a camera frame: a pattern that changes every step."""

    metadata = {"render_modes": []}

    def __init__(self, shape: tuple[int, ...] = SHAPE, limit: int = 50) -> None:
        self.observation_space = gym.spaces.Box(0, 255, shape, np.uint8)
        self.action_space = gym.spaces.Discrete(2)
        self.t, self.limit = 0, limit
        self.base = np.zeros(shape, np.uint8)

    def frame(self) -> np.ndarray:
        return (self.base + np.uint8(self.t % 251)).astype(np.uint8)

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        self.t = 0
        self.base = self.np_random.integers(0, 255, self.observation_space.shape, dtype=np.uint8)
        return self.frame(), {}

    def step(self, action: Any) -> Any:
        self.t += 1
        return self.frame(), 0.0, False, self.t >= self.limit, {}


@pytest.mark.parametrize("num_envs", [1, 4])
def test_camera_frames_are_views_of_the_slot_with_no_copy(num_envs):
    fns = [CameraEnv for _ in range(num_envs)]
    ours = envhub.AsyncVectorEnv(fns, num_workers=min(2, num_envs), step_timeout=STEP_TIMEOUT)
    ref = gym.vector.SyncVectorEnv(fns)
    try:
        got, _ = ours.reset(seed=3)
        want, _ = ref.reset(seed=3)
        np.testing.assert_array_equal(got, want)
        kept = []
        for _ in range(6):
            got = ours.step(np.zeros(num_envs, np.int64))[0]
            want = ref.step(np.zeros(num_envs, np.int64))[0]
            assert got.shape == (num_envs, *SHAPE) and got.dtype == np.uint8
            np.testing.assert_array_equal(got, want)
            # The frame is the slot's row: its memory is the shared mapping, owned by the slot.
            assert in_shared_memory(got) is not None
            assert slot_of(got) is not None
            kept.append((got, want.copy()))
        # Kept frames are other slots' rows, unchanged by later steps.
        assert not np.shares_memory(kept[-1][0], kept[-2][0])
        for got, want in kept[-3:]:
            np.testing.assert_array_equal(got, want)
        # No observation byte was copied between the worker's write and the caller's array.
        assert ours._session.obs_bytes_copied == 0
    finally:
        ours.close()
        ref.close()


@pytest.mark.parametrize("shape", [(6, 5), (6, 5, 1), (6, 5, 3), (6, 5, 4)])
def test_rendered_frames_of_any_channel_count_travel_as_rgb(shape):
    # What `HostedBatch.render_rgb` sends for a frame Gymnasium's `render()` returns: gray
    # repeated over the three channels, alpha dropped, colour as it is.
    from envhub.worker.batch import _rgb

    frame = np.arange(int(np.prod(shape)), dtype=np.uint8).reshape(shape)
    h, w, data = _rgb(frame)
    got = np.frombuffer(data, np.uint8).reshape(h, w, 3)
    want = np.dstack([frame] * 3) if frame.ndim == 2 else frame[..., [0, 0, 0]] if shape[-1] == 1 else frame[..., :3]
    np.testing.assert_array_equal(got, want)


def test_a_grayscale_env_renders_through_a_worker():
    class Gray(CameraEnv):
        metadata = {"render_modes": ["rgb_array"]}

        def __init__(self) -> None:
            super().__init__((4, 4, 3))
            self.render_mode = "rgb_array"

        def render(self) -> np.ndarray:
            return np.full((3, 2), 7 * (self.t + 1), np.uint8)

    from envhub.wire.spaces import from_gymnasium
    from envhub.worker import HostedBatch, HostedEnv

    env = Gray()
    hosted = HostedEnv(env, from_gymnasium(env.observation_space), from_gymnasium(env.action_space))
    (frame,) = HostedBatch([hosted], "next_step").render_rgb([True])
    assert frame[:2] == (3, 2) and frame[2] == bytes([7] * 18)


def test_same_step_final_frames_are_views_of_the_slot():
    # The last frame of an episode (same_step's `final_obs`) is the slot's row too, not a copy.
    fns = [lambda i=i: CameraEnv(limit=2 + i) for i in range(3)]
    mode = gym.vector.AutoresetMode.SAME_STEP
    ours = envhub.AsyncVectorEnv(fns, num_workers=2, autoreset_mode=mode, step_timeout=STEP_TIMEOUT)
    ref = gym.vector.SyncVectorEnv(fns, autoreset_mode=mode)
    try:
        assert_same(ours.reset(seed=1), ref.reset(seed=1), "reset")
        finals = 0
        for t in range(8):
            got, want = ours.step(np.zeros(3, np.int64)), ref.step(np.zeros(3, np.int64))
            assert_same(got, want, f"step {t}")
            info = got[4]
            for k in np.flatnonzero(info.get("_final_obs", np.zeros(3, bool))):
                assert slot_of(info["final_obs"][k]) is not None, (t, k)
                finals += 1
        assert finals >= 4
    finally:
        ours.close()
        ref.close()
