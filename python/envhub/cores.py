"""How many CPUs this process may use, for the default worker and thread counts."""

from __future__ import annotations

import os


def usable_cores() -> int:
    """The CPUs this process may run on: its affinity, which Slurm (`--cpus-per-task`),
    `taskset` and container CPU sets narrow, where `os.cpu_count()` counts the whole
    machine's (a shard given 4 CPUs of a 64-core node would start workers for 64). The hub's
    own default (Rust's `available_parallelism`) reads the affinity too. At least 1."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform (macOS)
        return max(1, os.cpu_count() or 1)
