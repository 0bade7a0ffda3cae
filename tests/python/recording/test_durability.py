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

    root, crash_at, exchange = sys.argv[1], int(sys.argv[2]), sys.argv[3] == "1"
    renames = []

    def hook(rel):
        renames.append(rel)
        print(rel, flush=True)
        if len(renames) == crash_at:
            os._exit(9)  # a crash: nothing after this runs, nothing is cleaned up

    _durable.rename_hook = hook
    if not exchange:  # as on a file system without RENAME_EXCHANGE
        _durable._exchange = lambda a, b: False
    envhub.record("mujoco-inverted-pendulum", 3, root, num_envs=3, max_episode_steps=6, width=32, height=32,
                  seed=5, recorder={"commit_every": 3600})
    """
)

# In LeRobot's interpreter, for each `ROOT\tCLEAN\tSCRATCH` line: what its loader gives of ROOT
# (per frame: index, episode, state, each camera's mean level), and what `aggregate_datasets`
# of ROOT and CLEAN holds (the same per frame, and the rows of its data files).
READERS = textwrap.dedent(
    """\
    import json, sys, traceback
    from pathlib import Path
    import pyarrow.parquet as pq
    try:
        from lerobot.datasets.lerobot_dataset import LeRobotDataset
        from lerobot.datasets.aggregate import aggregate_datasets
    except ImportError:
        from ledataset.datasets.lerobot_dataset import LeRobotDataset
        from ledataset.datasets.aggregate import aggregate_datasets

    def frames(ds):
        out = []
        for i in range(len(ds)):
            item = ds[i]
            out.append([int(item["index"]), int(item["episode_index"]), *item["observation.state"].tolist(),
                        *[round(float(item[k].mean()) * 255, 1) for k in ds.meta.video_keys]])
        return out

    for line in sys.stdin:
        try:
            root, clean, scratch = (Path(p) for p in line.rstrip("\\n").split("\\t"))
            ds = LeRobotDataset("envhub/crashed", root=root)
            aggregate_datasets(["envhub/crashed", "envhub/clean"], "envhub/aggr", roots=[root, clean],
                               aggr_root=scratch / "aggr")
            agg = LeRobotDataset("envhub/aggr", root=scratch / "aggr")
            out = {"ok": True, "episodes": ds.meta.total_episodes, "frames": frames(ds),
                   "aggregate": {"episodes": agg.meta.total_episodes, "frames": frames(agg),
                                 "rows": pq.read_table(scratch / "aggr" / "data").num_rows}}
        except Exception:
            out = {"ok": False, "error": traceback.format_exc()}
        print(json.dumps(out), flush=True)
    """
)


def _record_pendulums(root, episodes: int, seed: int) -> None:
    envhub.record("mujoco-inverted-pendulum", episodes, root, num_envs=3, max_episode_steps=6, width=32,
                  height=32, seed=seed)


# Slow: a crash at each rename of an append (its commit, then the joins of its files at close:
# about 15 with RENAME_EXCHANGE; 6 without, where files are not joined), each dataset read by
# LeRobot's loader and aggregated with `aggregate_datasets` (about 6 min on two busy cores).
@pytest.mark.slow
def test_a_crash_at_any_rename_shows_every_reader_the_last_commit(tmp_path):
    """An append (a commit, then the joins of its new files with the last ones), crashed at each
    of its renames (`os._exit` from the rename hook), with and without RENAME_EXCHANGE: LeRobot's
    loader gives exactly the episodes `meta/` counts, before or after the commit, frame for
    frame as a clean recording of them; `aggregate_datasets` of it and another dataset holds
    exactly those episodes' rows and frames and the other's (no row of a file no commit owns);
    the next recording appends after it."""
    import json
    import shutil
    import subprocess
    import sys

    from lerobot_datasets import lerobot_python

    python = lerobot_python()
    mujoco_or_skip(envhub)
    base, full, other = tmp_path / "base", tmp_path / "full", tmp_path / "other"
    _record_pendulums(base, 3, seed=0)
    shutil.copytree(base, full)
    _record_pendulums(full, 3, seed=5)
    _record_pendulums(other, 3, seed=4)
    (tmp_path / "crash.py").write_text(CRASH_BETWEEN_RENAMES)
    (tmp_path / "readers.py").write_text(READERS)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    readers = subprocess.Popen([python, str(tmp_path / "readers.py")], stdin=subprocess.PIPE,
                               stdout=subprocess.PIPE, text=True)

    def read(root):
        scratch = tmp_path / f"scratch-{root.name}"
        scratch.mkdir()
        readers.stdin.write(f"{root}\t{other}\t{scratch}\n")
        readers.stdin.flush()
        out = json.loads(readers.stdout.readline() or '{"ok": false, "error": "the readers died"}')
        assert out["ok"], out["error"]
        return out

    try:
        ref = {3: read(base), 6: read(full)}
        theirs = [f[2:] for f in read(other)["frames"]]
        for exchange in ("1", "0"):
            crash_at = 1
            while True:
                root = tmp_path / f"crash{exchange}-{crash_at}"
                shutil.copytree(base, root)
                proc = subprocess.run([sys.executable, str(tmp_path / "crash.py"), str(root), str(crash_at), exchange],
                                      capture_output=True, text=True, timeout=300, env=env)
                assert proc.returncode in (0, 9), proc.stderr[-3000:]
                where = (exchange, crash_at, proc.stdout.strip().splitlines()[-1:])
                got = read(root)
                assert got["episodes"] in ref, where
                want = ref[got["episodes"]]
                assert got["frames"] == want["frames"], where
                aggregated = got["aggregate"]
                if exchange == "1":  # without it, `meta/`'s files change one by one (see the report)
                    assert aggregated["episodes"] == got["episodes"] + 3, where
                    assert [f[2:] for f in aggregated["frames"]] == [f[2:] for f in want["frames"]] + theirs, where
                    assert aggregated["rows"] == len(aggregated["frames"]), where
                if proc.returncode == 0:
                    break
                # Recording again removes what the crash left and appends after the last commit.
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    _record_pendulums(root, 3, seed=9)
                summary, arrays = load(root)
                assert summary["num_episodes"] == got["episodes"] + 3, where
                np.testing.assert_array_equal(arrays["raw/index"], np.arange(summary["num_frames"]))
                crash_at += 1
            # The commit's renames and the joins' (none without an exchange: see `_join`).
            assert crash_at >= (10 if exchange == "1" else 6), (exchange, crash_at)
    finally:
        readers.stdin.close()
        readers.wait(timeout=60)


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


class _Camera:
    """An env whose observation is a 64x64 camera (each frame one level, by env and step),
    episodes of 4 steps."""

    metadata = {"render_fps": 30}

    def __init__(self, k: int) -> None:
        import gymnasium
        from gymnasium import spaces

        class Env(gymnasium.Env):
            metadata = {"render_fps": 30}
            observation_space = spaces.Dict({"pixels": spaces.Box(0, 255, (64, 64, 3), np.uint8)})
            action_space = spaces.Box(-1, 1, (1,), np.float32)

            def reset(self, *, seed=None, options=None):
                self.t = 0
                return {"pixels": np.full((64, 64, 3), 20 * k, np.uint8)}, {}

            def step(self, action):
                self.t += 1
                return {"pixels": np.full((64, 64, 3), 20 * k + 8 * self.t, np.uint8)}, 0.0, False, self.t >= 4, {}

        self.env = Env()


def _svt_threads() -> int:
    """The threads that one open SVT-AV1 encoder runs, opened with the recorder's settings."""
    import io

    import av
    from envhub.recording._encoding import requested

    encoding = requested("libsvtav1", None, None, "yuv420p", 64, 64)
    before = _threads()
    with av.open(io.BytesIO(), mode="w", format="mp4") as out:
        stream = out.add_stream("libsvtav1", rate=30, options=encoding.options())
        stream.width, stream.height, stream.pix_fmt = 64, 64, "yuv420p"
        frame = av.VideoFrame.from_ndarray(np.zeros((64, 64, 3), np.uint8), format="rgb24")
        frame.pts = 0
        out.mux(stream.encode(frame))
        opened = _threads() - before
        out.mux(stream.encode(None))
    return opened


