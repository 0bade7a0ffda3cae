"""The recorder never touches what is not its own (a refused folder is left byte for byte, an
accepted one keeps the user's files), a crash between any two renames leaves the last commit,
and its queue is bounded in bytes and its encoding in threads."""

from __future__ import annotations

import os
import textwrap
import warnings

import numpy as np
import pytest
from harness import import_envhub, mujoco_or_skip
from lerobot_datasets import (
    load,
    recording_deps,  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)
    snapshot,
)

envhub = import_envhub()


# What is not the recorder's ---------------------------------------------------------------------


def _users_files(root) -> None:
    (root / "data").mkdir(parents=True, exist_ok=True)
    (root / "data" / "mine.parquet").write_bytes(b"PAR1 not the recorder's PAR1")
    (root / "videos" / "cam" / "take1").mkdir(parents=True, exist_ok=True)
    (root / "videos" / "cam" / "take1" / "clip.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42 a user's clip")
    (root / "notes").mkdir(exist_ok=True)


def test_a_refused_folder_is_left_byte_for_byte_as_it_was(tmp_path):
    """A non-empty folder that holds no dataset is refused, and refused again: nothing in it
    changes (every file's hash, every folder), and no `.envhub/` is left."""
    root = tmp_path / "foreign"
    _users_files(root)
    (root / "notes" / "todo.txt").write_text("mine")
    before = snapshot(root)
    for _ in range(2):
        with pytest.raises(envhub.recording.DatasetLayoutError, match="holds no LeRobot dataset"):
            envhub.record("gym-pendulum", 1, root, video=False, max_episode_steps=5)
        assert snapshot(root) == before
    assert not (root / ".envhub").exists()
    # A dataset of another layout is refused untouched too.
    ds = tmp_path / "pendulum"
    envhub.record("gym-pendulum", 1, ds, video=False, max_episode_steps=5)
    before = snapshot(ds)
    with pytest.raises(envhub.recording.DatasetLayoutError, match="another layout"):
        envhub.record("gym-cartpole", 1, ds, video=False)
    assert snapshot(ds) == before


def test_an_accepted_recording_never_deletes_the_users_files(tmp_path):
    """Files in a dataset's folders that the recorder does not write (a clip under `videos/`,
    a Parquet file under `data/` of another name) survive appending, and the crash clean-up of
    a first commit that never finished."""
    root = tmp_path / "pendulum"
    envhub.record("gym-pendulum", 2, root, num_envs=2, video=False, max_episode_steps=5)
    _users_files(root)
    theirs = {k: v for k, v in snapshot(root).items() if "mine" in k or "take1" in k or k.startswith("notes")}
    envhub.record("gym-pendulum", 2, root, num_envs=2, video=False, max_episode_steps=5)
    after = snapshot(root)
    assert {k: after.get(k) for k in theirs} == theirs
    summary, _ = load(root)
    assert summary["num_episodes"] == 4
    # A recording that crashed before its first commit left `.envhub/`; the user's files next to
    # what it left are theirs still.
    crashed = tmp_path / "crashed"
    (crashed / ".envhub" / "staging").mkdir(parents=True)
    (crashed / "videos" / "cam" / "take1").mkdir(parents=True)
    (crashed / "videos" / "cam" / "take1" / "clip.mp4").write_bytes(b"a user's clip")
    envhub.record("gym-pendulum", 1, crashed, video=False, max_episode_steps=5)
    assert (crashed / "videos" / "cam" / "take1" / "clip.mp4").read_bytes() == b"a user's clip"


# Durability ------------------------------------------------------------------------------------

CRASH_BETWEEN_RENAMES = textwrap.dedent(
    """\
    import os, sys
    import envhub
    from envhub.recording import _durable

    root, crash_at = sys.argv[1], int(sys.argv[2])
    renames = []

    def hook(rel):
        renames.append(rel)
        print(rel, flush=True)
        if len(renames) == crash_at:
            os._exit(9)  # a crash: nothing after this runs, nothing is cleaned up

    _durable.rename_hook = hook
    envhub.record("mujoco-inverted-pendulum", 3, root, num_envs=3, max_episode_steps=6, width=32, height=32,
                  seed=5, recorder={"commit_every": 3600})
    """
)


