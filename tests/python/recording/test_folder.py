"""The dataset folder: one writer at a time until its private folder is gone, refusals that
touch nothing, clear errors for folders that cannot be written, and camera statistics as
LeRobot computes them.
"""

from __future__ import annotations

import json
import os
import subprocess
import textwrap

import gymnasium
import numpy as np
import pytest
from harness import import_envhub
from lerobot_datasets import lerobot_python, snapshot

envhub = import_envhub()
from envhub.recording import _dataset  # noqa: E402


def _pendulums(n: int = 2, steps: int = 5):
    return gymnasium.vector.SyncVectorEnv([lambda: gymnasium.make("Pendulum-v1", max_episode_steps=steps)] * n)


def _open(root) -> envhub.RecordEpisodes:
    rec = envhub.RecordEpisodes(_pendulums(), str(root), video=False)
    try:
        rec.reset(seed=0)
    except BaseException:
        rec.close()
        raise
    return rec


def _record(root, steps: int = 12) -> None:
    rec = _open(root)
    try:
        for _ in range(steps):
            rec.step(np.zeros((2, 1), np.float32))
    finally:
        rec.close()


def test_the_lock_holds_until_the_private_folder_is_gone(tmp_path, monkeypatch):
    """A writer that opened the lock file just before the holder closed (which removes the
    private folder, lock file included) must not get in beside the next writer: its lock on the
    removed file is noticed, and it is refused while the next writer holds the new one."""
    root = tmp_path / "d"
    first = _open(root)
    stale = open(root / ".envhub" / "lock", "a")  # a second writer, between its open and its flock
    first.close()
    assert not (root / ".envhub").exists()
    third = _open(root)
    try:
        real_open = open
        handed = []

        def late_open(path, *args, **kwargs):
            if str(path).endswith(os.path.join(".envhub", "lock")) and not handed:
                handed.append(path)
                return stale  # the file it opened before the first writer closed
            return real_open(path, *args, **kwargs)

        monkeypatch.setattr(_dataset, "open", late_open, raising=False)
        with pytest.raises(envhub.recording.RecordingError, match="being written by another recorder"):
            _open(root)
        assert handed and stale.closed
    finally:
        monkeypatch.undo()
        third.close()
    assert not (root / ".envhub").exists()


def test_refusals_touch_nothing(tmp_path):
    """An `info.json` counting more episodes than `meta/episodes/` describes is refused, and the
    folder is left byte for byte as it was (no `.envhub/`, no staging)."""
    root = tmp_path / "d"
    _record(root)
    info = json.loads((root / "meta/info.json").read_text())
    info["total_episodes"] += 3
    (root / "meta/info.json").write_text(json.dumps(info))
    before = snapshot(root)
    with pytest.raises(envhub.recording.DatasetLayoutError, match="describes 4 of them"):
        _open(root)
    assert snapshot(root) == before


def test_a_dangling_link_and_a_read_only_folder_are_clear_errors(tmp_path):
    """A dangling symbolic link names where it points; a folder on a read-only mount, and a
    new dataset inside one, say that the folder cannot be written (and nothing is written)."""
    link = tmp_path / "link"
    link.symlink_to(tmp_path / "nowhere")
    with pytest.raises(envhub.recording.DatasetLayoutError, match="symbolic link to .*nowhere.*does not exist"):
        _open(link)
    assert not (tmp_path / "nowhere").exists() and link.is_symlink()

    mount = tmp_path / "ro"
    mount.mkdir()
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=1m", "tmpfs", str(mount)], capture_output=True)
    if done.returncode != 0:
        pytest.skip(f"a read-only mount needs root here ({done.stderr.decode().strip()})")
    try:
        for root in (mount, mount / "new" / "dataset"):
            with pytest.raises(envhub.recording.RecordingError, match="not writable by this process"):
                _open(root)
        assert os.listdir(mount) == []
    finally:
        subprocess.run(["umount", str(mount)], check=True)


LEROBOT_CAMERA_STATS = textwrap.dedent(
    """\
    # In LeRobot's interpreter: LeRobot's own statistics of each episode's frames (as its writer
    # computes them from the images), against the episodes file's.
    import json, sys
    from pathlib import Path
    import numpy as np, pyarrow as pa, pyarrow.parquet as pq
    try:
        from lerobot.datasets.compute_stats import get_feature_stats
    except ImportError:
        from ledataset.datasets.compute_stats import get_feature_stats

    root, frames = Path(sys.argv[1]), np.load(sys.argv[2])
    eps = pa.concat_tables([pq.read_table(p) for p in sorted((root / "meta/episodes").glob("*/*.parquet"))])
    key = "observation.images.pixels"
    worst, counts = 0.0, []
    for e in range(eps.num_rows):
        lo, hi = eps.column("dataset_from_index")[e].as_py(), eps.column("dataset_to_index")[e].as_py()
        # Every frame (episodes of up to 100 frames), in float64: LeRobot squares its uint8 frames
        # in uint8, which overflows its std (documented).
        images = frames[lo:hi].transpose(0, 3, 1, 2).astype(np.float64)
        want = get_feature_stats(images, axis=(0, 2, 3), keepdims=True)
        for name in ("min", "max", "mean", "std", "q01", "q10", "q50", "q90", "q99"):
            w = np.squeeze(np.asarray(want[name], dtype=np.float64) / 255.0, axis=0).reshape(-1)
            got = np.asarray(eps.column(f"stats/{key}/{name}")[e].as_py(), dtype=np.float64).reshape(-1)
            worst = max(worst, float(np.max(np.abs(got - w))))
        counts.append([int(want["count"][0]), int(eps.column(f"stats/{key}/count")[e].as_py()[0])])
    print(json.dumps({"worst": worst, "counts": counts}))
    """
)


