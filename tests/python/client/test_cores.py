"""Default worker and thread counts count the CPUs this process may run on (its affinity, as
Slurm's CPU binding, `taskset` and container CPU sets narrow it), not the machine's."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from harness import import_envhub

envhub = import_envhub()

ASK = "import os; from envhub.wire.cores import usable_cores; print(usable_cores(), os.cpu_count())"


def _ask(cpus: set[int] | None = None, envhub_cpus: str | None = None) -> subprocess.CompletedProcess[str]:
    """`usable_cores()` and `os.cpu_count()` of a child bound to `cpus`, with `ENVHUB_CPUS`."""
    env = dict(os.environ)
    env.pop("ENVHUB_CPUS", None)
    if envhub_cpus is not None:
        env["ENVHUB_CPUS"] = envhub_cpus
    return subprocess.run(
        [sys.executable, "-c", ASK],
        preexec_fn=None if cpus is None else lambda: os.sched_setaffinity(0, cpus),
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )


def _usable(done: subprocess.CompletedProcess[str]) -> int:
    assert done.returncode == 0, done.stderr
    return int(done.stdout.split()[0])


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this platform")
def test_a_process_bound_to_one_cpu_counts_one_core_whatever_the_machine_has():
    one = min(os.sched_getaffinity(0))
    bound = _ask(cpus={one})
    assert _usable(bound) == 1, f"bound to CPU {one}: {bound.stdout} (usable cores, the machine's)"
    # Unbound (as this test runs): every CPU the test may use.
    assert _usable(_ask(cpus=os.sched_getaffinity(0))) == len(os.sched_getaffinity(0))


def test_envhub_cpus_narrows_the_count_as_a_ray_shard_s_reservation_does():
    assert _usable(_ask(envhub_cpus="1")) == 1
    # More than this process may run on: the cores it has, not the number asked for.
    assert _usable(_ask(envhub_cpus="4096")) == _usable(_ask())


@pytest.mark.parametrize("bad", ["0", "-2", "two", "1.5"])
def test_a_bad_envhub_cpus_is_refused_naming_the_variable_and_what_is_valid(bad):
    done = _ask(envhub_cpus=bad)
    assert done.returncode != 0
    assert f"ENVHUB_CPUS={bad!r}" in done.stderr, done.stderr
    assert "whole number of CPUs, at least 1" in done.stderr, done.stderr
