"""Rendering an envhub env as Gymnasium renders it: `rgb_array` frames, classic control's
frames equal Gymnasium's own env's, Stable-Baselines3's `make_vec_env`, `render_fps` as
Gymnasium declares it (following the frame skip), and Gymnasium's rendering wrappers."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from harness import import_envhub, mujoco_or_skip, runnable_or_skip

envhub = import_envhub()

REGISTRY = envhub.EnvRegistry()


def test_render_rgb_array():
    mujoco_or_skip(envhub)
    env = envhub.make("mujoco-ant", render_mode="rgb_array")
    try:
        assert env.metadata["render_modes"] == ["rgb_array"]
        env.reset(seed=0)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        assert frame.std() > 0, "a blank frame"
        check_env(env, skip_close_check=True)
    finally:
        env.close()
    envs = envhub.make_vec("mujoco-ant", 2, num_workers=1, render_mode="rgb_array")
    try:
        envs.reset(seed=0)
        frames = envs.render()
        assert len(frames) == 2 and all(f.shape == frame.shape for f in frames)
    finally:
        envs.close()
    assert envhub.make("gym-cartpole").render() is None


def test_classic_control_renders_through_gymnasiums_own_env(tmp_path):
    """The native classic-control envs draw nothing: with a render mode, the entry runs
    Gymnasium's own env in the Python worker (the same dynamics), so its frames are
    Gymnasium's. An entry pinned to the native adapter still refuses the mode."""
    ref = gymnasium.make("CartPole-v1", render_mode="rgb_array")
    env = envhub.make("gym-cartpole", render_mode="rgb_array")
    try:
        assert env.adapter == "gymnasium"
        assert env.reset(seed=4)[0].tolist() == ref.reset(seed=4)[0].tolist()
        for _ in range(5):
            ours, want = env.step(1), ref.step(1)
            assert ours[0].tolist() == want[0].tolist() and ours[1:4] == want[1:4]
        frame = env.render()
        assert frame.shape == (400, 600, 3) and frame.dtype == np.uint8
        np.testing.assert_array_equal(frame, ref.render())
    finally:
        env.close()
    # As Stable-Baselines3's `make_vec_env("envhub/gym-cartpole", 8)` makes its envs.
    envs = [gymnasium.make("envhub/gym-cartpole", render_mode="rgb_array") for _ in range(2)]
    try:
        for e in envs:
            e.reset(seed=0)
            assert e.render().shape == (400, 600, 3)
    finally:
        for e in envs:
            e.close()
    pinned = tmp_path / "pinned.yaml"
    pinned.write_text(
        "environments:\n  - {id: pinned-cartpole, name: CartPole, framework: gymnasium, env_id: CartPole-v1,"
        " adapter: classic_control, robot_type: custom, env_type: floor}\n"
    )
    with pytest.raises(envhub.MakeError, match="render mode `rgb_array` is not supported"):
        envhub.make("pinned-cartpole", render_mode="rgb_array", registry=str(pinned))


def test_stable_baselines3_make_vec_env_renders():
    """SB3's `make_vec_env` asks every env for `render_mode="rgb_array"` (SB3 is not in the
    default test set-up: `pip install stable-baselines3` to run this)."""
    sb3 = pytest.importorskip("stable_baselines3.common.env_util")
    venv = sb3.make_vec_env("envhub/gym-cartpole", 2)
    try:
        venv.reset()
        assert venv.get_images()[0].shape == (400, 600, 3)
    finally:
        venv.close()


@pytest.mark.parametrize(
    ("entry_id", "gym_id"),
    [
        ("gym-cartpole", "CartPole-v1"),
        ("gym-pendulum", "Pendulum-v1"),
        ("gym-mountain-car", "MountainCar-v0"),
        ("gym-mountain-car-continuous", "MountainCarContinuous-v0"),
        ("gym-acrobot", "Acrobot-v1"),
        ("mujoco-hopper", "Hopper-v5"),
        ("mujoco-ant", "Ant-v5"),
        ("mujoco-reacher", "Reacher-v5"),
    ],
)
def test_render_fps_is_gymnasiums(entry_id, gym_id):
    """`metadata["render_fps"]` (what video writers and `HumanRendering` read) is Gymnasium's,
    on `envhub.make`, `gymnasium.make("envhub/...")` and `envhub.make_vec`."""
    env = runnable_or_skip(envhub, entry_id)
    try:
        want = gymnasium.make(gym_id).metadata["render_fps"]
        assert env.metadata["render_fps"] == want
        assert type(env.metadata["render_fps"]) is int
    finally:
        env.close()
    env = gymnasium.make(f"envhub/{entry_id}")
    try:
        assert env.metadata["render_fps"] == want
    finally:
        env.close()
    envs = envhub.make_vec(entry_id, 2, num_workers=1)
    try:
        assert envs.metadata["render_fps"] == want
    finally:
        envs.close()


def test_render_fps_follows_frame_skip():
    """MuJoCo's rate is `round(1 / dt)`, and `dt` grows with `frame_skip`."""
    env = runnable_or_skip(envhub, "mujoco-hopper")
    env.close()
    env = envhub.make("mujoco-hopper", frame_skip=2)
    try:
        want = gymnasium.make("Hopper-v5", frame_skip=2).metadata["render_fps"]
        assert env.metadata["render_fps"] == want == 250
    finally:
        env.close()


def test_rendering_wrappers_accept_envhub_envs(tmp_path):
    """`HumanRendering` needs `render_fps`; `RecordVideo` writes its video at that rate."""
    mujoco_or_skip(envhub)
    env = envhub.make("mujoco-reacher", render_mode="rgb_array", width=64, height=64)
    try:
        human = gymnasium.wrappers.HumanRendering(env)  # raises without `render_fps`
        assert human.metadata["render_fps"] == 50
    finally:
        env.close()
    pytest.importorskip("moviepy", reason="RecordVideo needs moviepy")
    videos = tmp_path / "videos"
    env = gymnasium.wrappers.RecordVideo(
        envhub.make("mujoco-reacher", render_mode="rgb_array", width=64, height=64),
        str(videos),
        episode_trigger=lambda _: True,
    )
    try:
        assert env.frames_per_sec == 50
        env.reset(seed=0)
        for _ in range(10):
            env.step(env.action_space.sample())
    finally:
        env.close()
    assert list(videos.glob("*.mp4")), "no video written"
