"""`envhub eval` kept under control: a policy that hangs, two runs into one folder, signals.

- Every policy call has a deadline (`policy_timeout`, `--policy-timeout`): an in-process
  policy that hangs fails its batch's episodes with an error naming it and the wait (its
  call is abandoned: later calls fail at once while it hangs, and go through once it
  returns); a `--policy-env` process that hangs is killed and a new one takes the next
  episodes. `fail_fast` stops at the first such failure.
- The output folder is locked while an evaluation runs: a second one, or a `--resume`, is
  refused with the first one's pid; the lock goes when the run ends, however it ends.
- SIGTERM (or SIGINT) to `envhub eval` stops the evaluation: the exit status is 143 (130)
  and no process it started (its workers) is left. With a policy in a catalog Python
  environment: evaluation/test_policy_env.py.

Outcomes are asserted, never how long anything took.
"""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest
from eval_processes import alive, kill_all, marked, start_eval
from harness import import_envhub

envhub = import_envhub()

from envhub.evaluation import EvaluationStopped, PolicyError, evaluate  # noqa: E402
from envhub.evaluation.callable import Watchdog  # noqa: E402
from envhub.evaluation.policy_env import EnvPolicy  # noqa: E402
from envhub.evaluation.results import FolderLock, FolderLocked  # noqa: E402

PENDULUM = {
    "name": "pendulum",
    "entries": ["gym-pendulum"],
    "episodes_per_task": 4,
    "init": {"seed_start": 10},
    "horizon": 20,
    "success": "none",
}


# The watchdog ------------------------------------------------------------------------------


def test_a_hung_in_process_policy_fails_its_batch_and_the_run_goes_on(tmp_path):
    release = threading.Event()

    class Hangs:
        """Hangs at episode 1's first call until released."""

        def reset(self, slot, episode):
            self.episode = episode.index

        def __call__(self, observations, tasks):
            if self.episode == 1:
                release.wait()
            return [np.zeros(1, np.float32) for _ in observations]

    try:
        results = evaluate(PENDULUM, Hangs(), out=tmp_path / "hang", policy_timeout=1.0, progress=False)
        errors = [e["error"] for e in results["episodes"]]
        assert errors[0] is None
        assert "gave no answer to `act` within 1 s (--policy-timeout)" in errors[1] and "Hangs" in errors[1]
        # While the abandoned call hangs, the next episodes fail at once, naming it.
        assert all("still in its `act` call" in e for e in errors[2:]), errors
        assert results["summary"]["done"] == 4
        with pytest.raises(EvaluationStopped, match="gave no answer"):
            evaluate(PENDULUM, Hangs(), out=tmp_path / "fast", policy_timeout=1.0, fail_fast=True, progress=False)
    finally:
        release.set()


def test_the_watchdog_lets_a_policy_that_returns_late_go_on():
    release = threading.Event()
    dog = Watchdog("`slow`", 0.5)
    with pytest.raises(PolicyError, match="gave no answer to `act` within 0.5 s"):
        dog.call("act", release.wait)
    with pytest.raises(PolicyError, match="still in its `act` call"):
        dog.call("act", lambda: 1)
    release.set()
    deadline = time.monotonic() + 60
    while dog.hung and time.monotonic() < deadline:
        time.sleep(0.01)
    assert dog.call("act", lambda: 2) == 2
    assert Watchdog("x", None).call("act", lambda: 3) == 3  # no deadline: in the caller's thread
    with pytest.raises(ValueError, match="positive"):
        Watchdog("x", 0)


HANG_ONCE = textwrap.dedent(
    """\
    import os, time
    import numpy as np

    MARK = {mark!r}

    def act(observations, tasks):
        # The first process to see a third call hangs there; a new process answers.
        n = int(open(MARK).read()) if os.path.exists(MARK) else 0
        open(MARK, "w").write(str(n + 1))
        if n == 2:
            open(MARK + ".pid", "w").write(str(os.getpid()))
            time.sleep(3600)
        return np.zeros((len(observations), 1), np.float32)
    """
)


