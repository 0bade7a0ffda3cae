"""`envhub eval` as a process tree for the tests that signal it: a long evaluation started in
a session of its own, every process it started found by a mark in its environment (every
descendant inherits it, whatever its process group or session), and whatever a failed test
left running killed."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import textwrap
import time
import uuid

import pytest

SLOW_POLICY = textwrap.dedent(
    """\
    import os, time
    import numpy as np

    def act(observations, tasks):
        open(os.environ["EVAL_MARK_FILE"], "a").write(f"{os.getpid()}\\n")
        time.sleep(0.05)
        return np.zeros((len(observations), 1), np.float32)
    """
)


def alive(pid: int) -> bool:
    """Running (a zombie, or no process, is down)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def marked(mark: str) -> list[int]:
    """The processes whose environment holds `mark` (every descendant inherits it, whatever
    its process group or session)."""
    found = []
    needle = f"EVAL_RUN_MARK={mark}".encode()
    for name in os.listdir("/proc"):
        if not name.isdigit() or int(name) == os.getpid():
            continue
        try:
            with open(f"/proc/{name}/environ", "rb") as f:
                if needle in f.read().split(b"\0") and alive(int(name)):
                    found.append(int(name))
        except OSError:
            continue
    return found


def wait_for(check, seconds: float, what: str):
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        value = check()
        if value:
            return value
        time.sleep(0.1)
    pytest.fail(f"gave up waiting for {what} after {seconds:g} s")


def start_eval(tmp_path, *extra):
    """`envhub eval` of long Pendulum episodes over 2 envs (2 workers), the slow policy
    (`extra` may run it in a Python environment), in its own session; returns it once its
    policy has answered."""
    from envhub._cli import BINARY

    registry = tmp_path / "bench.yaml"
    registry.write_text(json.dumps({"environments": [], "benchmarks": {"long-pendulum": {
        "entries": ["gym-pendulum"], "episodes_per_task": 4, "init": {"seed_start": 0},
        "horizon": 100000, "success": "none"}}}))
    (tmp_path / "slow.py").write_text(SLOW_POLICY)
    mark, calls = uuid.uuid4().hex, tmp_path / "calls"
    env = {**os.environ, "EVAL_RUN_MARK": mark, "EVAL_MARK_FILE": str(calls)}
    args = [str(BINARY), "--registry", "@default", "--registry", str(registry), "eval", "long-pendulum",
            "--policy", f"{tmp_path / 'slow.py'}:act", "--num-envs", "2", "--workers", "2",
            "--out", str(tmp_path / "out"), "--quiet", *extra]
    proc = subprocess.Popen(args, env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)

    def answered():
        if proc.poll() is not None:
            pytest.fail(f"envhub eval ended early ({proc.returncode}): {proc.stderr.read().decode()[-3000:]}")
        return calls.exists() and calls.read_text().count("\n") >= 2

    wait_for(answered, 300, "the policy's first answers")
    return proc, mark, args, env


def kill_all(proc, mark) -> None:
    """Whatever a failed test left running."""
    for pid in [proc.pid] * (proc.poll() is None) + marked(mark):
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    try:
        proc.wait(timeout=60)
    except subprocess.TimeoutExpired:
        pass
