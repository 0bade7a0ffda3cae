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


def _under_affinity(cpus: set[int]) -> tuple[int, int]:
    done = subprocess.run(
        [sys.executable, "-c", ASK],
        preexec_fn=lambda: os.sched_setaffinity(0, cpus),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert done.returncode == 0, done.stderr
    usable, machine = done.stdout.split()
    return int(usable), int(machine)


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity on this platform")
def test_a_process_bound_to_one_cpu_counts_one_core_whatever_the_machine_has():
    one = min(os.sched_getaffinity(0))
    usable, machine = _under_affinity({one})
    assert usable == 1, f"bound to CPU {one}: {usable} usable cores (the machine has {machine})"
    # Unbound (as this test runs): every CPU the test may use.
    assert _under_affinity(os.sched_getaffinity(0))[0] == len(os.sched_getaffinity(0))


def _with_cpus(value: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", ASK],
        env={**os.environ, "ENVHUB_CPUS": value},
        capture_output=True,
        text=True,
        timeout=60,
    )


def test_envhub_cpus_narrows_the_count_as_a_ray_shard_s_reservation_does():
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    one = _with_cpus("1")
    assert one.returncode == 0, one.stderr
    assert one.stdout.split()[0] == "1"
    # More than this process may run on: the cores it has, not the number asked for.
    many = _with_cpus("4096")
    assert many.returncode == 0, many.stderr
    assert int(many.stdout.split()[0]) == cores


@pytest.mark.parametrize("bad", ["0", "-2", "two", "1.5"])
def test_a_bad_envhub_cpus_is_refused_naming_the_variable_and_what_is_valid(bad):
    done = _with_cpus(bad)
    assert done.returncode != 0
    assert f"ENVHUB_CPUS={bad!r}" in done.stderr, done.stderr
    assert "whole number of CPUs, at least 1" in done.stderr, done.stderr