def test_a_hung_policy_process_is_killed_and_a_new_one_takes_the_next_episodes(tmp_path):
    mark = tmp_path / "calls"
    (tmp_path / "hang_once.py").write_text(HANG_ONCE.format(mark=str(mark)))
    policy = EnvPolicy(f"{tmp_path / 'hang_once.py'}:act", [sys.executable], env_name="(this interpreter)", timeout=3.0)
    bench = {**PENDULUM, "horizon": 2}  # two calls per episode: the third call is episode 1's first
    results = evaluate(bench, policy, out=tmp_path / "out", progress=False)
    errors = [e["error"] for e in results["episodes"]]
    assert errors[0] is None and errors[2:] == [None, None], errors
    assert "gave no answer to `act` within 3 s (--policy-timeout)" in errors[1] and "hang_once.py:act" in errors[1]
    assert "was killed" in errors[1] and policy.killed == 1
    hung = int((tmp_path / "calls.pid").read_text())
    assert not alive(hung)


# One evaluation per folder -----------------------------------------------------------------


def test_a_folder_in_use_is_refused_naming_its_owner(tmp_path):
    code = textwrap.dedent(
        f"""\
        import sys, time
        sys.path.insert(0, {os.path.join(os.path.dirname(envhub.__file__), os.pardir)!r})
        from envhub.evaluation.results import FolderLock
        FolderLock({str(tmp_path / "run")!r})
        print("locked", flush=True)
        sys.stdin.read()
        """
    )
    owner = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        assert owner.stdout.readline().strip() == "locked"
        for resume in (False, True):
            with pytest.raises(FolderLocked, match=rf"in use by a running evaluation \(pid {owner.pid}\)"):
                evaluate(PENDULUM, lambda o, t: np.zeros((len(o), 1), np.float32), out=tmp_path / "run",
                         resume=resume, progress=False)
    finally:
        owner.communicate("", timeout=60)
    # The lock went with its process: the folder is free again.
    FolderLock(str(tmp_path / "run")).release()


# Signals to `envhub eval` --------------------------------------------------------------------

@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_stops_the_evaluation_and_everything_it_started(tmp_path, sig):
    proc, mark, args, env = start_eval(tmp_path)
    try:
        started = marked(mark)
        assert proc.pid in started and len(started) >= 3, started  # the evaluation and its 2 workers
        # The folder is in use: a second run and a resume are refused, naming this one.
        for more in ([], ["--resume"]):
            second = subprocess.run(args + more, env={**env, "EVAL_RUN_MARK": "other"}, capture_output=True,
                                    text=True, timeout=300, cwd=tmp_path)
            assert second.returncode == 2, second.stderr
            assert f"in use by a running evaluation (pid {proc.pid})" in second.stderr
        proc.send_signal(sig)
        _, stderr = proc.communicate(timeout=300)
        assert proc.returncode == 128 + sig, stderr.decode()[-3000:]
        assert f"stopped by {sig.name}" in stderr.decode()
        # Exited only when everything was down.
        assert [p for p in started if alive(p)] == []
        assert marked(mark) == []
    finally:
        kill_all(proc, mark)
    done = [json.loads(x) for x in (tmp_path / "out" / "episodes.jsonl").read_text().splitlines()]
    assert done == []  # no episode of 100000 steps ended: none recorded, none lost on --resume


def test_an_unknown_policy_is_a_usage_error(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "envhub.evaluation", "mujoco", "--policy", "no_such_module_xyz:act",
         "--out", str(tmp_path / "out")],
        capture_output=True, text=True, timeout=300,
    )
    assert done.returncode == 2, done.stderr
    assert re.search(r"cannot load the policy `no_such_module_xyz:act`: ModuleNotFoundError", done.stderr)