def test_av1_encoding_keeps_one_svt_encoder_per_encoding_thread(tmp_path):
    """SVT-AV1 runs its own pipeline of threads in every open encoder (16 at its least,
    whatever FFmpeg's thread count), so an encoder per env and camera, open through each
    episode, took 16 threads per env (six envs, 96). Its episodes are encoded losslessly as
    they run and into AV1 when they end, on the `encode_threads` threads, one encoder each at
    a time: the recording adds at most the writer, two encoding threads and two SVT-AV1
    encoders' threads, and every frame decodes back."""
    import av
    import gymnasium

    svt = _svt_threads()
    assert svt >= 4, f"SVT-AV1 opened {svt} threads: this test needs an encoder with threads of its own"
    env = gymnasium.vector.SyncVectorEnv([lambda k=k: _Camera(k).env for k in range(6)])
    root = tmp_path / "d"
    rec = envhub.RecordEpisodes(env, str(root), codec="libsvtav1", encode_threads=2)
    before = _threads()
    most = before
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec.reset(seed=0)
        for _ in range(20):
            rec.step(np.zeros((6, 1), np.float32))
            most = max(most, _threads())
        rec.close()
    assert most - before <= 1 + 2 + 2 * svt, f"{most - before} threads more while recording ({svt} per SVT-AV1 encoder)"
    assert rec.stats["episodes_written"] == 24  # 4 episodes of 4 steps per env (every 5th step resets)
    (video,) = root.glob("videos/*/*/*.mp4")
    with av.open(str(video)) as src:
        assert src.streams.video[0].codec_context.name in ("av1", "libdav1d", "libaom-av1")
        frames = [f.to_ndarray(format="rgb24") for f in src.decode(video=0)]
    assert len(frames) == 24 * 4
