"""Recording rollouts into LeRobot datasets, judged by LeRobot's own loader: what can be recorded.

Each test steps envhub envs through `envhub.RecordEpisodes`, keeps its own copy of what the
session returned, then loads the dataset with `LeRobotDataset(repo_id, root=DIR)` from the
`lerobot-dataset` package in LeRobot's own interpreter (`support/lerobot_datasets.py`: where
it comes from, when the tests skip, the codec tolerance). Here: native and Python-hosted envs,
every autoreset mode, envs on other hubs, Gymnasium's own vector env, camera observations."""

from __future__ import annotations

import json
import os

import numpy as np
import pytest
from harness import import_envhub, mujoco_or_skip
from hub_daemons import two_hubs  # noqa: F401 (a fixture: hubs on loopback)
from lerobot_datasets import (
    check_against,
    load,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
)
from recorded_episodes import FrameTap, drive

envhub = import_envhub()
os.environ.setdefault("MUJOCO_GL", "egl")  # Gymnasium's own MuJoCo rendering in hosted workers


# Native, Python-hosted, Dict with a camera -------------------------------------------------


# slow: 60 steps of three Hoppers, each step rendered (MuJoCo offscreen through Mesa's software
# EGL here, about 40 ms a frame); the 60 steps give the six episodes of different lengths the
# test checks.
@pytest.mark.slow
def test_native_mujoco_with_render_frames(tmp_path):
    """A native MuJoCo env (Hopper, three envs, `next_step` autoreset) with `rgb_array`
    frames: episodes of different lengths, states and actions bit for bit, the video within
    the codec tolerance."""
    mujoco_or_skip(envhub)
    env = envhub.make_vec("mujoco-hopper", 3, num_workers=1, render_mode="rgb_array",
                          max_episode_steps=25, width=64, height=48)
    root = tmp_path / "hopper"
    tap = FrameTap(env)
    rec = envhub.RecordEpisodes(tap, str(root), commit_every=0.05)
    rng = np.random.default_rng(0)
    try:
        expected = drive(rec, 60, lambda obs: rng.uniform(-1, 1, (3, 3)).astype(np.float32), seed=1, frames=tap)
    finally:
        rec.close()
    assert len(expected) >= 6 and len({len(ep["action"]) for ep in expected}) > 1
    assert rec.stats["episodes_written"] == len(expected)
    summary, arrays = load(root)
    task = envhub.EnvRegistry().get("mujoco-hopper").description
    check_against(summary, arrays, expected, task, video_key="observation.images.render")
    assert summary["features"]["observation.state"] == {"dtype": "float64", "shape": [11]}
    assert summary["features"]["observation.images.render"]["shape"] == [48, 64, 3]
    info = json.loads((root / "meta" / "info.json").read_text())
    assert info["fps"] == env.metadata["render_fps"] and info["codebase_version"] == "v3.0"
    assert "observation.state" in summary["stats_keys"] and "observation.images.render" in summary["stats_keys"]


def test_python_hosted_env_same_step(tmp_path):
    """A Python-hosted env (Gymnasium's CartPole, drawn by pygame; Discrete actions) under
    `same_step` autoreset."""
    env = envhub.make_vec("gym-cartpole", 2, num_workers=1, autoreset_mode="same_step", render_mode="rgb_array")
    root = tmp_path / "cartpole"
    tap = FrameTap(env)
    rec = envhub.RecordEpisodes(tap, str(root))
    rng = np.random.default_rng(1)
    try:
        expected = drive(rec, 50, lambda obs: rng.integers(0, 2, 2), seed=3, same_step=True, frames=tap)
    finally:
        rec.close()
    assert len(expected) >= 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("gym-cartpole").description,
                  video_key="observation.images.render")
    assert summary["features"]["action"] == {"dtype": "int64", "shape": [1]}


def test_disabled_autoreset_with_masked_resets(tmp_path):
    """`autoreset_mode="disabled"`: an episode starts at the masked reset that the caller
    makes; an episode a full reset cuts short is not written."""
    env = envhub.make_vec("gym-pendulum", 2, num_workers=1, autoreset_mode="disabled", max_episode_steps=4)
    root = tmp_path / "disabled"
    rec = envhub.RecordEpisodes(env, str(root), video=False)
    rng = np.random.default_rng(6)
    expected, current = [], [{}, {}]
    try:
        obs, _ = rec.reset(seed=0)
        for t in range(11):
            if t == 2:  # env 1 starts over two steps late: its episodes end out of step with env 0's
                obs, _ = rec.reset(options={"reset_mask": np.array([False, True])})
                current[1] = {}
            actions = rng.uniform(-2, 2, (2, 1)).astype(np.float32)
            nobs, rewards, term, trunc, _ = rec.step(actions)
            for i in range(2):
                ep = current[i]
                ep.setdefault("observation.state", []).append(np.array(obs[i]))
                ep.setdefault("action", []).append(actions[i].copy())
                ep.setdefault("next.reward", []).append(float(rewards[i]))
                ep.setdefault("next.terminated", []).append(bool(term[i]))
                ep.setdefault("next.truncated", []).append(bool(trunc[i]))
            done = term | trunc
            obs = nobs
            for i in np.flatnonzero(done):
                expected.append(current[i])
                current[i] = {}
            if done.any():
                obs, _ = rec.reset(options={"reset_mask": done})
        rec.reset(seed=1)  # cuts the episodes in flight short: not written
    finally:
        rec.close()
    assert rec.stats["episodes_cut"] == 3 and len(expected) == 4  # env 1 at step 2, both at the end
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("gym-pendulum").description)


