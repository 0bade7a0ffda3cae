"""How many CPUs this process may use, for the default worker and thread counts."""

from __future__ import annotations

import os

from .errors import InvalidConfigError

#: CPUs a scheduler granted this process without binding it to them: a Ray shard's
#: `--cpus-per-shard` (Ray reserves CPUs but leaves the task free to run on every core).
CPUS_VAR = "ENVHUB_CPUS"


def usable_cores() -> int:
    """The CPUs this process may run on: its affinity, which Slurm (`--cpus-per-task`),
    `taskset` and container CPU sets narrow, where `os.cpu_count()` counts the whole
    machine's (a shard given 4 CPUs of a 64-core node would start workers for 64); at most
    `ENVHUB_CPUS` where that is set. The hub's own default (Rust's `available_parallelism`)
    reads the affinity too. At least 1."""
    try:
        cores = max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # no affinity on this platform (macOS)
        cores = max(1, os.cpu_count() or 1)
    granted = os.environ.get(CPUS_VAR, "").strip()
    if not granted:
        return cores
    try:
        cpus = int(granted)
    except ValueError:
        cpus = 0
    if cpus < 1:
        raise InvalidConfigError(f"{CPUS_VAR}={granted!r}: give a whole number of CPUs, at least 1 (or unset it)")
    return min(cores, cpus)
