"""Ctrl-C while a step waits on its workers: `KeyboardInterrupt` reaches the client while
the step still waits, however long the step would take, and the session is closed on the
spot — workers killed, nothing of it left in /dev/shm. The client runs in a child process
here, so the signal reaches only it, as Ctrl-C in a terminal reaches the foreground program.

The step would take ten minutes and the step timeout is longer still, so only the interrupt
can end it within the test; how fast it does (tens of milliseconds here) is measured by
python/bench/bench_failure_latency.py, not bounded here."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from harness import import_envhub

envhub = import_envhub()

CLIENT = textwrap.dedent(
    """\
    import signal, sys, time
    import numpy as np
    import envhub

    # As in a terminal: a program started in the background of a non-interactive shell (a CI
    # runner's `cmd &`) inherits SIGINT ignored, and Python then installs no
    # KeyboardInterrupt handler.
    signal.signal(signal.SIGINT, signal.default_int_handler)

    envs = envhub.make_vec(
        "null-env", 2, num_workers=2, registry=sys.argv[1], sleep_ms=600_000, step_timeout=1200
    )
    envs.reset(seed=0)
    print("ready", *envs.worker_pids, flush=True)
    try:
        envs.step(np.zeros(2, dtype=np.int64))
        print("stepped", flush=True)
    except KeyboardInterrupt:
        print("interrupted", time.monotonic(), envs._session.closed, flush=True)
    """
)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie counts as gone
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except OSError:
        return False


def test_ctrl_c_interrupts_a_step_that_would_take_minutes(null_registry, tmp_path):
    namespace = f"pyint{os.getpid()}_"
    script = tmp_path / "client.py"
    script.write_text(CLIENT)
    env = {**os.environ, "ENVHUB_NAMESPACE": namespace}
    child = subprocess.Popen(
        [sys.executable, str(script), null_registry],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert child.stdout is not None
        line = child.stdout.readline().split()
        assert line and line[0] == "ready", (line, child.stderr.read() if child.stderr else "")
        workers = [int(p) for p in line[1:]]
        time.sleep(0.3)  # the step is under way and blocked on the workers
        child.send_signal(signal.SIGINT)
        # Far below the ten minutes of the step: a missed Ctrl-C never returns in time.
        out, err = child.communicate(timeout=120)
    except subprocess.TimeoutExpired:
        pytest.fail("Ctrl-C did not end the step: it still waited on its workers")
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    words = out.split()
    assert words and words[0] == "interrupted", (out, err)
    assert words[2] == "True", "the session is closed"
    # None of its workers is left sleeping in its ten-minute step.
    deadline = time.monotonic() + 60
    while any(alive(p) for p in workers) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert not any(alive(p) for p in workers), "workers outlived the interrupted session"
    # Only iceoryx2's per-namespace management segment may stay (shared by every session of
    # the namespace); no channel, node or batch slot of the session.
    left = [f for f in os.listdir("/dev/shm") if namespace in f and not f.endswith("global_mgmt")]
    assert not left, left
    assert "Lost chunk" not in err and "Traceback" not in err, err


def test_closing_an_env_that_never_stepped_is_silent(tmp_path):
    """A mistake (an env made and dropped) must not produce iceoryx2 warnings."""
    script = tmp_path / "quiet.py"
    script.write_text(
        textwrap.dedent(
            """\
            import envhub
            envs = envhub.make_vec("gym-cartpole", 4, num_workers=2)
            envs.close()
            env = envhub.make("gym-cartpole")
            del env
            """
        )
    )
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert done.stderr.strip() == "", done.stderr
