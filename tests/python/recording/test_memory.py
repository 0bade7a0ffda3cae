"""The recorder's memory: what it holds above the process once the dataset is opened stays
under `queue_bytes` plus the constant docs/guide/recording.md states, however long the episodes
(issue 42): rows past a budget go to files in the dataset's staging folder, and commits read
them back a row group or a statistics' slice at a time, writing what memory would have.

A memory bound, not a time bound: the scenario is the benchmark's (`bench_record_append.py
memory`), in a process of its own so that nothing else's memory counts."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import gymnasium
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
from gymnasium import spaces
from harness import REPO_ROOT, import_envhub
from lerobot_datasets import recording_deps  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)

envhub = import_envhub()
MIB = 2**20
#: docs/guide/recording.md's constant: what a recording holds beyond `queue_bytes` (allocators,
#: the rows held before they go to files, a commit's row groups and statistics' slices).
CONSTANT_MIB = 80


def _bench(envs: int, long: int) -> dict:
    script = REPO_ROOT / "python" / "bench" / "bench_record_append.py"
    proc = subprocess.run([sys.executable, str(script), "memory", "--envs", str(envs), "--long", str(long)],
                          capture_output=True, text=True, timeout=1200,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_long_episode_stays_within_the_constant():
    """2 envs with 4 KiB observations, env 0's episode 6,000 steps (24 MiB of rows) beside
    about 550 ended 10-step episodes of env 1, a 1 MiB queue: the bound is 1 + 80 MiB whatever
    the episode's length (measured 22 MiB held, 51 MiB at the peak). Before the rows went to
    files, the episode's rows stayed in memory until its commit, which copied them: 62 MiB held
    and 142 MiB at the peak."""
    out = _bench(2, 6000)
    bound = out["queue_bytes"] + CONSTANT_MIB * MIB
    assert out["written"] > 500
    assert out["held_above_mib"] * MIB < bound, out
    assert out["peak_above_mib"] * MIB < bound, out


class _Varied(gymnasium.Env):
    """Random wide observations; env 0's episodes are long, the others' of random lengths."""

    metadata = {"render_fps": 30}

    def __init__(self, k: int) -> None:
        self.k, self.rng = k, np.random.default_rng(k)
        self.observation_space = spaces.Box(-1, 1, (64,), np.float64)
        self.action_space = spaces.Box(-1, 1, (2,), np.float32)

    def reset(self, *, seed=None, options=None):
        self.t, self.n = 0, 400 if self.k == 0 else int(self.rng.integers(1, 30))
        return self.rng.normal(size=64) * 10.0**self.k, {}

    def step(self, action):
        self.t += 1
        obs = self.rng.normal(size=64) if self.k != 2 else np.round(self.rng.normal(size=64))
        return obs, float(self.rng.normal()), self.t >= self.n and self.k == 1, self.t >= self.n, {}


def _record(root, monkeypatch, spill_bytes: int) -> tuple:
    from envhub.recording import _rows

    monkeypatch.setattr(_rows, "SPILL_BYTES", spill_bytes)
    files = []

    class Counted(_rows.Spill):
        def __init__(self, path):
            files.append(path)
            super().__init__(path)

    monkeypatch.setattr(_rows, "Spill", Counted)
    env = gymnasium.vector.SyncVectorEnv([lambda k=k: _Varied(k) for k in range(4)])
    rec = envhub.RecordEpisodes(env, str(root), video=False)
    rec.reset(seed=0)
    rng = np.random.default_rng(9)
    for _ in range(900):
        rec.step(rng.normal(size=(4, 2)).astype(np.float32))
    rec.close()
    tables = [pa.concat_tables([pq.read_table(p) for p in sorted(root.glob(f"{kind}/*/*.parquet"))])
              for kind in ("data", "meta/episodes")]
    return tables, json.loads((root / "meta" / "stats.json").read_text()), len(files)


def test_rows_written_from_files_equal_rows_from_memory(tmp_path, monkeypatch):
    """The same episodes recorded with every episode's rows in memory and with them going to
    files past 16 KiB of rows: the data and every episode's statistics are equal bit for bit
    (the dataset's, summed over commits that may fall elsewhere, to rounding); no file is left."""
    (data, episodes), stats, files = _record(tmp_path / "memory", monkeypatch, 2**40)
    (data_, episodes_), stats_, files_ = _record(tmp_path / "files", monkeypatch, 2**14)
    assert files == 0 and files_ > 20
    assert data.num_rows > 2000 and episodes.num_rows > 100
    assert data.equals(data_)
    assert episodes.select([n for n in episodes.column_names if n.startswith("stats/")]).equals(
        episodes_.select([n for n in episodes_.column_names if n.startswith("stats/")]))
    for key, values in stats.items():
        for name, value in values.items():
            np.testing.assert_allclose(stats_[key][name], value, rtol=1e-12, atol=1e-12)
    assert not (tmp_path / "files" / ".envhub").exists()
