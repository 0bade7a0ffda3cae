"""What a commit costs does not grow with the commits before it (issue 52): during a long
episode, other envs' short episodes are committed hundreds of times.

Commits write small files that later commits join (`_files.py`), and a join re-points the
joined episodes by rewriting the episodes files that hold them. Two costs grew with the
number of commits: files were joined and rewritten a row group at a time and kept every row
group they read, one per commit, so a file's row groups, its footer and the work of every
later join or rewrite of it (a read and a write per group) grew with the commits; and an
episodes file joined across two data files was rewritten whole by a join that moved a part of
it, so a re-pointing wrote up to every episode committed. Work is counted here (row groups,
rows written), not timed."""

from __future__ import annotations

import os
import shutil
import tempfile
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pyarrow.parquet as pq
import pytest
from gymnasium import spaces
from harness import import_envhub
from lerobot_datasets import recording_deps  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)

envhub = import_envhub()


class _Short(gymnasium.Env):
    """Random 16-wide states; episodes `length` steps long."""

    metadata = {"render_fps": 30}

    def __init__(self, length: int, seed: int) -> None:
        self.observation_space = spaces.Box(-1, 1, (16,), np.float64)
        self.action_space = spaces.Box(-1, 1, (1,), np.float32)
        self.length, self.t, self.rng = length, 0, np.random.default_rng(seed)

    def reset(self, *, seed=None, options=None):
        self.t = 0
        return self.rng.random(16), {}

    def step(self, action):
        self.t += 1
        return self.rng.random(16), 0.0, False, self.t >= self.length, {}


@pytest.fixture
def fast_folder(tmp_path):
    """A folder on tmpfs where there is one (`/dev/shm`, where envhub's shared memory lives):
    each commit fsyncs its files, which on a disk is most of the time of 100 commits."""
    shm = Path("/dev/shm")
    if not (shm.is_dir() and os.access(shm, os.W_OK)):
        yield tmp_path
        return
    folder = Path(tempfile.mkdtemp(prefix="envhub-test-commits-", dir=shm))
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _row_groups(root: Path) -> tuple[int, int]:
    """The data and episodes files of the dataset at `root`, and their row groups."""
    files = [*root.glob("data/*/*.parquet"), *root.glob("meta/episodes/*/*.parquet")]
    return len(files), sum(pq.ParquetFile(p).num_row_groups for p in files)


def test_row_groups_do_not_grow_with_the_commits(fast_folder, monkeypatch):
    """Env 0's episode lasts the whole recording; env 1's last 2 steps, each committed as it
    ends: 80 commits. After each, the dataset's data and episodes files hold a few row groups
    (about 4 MiB each; these files are far smaller), not one per commit joined into them (80
    at the close before), so a commit's joins and re-pointings read and write a few groups;
    and each re-pointing writes the episodes its join moves, not whole episodes files."""
    from envhub.recording import _dataset

    root = fast_folder / "d"
    after: list[tuple[int, int]] = []  # per commit: files, row groups
    moves: list[tuple[int, int]] = []  # per re-pointing between commits: episodes moved, rows written
    closing: list[bool] = []
    real, real_repoint = _dataset.Dataset.commit, _dataset.Dataset._repoint

    def commit(self, episodes):
        out = real(self, episodes)
        after.append(_row_groups(root))
        return out

    def repoint(self, commit, files, parts, at, shifts):
        written = len(commit._written)
        real_repoint(self, commit, files, parts, at, shifts)
        if not closing:
            moves.append((sum(p.episodes for p in parts),
                          sum(pq.read_metadata(p).num_rows for p in commit._written[written:])))

    monkeypatch.setattr(_dataset.Dataset, "commit", commit)
    monkeypatch.setattr(_dataset.Dataset, "_repoint", repoint)
    env = gymnasium.vector.SyncVectorEnv([lambda: _Short(10**6, 0), lambda: _Short(2, 1)])
    # A queue of one step: each episode is committed as it ends (a commit comes early once the
    # ended episodes' rows reach `queue_bytes`).
    rec = envhub.RecordEpisodes(env, str(root), video=False, queue_bytes=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the queue is full at every step
        rec.reset(seed=0)
        for _ in range(240):
            rec.step(np.zeros((2, 1), np.float32))
        closing.append(True)  # the close joins every run whole, re-pointing all (once)
        rec.close()  # the last commit, then every run joined into one file (LeRobot's layout)
    assert len(after) == 80 == rec.stats["episodes_written"]
    grew = [(k, files, groups) for k, (files, groups) in enumerate(after) if groups > files]
    assert not grew, f"commits after which files held more than a row group each (commit, files, groups): {grew[-3:]}"
    # Each re-pointing wrote the episodes it moved, no more (before: whole episodes files, up
    # to every episode committed).
    assert len(moves) > 40
    wasted = [m for m in moves if m[1] != m[0]]
    assert not wasted, f"{len(wasted)} of {len(moves)} re-pointings wrote other episodes too (moved, written): {wasted[-3:]}"
    files, groups = _row_groups(root)
    assert (files, groups) == (2, 2)
    assert pq.read_metadata(root / "data" / "chunk-000" / "file-000.parquet").num_rows == 160