def test_camera_statistics_are_lerobots_for_one_frame_episodes(tmp_path):
    """Episodes of one frame and of several: a camera's per-episode statistics (quantiles over
    the pixels, also for one frame) equal LeRobot's `get_feature_stats` over the frames drawn."""
    from drawn_env import KEY, Drawn, image

    class Short(Drawn):
        def step(self, action):
            obs, reward, _, _, info = super().step(action)
            return obs, reward, False, self.t >= (1 if self.ep % 2 == 0 else 7), info

    root = tmp_path / "d"
    rec = envhub.RecordEpisodes(gymnasium.vector.SyncVectorEnv([Short]), str(root), task="draw")
    try:
        rec.reset(seed=0)
        for _ in range(20):
            rec.step(np.zeros((1, 1), np.float32))
    finally:
        rec.close()
    import pyarrow.parquet as pq

    state = np.array(pq.read_table(root / "data/chunk-000/file-000.parquet").column("observation.state").to_pylist())
    lengths = pq.read_table(root / "meta/episodes/chunk-000/file-000.parquet").column("length").to_pylist()
    assert 1 in lengths and 7 in lengths
    drawn = tmp_path / "drawn.npy"
    np.save(drawn, np.stack([image(int(ep), int(t)) for ep, t in state]))
    script = tmp_path / "stats.py"
    script.write_text(LEROBOT_CAMERA_STATS)
    proc = subprocess.run([lerobot_python(), str(script), str(root), str(drawn)], capture_output=True, text=True,
                          timeout=600)
    assert proc.returncode == 0, proc.stderr[-4000:]
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["worst"] < 1e-9, result
    assert all(want == got for want, got in result["counts"]), result
    assert KEY == "observation.images.pixels"


CRASH_BEFORE_INFO = textwrap.dedent(
    """\
    # A commit on a file system without an atomic exchange, cut by a crash right before
    # `meta/info.json`'s rename (`stats.json` is renamed already).
    import os, sys
    import gymnasium, numpy as np
    import envhub
    from envhub.recording import _durable

    def hook(rel):
        if rel == "meta/info.json":
            os._exit(9)

    _durable._exchange = lambda a, b: False
    _durable.rename_hook = hook
    env = gymnasium.vector.SyncVectorEnv([lambda: gymnasium.make("Pendulum-v1", max_episode_steps=5)] * 2)
    rec = envhub.RecordEpisodes(env, sys.argv[1], video=False, commit_every=3600)
    rec.reset(seed=1)
    for _ in range(12):
        rec.step(np.ones((2, 1), np.float32))
    rec.close()
    """
)


def test_stats_describe_the_committed_frames_after_a_crash_without_exchange(tmp_path):
    """Without `RENAME_EXCHANGE`, a crash between `stats.json`'s rename and `info.json`'s leaves
    a `stats.json` counting frames never committed; the next recording that opens the folder
    puts back the statistics of the committed episodes (from `meta/episodes/`) before anything
    else, and its own commit adds to those."""
    import sys

    root = tmp_path / "d"
    _record(root)  # 4 episodes of 5 frames
    committed = json.loads((root / "meta/stats.json").read_text())
    script = tmp_path / "crash.py"
    script.write_text(CRASH_BEFORE_INFO)
    proc = subprocess.run([sys.executable, str(script), str(root)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == 9, proc.stderr[-3000:]
    info = json.loads((root / "meta/info.json").read_text())
    assert info["total_frames"] == 20
    assert json.loads((root / "meta/stats.json").read_text())["action"]["count"] == [40]  # the window
    with pytest.warns(UserWarning, match="did not describe the committed episodes"):
        rec = _open(root)
    rec.close()
    restored = json.loads((root / "meta/stats.json").read_text())
    assert restored.keys() == committed.keys()
    for key, stats in committed.items():
        for name, value in stats.items():
            np.testing.assert_allclose(restored[key][name], value, rtol=1e-12, atol=1e-15, err_msg=f"{key} {name}")
    _record(root)
    assert json.loads((root / "meta/stats.json").read_text())["action"]["count"] == [40]
