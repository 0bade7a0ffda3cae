"""The recorder's memory: what it holds above the process once the dataset is opened stays
under `queue_bytes` plus the constant docs/guide/recording.md states, plus a few times the
numeric rows of the longest episode in flight (issue 42).

A memory bound, not a time bound: the scenario is the benchmark's (`bench_record_append.py
memory`), in a process of its own so that nothing else's memory counts."""

from __future__ import annotations

import json
import os
import subprocess
import sys

from harness import REPO_ROOT
from lerobot_datasets import recording_deps  # noqa: F401 (autouse: pyarrow and PyAV, or a skip)

MIB = 2**20
#: docs/guide/recording.md's constant: what a recording holds beyond `queue_bytes` and its
#: longest episode's rows (allocators, the writer's blocks, a commit's copies).
CONSTANT_MIB = 64
#: Per byte of the longest episode's numeric rows (about two measured: held, and copied at its
#: end), with room for a slower, busier machine's later release.
PER_ROW_BYTE = 5


def _bench(envs: int, long: int) -> dict:
    script = REPO_ROOT / "python" / "bench" / "bench_record_append.py"
    proc = subprocess.run([sys.executable, str(script), "memory", "--envs", str(envs), "--long", str(long)],
                          capture_output=True, text=True, timeout=1200,
                          env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_a_long_episode_beside_short_ones_stays_within_the_bound():
    """8 envs with 4 KiB observations, env 0's episode 1,500 steps (6 MiB of rows) beside
    about 950 ended episodes of the others, a 1 MiB queue (the bound: 96 MiB; measured 73 MiB
    at the peak). Before it, the first commit's imports (pandas, through `pa.array`),
    Parquet's dictionary builder (five times a wide column), whole episodes files read for a
    join and memory the allocators kept after commits took the process 123 MiB above its
    baseline at the end and 223 MiB at the peak."""
    out = _bench(8, 1500)
    rows = 1500 * (512 * 8 + 4 + 8 + 3)  # env 0's episode: state, action, reward, flags
    bound = out["queue_bytes"] + CONSTANT_MIB * MIB + PER_ROW_BYTE * rows
    assert out["written"] > 900
    assert out["held_above_mib"] * MIB < bound, out
    assert out["peak_above_mib"] * MIB < bound, out
