"""Which episodes a recording keeps and what becomes of a dataset's folder: `keep="success"`,
appending to a dataset (and refusing one of another layout), one recorder per folder, a full
queue (waiting or dropping whole episodes, and saying so), and a recorder killed mid-write or
crashed between renames. Judged by LeRobot's own loader (`support/lerobot_datasets.py`)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
import warnings

import numpy as np
import pytest
from harness import import_envhub, mujoco_or_skip
from lerobot_datasets import (
    check_against,
    load,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
)
from recorded_episodes import drive

envhub = import_envhub()
os.environ.setdefault("MUJOCO_GL", "egl")  # Gymnasium's own MuJoCo rendering in hosted workers


# Filters, appending, layouts ---------------------------------------------------------------


def test_success_only_keeps_successful_episodes(tmp_path):
    """`keep="success"` on FetchReach (`is_success` info): env 0 reaches the goal (scripted),
    env 1 moves at random; only successful episodes are written, the others counted."""
    env = envhub.make_vec("fetch-reach", 2, num_workers=1)
    root = tmp_path / "fetch"
    rec = envhub.RecordEpisodes(env, str(root), keep="success", max_episodes=2)
    rng = np.random.default_rng(4)

    def act(obs):
        a = rng.uniform(-1, 1, (2, 4)).astype(np.float32)
        a[0, :3] = np.clip(10 * (obs["desired_goal"][0] - obs["achieved_goal"][0]), -1, 1)
        a[0, 3] = 0
        return a

    try:
        obs, _ = rec.reset(seed=0)
        for _ in range(300):
            obs, *_ = rec.step(act(obs))
            if rec.stats["episodes_kept"] >= 2 and rec.stats["episodes_filtered"] >= 1:
                break
    finally:
        rec.close()
    assert rec.stats["episodes_written"] == 2 and rec.stats["episodes_filtered"] >= 1
    summary, arrays = load(root)
    assert summary["num_episodes"] == 2 and summary["episode_success"] == [True, True]
    assert {"observation.observation", "observation.achieved_goal", "observation.desired_goal"} <= set(
        summary["features"]
    )


def test_success_only_needs_a_success_info(tmp_path):
    mujoco_or_skip(envhub)
    env = envhub.make_vec("mujoco-hopper", 1, max_episode_steps=3)
    rec = envhub.RecordEpisodes(env, str(tmp_path / "d"), keep="success")
    try:
        rec.reset(seed=0)
        with pytest.raises(envhub.recording.RecordingError, match="`success` or `is_success`"):
            for _ in range(4):
                rec.step(rec.action_space.sample())
    finally:
        rec.close()


def test_append_and_a_dataset_of_another_layout(tmp_path):
    """Recording into an existing dataset appends episodes (indices go on); a dataset of
    another layout, or a folder that holds something else, is an error naming the mismatch."""
    root = tmp_path / "pendulum"
    first = envhub.record("gym-pendulum", 2, root, num_envs=2, video=False, max_episode_steps=8, seed=0)
    second = envhub.record("gym-pendulum", 3, root, num_envs=2, video=False, max_episode_steps=8, seed=7)
    assert first["episodes_written"] == 2 and second["episodes_written"] == 3
    summary, arrays = load(root)
    assert summary["num_episodes"] == 5 and summary["episode_lengths"] == [8] * 5
    np.testing.assert_array_equal(arrays["raw/episode_index"], np.repeat(np.arange(5), 8))
    np.testing.assert_array_equal(arrays["raw/index"], np.arange(40))

    with pytest.raises(envhub.recording.DatasetLayoutError) as err:
        envhub.record("gym-cartpole", 1, root, video=False)
    message = str(err.value)
    assert "feature `observation.state` is `float32` of shape [3] there, `float32` of shape [4] here" in message
    assert "feature `action`" in message and "hint:" in message
    other = tmp_path / "other"
    other.mkdir()
    (other / "notes.txt").write_text("mine")
    with pytest.raises(envhub.recording.DatasetLayoutError, match="holds no LeRobot dataset"):
        envhub.record("gym-pendulum", 1, other, video=False)
    assert (other / "notes.txt").read_text() == "mine"


def test_a_second_recorder_on_the_same_folder_is_refused(tmp_path):
    env_a = envhub.make_vec("gym-pendulum", 1)
    env_b = envhub.make_vec("gym-pendulum", 1)
    a = envhub.RecordEpisodes(env_a, str(tmp_path / "d"), video=False)
    b = envhub.RecordEpisodes(env_b, str(tmp_path / "d"), video=False)
    try:
        a.reset(seed=0)
        with pytest.raises(envhub.recording.RecordingError, match="being written by another recorder"):
            b.reset(seed=0)
    finally:
        a.close()
        b.close()


# The queue, crashes ------------------------------------------------------------------------


def _slow_writer_env():
    """Frames that take the writer far longer to encode (AV1 through libaom, 256x256) than
    the env takes to step and draw them."""
    mujoco_or_skip(envhub)
    return envhub.make_vec("mujoco-inverted-pendulum", 2, num_workers=1, render_mode="rgb_array",
                           max_episode_steps=20, width=256, height=256)


def test_full_queue_waits_and_says_so(tmp_path):
    env = _slow_writer_env()
    rec = envhub.RecordEpisodes(env, str(tmp_path / "d"), queue_bytes=1, when_full="wait", codec="libaom-av1")
    try:
        with pytest.warns(envhub.recording.QueueFullWarning, match="steps wait for the writer"):
            expected = drive(rec, 45, lambda obs: np.zeros((2, 1), np.float32), seed=0)
    finally:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec.close()
    assert rec.stats["steps_waited"] > 0 and rec.stats["seconds_waited"] > 0
    assert rec.stats["episodes_dropped"] == 0 and rec.stats["episodes_written"] == len(expected)
    summary, arrays = load(tmp_path / "d")
    check_against(summary, arrays, expected, summary["tasks"][0])


def test_full_queue_drops_whole_episodes_and_says_so(tmp_path):
    env = _slow_writer_env()
    rec = envhub.RecordEpisodes(env, str(tmp_path / "d"), queue_bytes=1, when_full="drop", codec="libaom-av1")
    try:
        with pytest.warns(envhub.recording.QueueFullWarning, match="a step is dropped"):
            expected = drive(rec, 100, lambda obs: np.zeros((2, 1), np.float32), seed=0)
    finally:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec.close()
    s = rec.stats
    assert s["steps_dropped"] > 0 and s["episodes_dropped"] > 0
    assert s["episodes_written"] + s["episodes_dropped"] <= len(expected) + rec.num_envs
    if s["episodes_written"]:
        # Whatever was written is whole: each episode is one the session ran, every frame of it
        # (the pendulum may fall before the 20-step limit, so lengths are the session's).
        summary, arrays = load(tmp_path / "d")
        assert len(summary["episode_lengths"]) == s["episodes_written"]
        for e in range(s["episodes_written"]):
            rows = arrays["raw/episode_index"] == e
            states = arrays["raw/observation.state"][rows]
            np.testing.assert_array_equal(arrays["raw/frame_index"][rows], np.arange(len(states)))
            same = [ep for ep in expected if np.array_equal(np.stack(ep["observation.state"]), states)]
            assert same, f"written episode {e} ({len(states)} frames) is none the session ran whole"


CRASHING_RECORDER = textwrap.dedent(
    """\
    import sys, numpy as np, envhub
    env = envhub.make_vec("mujoco-inverted-pendulum", 2, num_workers=1, render_mode="rgb_array",
                          max_episode_steps=10, width=32, height=32)
    rec = envhub.RecordEpisodes(env, sys.argv[1], commit_every=0.05)
    rec.reset(seed=0)
    while True:
        rec.step(np.zeros((2, 1), np.float32))
    """
)


def test_a_killed_recorder_leaves_a_dataset_that_loads(tmp_path):
    """`kill -9` in the middle of recording: the dataset loads with the episodes committed,
    and recording into it again appends after them."""
    mujoco_or_skip(envhub)
    root = tmp_path / "crash"
    script = tmp_path / "crash.py"
    script.write_text(CRASHING_RECORDER)
    proc = subprocess.Popen([sys.executable, str(script), str(root)], stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            info = root / "meta" / "info.json"
            if info.exists() and json.loads(info.read_text())["total_episodes"] >= 6:
                break
            assert proc.poll() is None, proc.stderr.read()
            time.sleep(0.02)
        else:
            pytest.fail("the recorder committed no 6 episodes in 120 s")
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    summary, _ = load(root)
    committed = summary["num_episodes"]
    assert committed >= 6 and summary["episode_lengths"] == [10] * committed
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # files a crash left are removed, and said so
        envhub.record("mujoco-inverted-pendulum", 2, root, num_envs=2, max_episode_steps=10, width=32, height=32)
    summary, arrays = load(root)
    assert summary["num_episodes"] == committed + 2 and summary["episode_lengths"][:committed] == [10] * committed
    np.testing.assert_array_equal(arrays["raw/index"], np.arange(summary["num_frames"]))
    np.testing.assert_array_equal(np.unique(arrays["raw/episode_index"]), np.arange(committed + 2))


def test_files_a_crash_left_between_renames_are_removed(tmp_path):
    """A crash after a commit renamed its data and episode files into place but before
    `meta/info.json` leaves files the totals do not count: the next recording removes them,
    says so, and appends."""
    import shutil

    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    root = tmp_path / "d"
    envhub.record("gym-pendulum", 2, root, num_envs=2, video=False, max_episode_steps=5)
    # What such a crash leaves: the data file and episodes file of a commit (episodes 2 and 3)
    # that `info.json` never counted.
    shutil.copy(root / "data/chunk-000/file-000.parquet", root / "data/chunk-000/file-001.parquet")
    episodes = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet")
    column = episodes.schema.get_field_index("episode_index")
    episodes = episodes.set_column(column, "episode_index", pc.add(episodes.column(column), 2))
    pq.write_table(episodes, root / "meta/episodes/chunk-000/file-001.parquet")
    with pytest.warns(UserWarning, match=r"removed 2 file\(s\) of episodes that a crash left uncommitted"):
        envhub.record("gym-pendulum", 1, root, video=False, max_episode_steps=5)
    summary, arrays = load(root)
    assert summary["num_episodes"] == 3 and summary["num_frames"] == 15
    np.testing.assert_array_equal(arrays["raw/index"], np.arange(15))
