"""`envhub eval` with its policy in a catalog Python environment (`--policy-env metaworld`,
a numpy-only policy): SIGTERM stops the evaluation, its workers and the policy's process
(exit 143, none left running); after SIGKILL to `envhub eval`, every process it started,
the policy's included, is gone within a bounded wait (the parent-death signal).

Skipped where the `metaworld` environment cannot be built; failed instead under
ENVHUB_SUITES_REQUIRED=1.
"""

from __future__ import annotations

import os
import signal
import subprocess

import pytest
from eval_processes import alive, kill_all, marked, start_eval, wait_for
from harness import import_envhub

envhub = import_envhub()

REQUIRED = bool(os.environ.get("ENVHUB_SUITES_REQUIRED"))


def _python_env(name: str) -> None:
    from envhub._cli import BINARY

    done = subprocess.run([str(BINARY), "env", "sync", name], capture_output=True, text=True, timeout=900)
    if done.returncode != 0:
        reason = f"the Python environment `{name}` cannot be built here: {(done.stderr or done.stdout)[-1500:]}"
        if REQUIRED:
            pytest.fail(f"{reason}, and ENVHUB_SUITES_REQUIRED is set")
        pytest.skip(reason)


def test_kill_9_leaves_no_process_of_the_evaluation(tmp_path):
    _python_env("metaworld")
    proc, mark, _, _ = start_eval(tmp_path, "--policy-env", "metaworld")
    try:
        started = marked(mark)
        policy = {int(x) for x in (tmp_path / "calls").read_text().split()}
        assert policy and policy <= set(started) and proc.pid not in policy  # the policy's own process
        assert len(started) >= 4, started  # the evaluation, its 2 workers, the policy's process
        proc.kill()
        proc.wait(timeout=60)
        wait_for(lambda: not marked(mark), 60, "the evaluation's processes to end after SIGKILL")
    finally:
        kill_all(proc, mark)


def test_sigterm_stops_a_policy_process(tmp_path):
    _python_env("metaworld")
    proc, mark, _, _ = start_eval(tmp_path, "--policy-env", "metaworld")
    try:
        started = marked(mark)
        proc.send_signal(signal.SIGTERM)
        _, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 143, stderr.decode()[-3000:]
        assert [p for p in started if alive(p)] == []
    finally:
        kill_all(proc, mark)