def _record_pendulums(root, episodes: int, seed: int) -> None:
    envhub.record("mujoco-inverted-pendulum", episodes, root, num_envs=3, max_episode_steps=6, width=32,
                  height=32, seed=seed)


def test_a_crash_between_any_two_renames_leaves_the_last_commit(tmp_path):
    """A commit's renames, each one the last thing a process does (`os._exit` from the rename
    hook): the dataset loads, and equals the last commit (meta files, stats included, change
    together); the next recording appends after it."""
    import shutil
    import subprocess
    import sys

    mujoco_or_skip(envhub)
    base = tmp_path / "base"
    _record_pendulums(base, 3, seed=0)
    ref_summary, ref = load(base)
    ref_meta = snapshot(base / "meta")
    script = tmp_path / "crash.py"
    script.write_text(CRASH_BETWEEN_RENAMES)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    crash_at, renames = 1, None
    while True:
        root = tmp_path / f"crash{crash_at}"
        shutil.copytree(base, root)
        proc = subprocess.run([sys.executable, str(script), str(root), str(crash_at)], capture_output=True,
                              text=True, timeout=300, env=env)
        if proc.returncode == 0:  # past the last rename: the whole commit is there
            renames = crash_at - 1
            break
        assert proc.returncode == 9, proc.stderr[-3000:]
        assert snapshot(root / "meta") == ref_meta, f"crash at rename {crash_at}: meta/ changed"
        summary, arrays = load(root)
        n = ref_summary["num_frames"]
        assert {k: summary[k] for k in ("num_episodes", "num_frames", "episode_lengths", "stats_keys")} == {
            k: ref_summary[k] for k in ("num_episodes", "num_frames", "episode_lengths", "stats_keys")}
        for key, values in ref.items():
            got = arrays[key][: len(values)] if key.startswith("raw/") else arrays[key]
            assert got.shape[0] >= n and np.array_equal(got[: len(values)], values), (crash_at, key)
        # Recording again removes what the crash left and appends after the last commit.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            _record_pendulums(root, 3, seed=9)
        summary, arrays = load(root)
        assert summary["num_episodes"] == 6 and summary["episode_lengths"][:3] == ref_summary["episode_lengths"]
        np.testing.assert_array_equal(arrays["raw/index"], np.arange(summary["num_frames"]))
        for key in ("raw/observation.state", "raw/action"):
            np.testing.assert_array_equal(arrays[key][:n], ref[key])
        crash_at += 1
    # The data file and the video file, each the last one with rows and frames appended, and
    # `meta/` (exchanged whole).
    assert renames == 3, renames


# Bounded in bytes and threads --------------------------------------------------------------------


def _threads() -> int:
    with open("/proc/self/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("Threads:"))


def test_the_queue_is_bounded_in_bytes_and_encoding_in_threads(tmp_path, null_registry):
    """Eight envs of 128x128 frames (48 KiB each, 384 KiB a step) that step far faster than
    the writer encodes them: the queue never holds more than its byte budget (the step being
    written included), and encoding takes no more threads than `encode_threads` (one per
    encoder, FFmpeg's default being one per core for each of the eight)."""
    env = envhub.make_vec("null-env", 8, num_workers=1, registry=null_registry, frame=[128, 128, 3],
                          max_episode_steps=10)
    budget = 1_000_000  # two steps and a half
    rec = envhub.RecordEpisodes(env, str(tmp_path / "d"), fps=30, task="nothing", queue_bytes=budget,
                                encode_threads=2)
    before = _threads()
    most = before
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec.reset(seed=0)
            for _ in range(40):
                rec.step(np.zeros(8, np.int64))
                most = max(most, _threads())
    finally:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            rec.close()
    step = 8 * 128 * 128 * 3
    assert rec.stats["steps_waited"] > 0, "the writer kept up: the budget was never reached"
    assert step < rec.stats["queue_bytes_peak"] <= budget
    assert most - before <= 1 + 2, f"{most - before} threads more while recording (writer + 2 encoders)"
    assert rec.stats["episodes_written"] == 24
    other = envhub.make_vec("gym-pendulum", 1)
    try:
        with pytest.raises(ValueError, match="queue_bytes"):
            envhub.RecordEpisodes(other, str(tmp_path / "e"), queue_bytes=0)
    finally:
        other.close()
