"""What a recording holds in memory beyond `queue_bytes`, and what a commit costs as the last
video file grows (issue 42's items 3 and 4: the figures docs/guide/recording.md gives).

    .venv/bin/python python/bench/bench_record_append.py memory [--envs 8] [--long 3000] [--steps N]
        [--short 10] [--commit-each] [--dir DIR]
    .venv/bin/python python/bench/bench_record_append.py append [--mb 200]

`memory`: Gymnasium vector env of `--envs` envs with 4 KiB observations (512 float64), env 0's
episodes `--long` steps, the others' `--short` (10), a 1 MiB queue (one step with `--commit-each`:
each ended episode is then committed at once), `--steps` steps (`--long` + 1 unless
given); the process's resident set is sampled
every 5 ms, and its rise over the baseline (after the first reset) reported, held at the end and
at the peak; and the commits made during env 0's episode: the time a commit took (wall, and
CPU of the writer thread, which commits), and the resident set after it (over the baseline),
each the mean over the first and over the last tenth of them (issue 52: neither may grow with the commits before). `append`: one env with 256x256 noise frames (large MP4 packets), episodes of 10 frames,
committed every 0.2 s (or 4x the last commit's time), until the camera's last video file (its
run of files, joined at the end) reaches `--mb` MB; each commit's time, episodes and the bytes
it wrote (`/proc/self/io` `wchar`, joins of small files included) against the file's size
before it.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import gymnasium
import numpy as np
from gymnasium import spaces

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from envhub.recording import (
    RecordEpisodes,
    _dataset,
)


def _rss() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class _Wide(gymnasium.Env):
    metadata = {"render_fps": 30}

    def __init__(self, length: int) -> None:
        self.observation_space = spaces.Box(-1, 1, (512,), np.float64)
        self.action_space = spaces.Box(-1, 1, (1,), np.float32)
        self.length, self.t = length, 0

    def reset(self, *, seed=None, options=None):
        self.t = 0
        return np.full(512, 0.5), {}

    def step(self, action):
        self.t += 1
        return np.full(512, self.t % 7 / 7), 0.0, False, self.t >= self.length, {}


class _Noise(gymnasium.Env):
    metadata = {"render_fps": 30}

    def __init__(self) -> None:
        self.observation_space = spaces.Dict({"pixels": spaces.Box(0, 255, (256, 256, 3), np.uint8)})
        self.action_space = spaces.Box(-1, 1, (1,), np.float32)
        self.rng = np.random.default_rng(0)
        self.t = 0

    def _obs(self):
        return {"pixels": self.rng.integers(0, 256, (256, 256, 3), dtype=np.uint8)}

    def reset(self, *, seed=None, options=None):
        self.t = 0
        return self._obs(), {}

    def step(self, action):
        self.t += 1
        return self._obs(), 0.0, False, self.t >= 10, {}


def memory(envs: int, long: int, steps: int | None = None, short: int = 10, each: bool = False,
           folder: str | None = None) -> dict:
    fns = [lambda: _Wide(long)] + [lambda: _Wide(short)] * (envs - 1)
    queue_bytes = 1 if each else 2**20
    env = gymnasium.vector.SyncVectorEnv(fns)
    # Per commit: seconds, the writer thread's CPU seconds (a commit runs on it: what another
    # process on the machine takes does not count), the resident set after it.
    commits: list[tuple[float, float, int]] = []
    real = _dataset.Dataset.commit

    def timed(self, episodes):
        t0, c0 = time.perf_counter(), time.thread_time()
        out = real(self, episodes)
        commits.append((time.perf_counter() - t0, time.thread_time() - c0, _rss()))
        return out

    _dataset.Dataset.commit = timed
    with tempfile.TemporaryDirectory(dir=folder) as tmp:
        rec = RecordEpisodes(env, str(Path(tmp) / "d"), video=False, queue_bytes=queue_bytes)
        rec.reset(seed=0)
        base, peak, stop = _rss(), [0], threading.Event()

        def sample() -> None:
            while not stop.is_set():
                peak[0] = max(peak[0], _rss())
                time.sleep(0.005)

        sampler = threading.Thread(target=sample, daemon=True)
        sampler.start()
        actions = np.zeros((envs, 1), np.float32)
        for _ in range(long + 1 if steps is None else steps):
            rec.step(actions)
        held = _rss()
        rec.close()
        stop.set()
        sampler.join()
    _dataset.Dataset.commit = real
    # The commits during env 0's episode (the last one, at the close, writes it): the first
    # and the last tenth of them.
    during = commits[:-1] if len(commits) > 1 else commits
    tenth = max(1, len(during) // 10)

    def mean(part: list[tuple[float, float, int]], k: int) -> float:
        return sum(c[k] for c in part) / len(part)

    return {"envs": envs, "long": long, "short": short, "queue_bytes": queue_bytes, "baseline_mib": base / 2**20,
            "held_above_mib": (held - base) / 2**20, "peak_above_mib": (peak[0] - base) / 2**20,
            "written": rec.stats["episodes_written"], "commits": len(commits),
            "commit_ms_first": 1e3 * mean(during[:tenth], 0), "commit_ms_last": 1e3 * mean(during[-tenth:], 0),
            "commit_cpu_ms_first": 1e3 * mean(during[:tenth], 1),
            "commit_cpu_ms_last": 1e3 * mean(during[-tenth:], 1),
            "rss_above_mib_first": (mean(during[:tenth], 2) - base) / 2**20,
            "rss_above_mib_last": (mean(during[-tenth:], 2) - base) / 2**20}


def _wchar() -> int:
    with open("/proc/self/io") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("wchar:"))


def append(mb: float) -> list[dict]:
    rows: list[dict] = []
    real = _dataset.Dataset.commit

    def timed(self, episodes):
        # The camera's last file: the files of its run (`_files.py`), joined into one at the end.
        size = sum(p.size for p in self._files[self.video_keys[0]].run)
        w0, t0 = _wchar(), time.perf_counter()
        out = real(self, episodes)
        rows.append({"last_file_mb": size / 1e6, "seconds": time.perf_counter() - t0,
                     "written_mb": (_wchar() - w0) / 1e6, "episodes": len(episodes)})
        return out

    _dataset.Dataset.commit = timed
    env = gymnasium.vector.SyncVectorEnv([_Noise])
    with tempfile.TemporaryDirectory() as tmp:
        rec = RecordEpisodes(env, str(Path(tmp) / "d"), commit_every=0.2, video_files_size_in_mb=10 * mb)
        rec.reset(seed=0)
        try:
            while not rows or rows[-1]["last_file_mb"] < mb:
                rec.step(np.zeros((1, 1), np.float32))
        finally:
            rec.close()
    return rows


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=["memory", "append"])
    p.add_argument("--envs", type=int, default=8)
    p.add_argument("--long", type=int, default=3000)
    p.add_argument("--steps", type=int, default=None)
    p.add_argument("--short", type=int, default=10, help="memory: the other envs' episodes' steps")
    p.add_argument("--commit-each", action="store_true",
                   help="memory: a queue of one step, so that each ended episode is committed at once")
    p.add_argument("--dir", default=None, help="memory: the folder to record in (default: the system's temporary one)")
    p.add_argument("--mb", type=float, default=200)
    a = p.parse_args()
    if a.what == "memory":
        print(json.dumps(memory(a.envs, a.long, a.steps, a.short, a.commit_each, a.dir)))
    else:
        for row in append(a.mb):
            print(json.dumps(row))


if __name__ == "__main__":
    main()