def test_envs_on_other_hubs(two_hubs, tmp_path):
    """Envs on two other hubs (`envhub serve` on loopback, reached over Zenoh), frames
    included: the recorder sees the same Gymnasium vector env."""
    mujoco_or_skip(envhub)
    env = envhub.make_vec("mujoco-hopper", 2, hubs=["pya", "pyb"], render_mode="rgb_array",
                          max_episode_steps=12, width=32, height=32)
    assert env.placement == [("pya", 0, 1), ("pyb", 1, 2)]
    root = tmp_path / "remote"
    tap = FrameTap(env)
    rec = envhub.RecordEpisodes(tap, str(root))
    rng = np.random.default_rng(7)
    try:
        expected = drive(rec, 30, lambda obs: rng.uniform(-1, 1, (2, 3)).astype(np.float32), seed=2, frames=tap)
    finally:
        rec.close()
    assert len(expected) >= 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("mujoco-hopper").description,
                  video_key="observation.images.render")


def test_gymnasiums_own_vector_env(tmp_path):
    """Not only envhub's envs: Gymnasium's `SyncVectorEnv` records the same way (the task
    text is env 0's id)."""
    import gymnasium

    env = gymnasium.vector.SyncVectorEnv([lambda: gymnasium.make("CartPole-v1")] * 2)
    root = tmp_path / "sync"
    rec = envhub.RecordEpisodes(env, str(root))
    rng = np.random.default_rng(8)
    try:
        expected = drive(rec, 60, lambda obs: rng.integers(0, 2, 2), seed=4)
    finally:
        rec.close()
    summary, arrays = load(root)
    check_against(summary, arrays, expected, "CartPole-v1")


def _camera_env():
    import gymnasium

    env = gymnasium.make("InvertedPendulum-v5", render_mode="rgb_array", width=64, height=48, max_episode_steps=30)
    return gymnasium.wrappers.AddRenderObservation(env, render_only=False)


def test_dict_observation_with_a_camera(tmp_path):
    """A Dict observation with a camera image (Gymnasium's MuJoCo pendulum with its frames
    added to the observation), through the drop-in `envhub.AsyncVectorEnv`: the image
    becomes a video, the state a column."""
    env = envhub.AsyncVectorEnv([_camera_env, _camera_env])
    root = tmp_path / "camera"
    rec = envhub.RecordEpisodes(env, str(root), task="balance the pole")
    rng = np.random.default_rng(2)
    paths = {"observation.state": ("state",), "observation.images.pixels": ("pixels",)}
    try:
        expected = drive(rec, 40, lambda obs: rng.uniform(-3, 3, (2, 1)).astype(np.float32), seed=0, paths=paths)
    finally:
        rec.close()
    assert len(expected) >= 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, "balance the pole", cameras=("observation.images.pixels",))
    # The env renders too (`render_mode="rgb_array"`), so its `render()` frames are a video as well.
    assert summary["video_keys"] == ["observation.images.pixels", "observation.images.render"]


def test_a_suites_camera_observations(tmp_path):
    """A suite's own cameras: robosuite's Lift with agentview and wrist images (in its own
    Python environment, as `pyenv/test_suites.py` builds it): two videos and sixteen columns.
    robosuite's envs declare no frame rate: its control rate, 20 Hz, is given."""
    try:
        env = envhub.make_vec("robosuite-lift-camera", 1, max_episode_steps=6)
    except envhub.EnvHubError as e:
        message = f"robosuite's environment cannot run here ({str(e).splitlines()[0]})"
        if os.environ.get("ENVHUB_SUITES_REQUIRED"):
            pytest.fail(f"{message}, and ENVHUB_SUITES_REQUIRED is set")
        pytest.skip(message)
    from envhub.recording._features import observation_columns

    paths = {c.name: c.path for c in observation_columns(env.single_observation_space)}
    cameras = tuple(name for name in paths if name.startswith("observation.images."))
    assert cameras == ("observation.images.agentview_image", "observation.images.robot0_eye_in_hand_image")
    root = tmp_path / "lift"
    rec = envhub.RecordEpisodes(env, str(root), fps=20)
    rng = np.random.default_rng(5)
    try:
        expected = drive(rec, 13, lambda obs: rng.uniform(-1, 1, (1, 7)).astype(np.float32), seed=0, paths=paths)
    finally:
        rec.close()
    assert len(expected) == 2
    summary, arrays = load(root)
    check_against(summary, arrays, expected, envhub.EnvRegistry().get("robosuite-lift-camera").description,
                  cameras=cameras)
    assert summary["fps"] == 20 and len(summary["features"]) == len(paths) + 5 + 5
