"""Failures as exceptions a Python user can catch: one class per kind, all `EnvHubError`,
each also the builtin a caller would expect. Real worker processes are killed, hang and
fail; a worker crash is raised as its death (the hub watches the process), never a hang.

No test here bounds how long something may take: a crash is told from a timeout by what the error
says, with the step timeout far above any wait a loaded machine causes; how fast a crash is
noticed is measured by python/bench/bench_failure_latency.py."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from harness import import_envhub

envhub = import_envhub()


def test_unknown_id():
    with pytest.raises(KeyError) as caught:
        envhub.make("mujoco-antt")
    err = caught.value
    assert isinstance(err, envhub.UnknownEnvError)
    assert "mujoco-ant" in err.suggestions and "did you mean" in str(err)
    with pytest.raises(envhub.UnknownEnvError):
        envhub.make_vec("no-such-env", 2)


def test_unknown_option_names_the_valid_ones():
    with pytest.raises(envhub.MakeError) as caught:
        envhub.make("gym-pendulum", gravty=9.8)
    assert isinstance(caught.value, ValueError)
    assert "gravty" in str(caught.value) and "g" in str(caught.value)


def test_invalid_session_options():
    with pytest.raises(envhub.InvalidConfigError):
        envhub.make_vec("gym-cartpole", 2, num_workers=3)
    with pytest.raises(envhub.InvalidConfigError):
        envhub.make_vec("gym-cartpole", 0)
    with pytest.raises(envhub.InvalidConfigError):
        envhub.make("gym-cartpole", step_timeout=-1)


def test_bad_discrete_action():
    env = envhub.make("gym-cartpole")
    try:
        env.reset(seed=0)
        with pytest.raises(ValueError) as caught:
            env.step(2)
        assert isinstance(caught.value, envhub.InvalidActionError)
        assert "Discrete(2)" in str(caught.value) and "hint:" in str(caught.value)
        env.step(1)  # the env is still usable
    finally:
        env.close()


# Far above a step on a slow, busy machine: a crash noticed only when it runs out would say
# "step timeout", which the tests below refuse.
STEP_TIMEOUT_S = 60.0


def _expect_death_noticed(caught: pytest.ExceptionInfo, pid: int) -> None:
    """The error is the worker's death as the hub's watch on the process saw it (its exit
    status), not the step timeout running out."""
    err = caught.value
    assert isinstance(err, RuntimeError) and err.pid == pid
    assert "step timeout" not in str(err), str(err)
    assert "SIGKILL" in str(err) or "signal" in str(err), str(err)


def test_worker_killed_between_steps():
    envs = envhub.make_vec("gym-cartpole", 4, num_workers=2, step_timeout=STEP_TIMEOUT_S)
    try:
        envs.reset(seed=0)
        pid = envs.worker_pids[0]
        os.kill(pid, signal.SIGKILL)
        with pytest.raises(envhub.WorkerDiedError) as caught:
            envs.step(np.zeros(4, dtype=np.int64))
        _expect_death_noticed(caught, pid)
        with pytest.raises(envhub.InvalidStateError):
            envs.step(np.zeros(4, dtype=np.int64))
    finally:
        envs.close()


def test_worker_killed_during_a_step(null_registry):
    """The step waits on an env that would sleep ten minutes (GIL released); a kill -9 ends
    it with the worker's death, not at the step timeout."""
    env = envhub.make("null-env", registry=null_registry, sleep_ms=600_000, step_timeout=STEP_TIMEOUT_S)
    try:
        env.reset(seed=0)
        pid = env.worker_pid
        threading.Timer(0.3, lambda: os.kill(pid, signal.SIGKILL)).start()
        with pytest.raises(envhub.WorkerDiedError) as caught:
            env.step(0)
        _expect_death_noticed(caught, pid)
    finally:
        env.close()


def test_worker_exit_and_env_error(null_registry):
    env = envhub.make("null-env", registry=null_registry, exit_after=2)
    try:
        env.reset(seed=0)
        with pytest.raises(envhub.WorkerDiedError):
            for _ in range(5):
                env.step(0)
    finally:
        env.close()
    env = envhub.make("null-env", registry=null_registry, error_after=1)
    try:
        env.reset(seed=0)
        with pytest.raises(envhub.EnvFailedError):
            for _ in range(5):
                env.step(0)
    finally:
        env.close()


def _gone(pid: int) -> bool:
    """Whether process `pid` has exited (a zombie not yet reaped counts as gone)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] == "Z"
    except (OSError, IndexError):
        return True


def test_hung_worker_times_out(null_registry):
    """A step that would sleep ten minutes ends at the 0.5 s step timeout: the worker is
    killed, and the error says so."""
    env = envhub.make("null-env", registry=null_registry, sleep_ms=600_000, step_timeout=0.5)
    try:
        env.reset(seed=0)
        pid = env.worker_pid
        start = time.monotonic()
        with pytest.raises(envhub.WorkerDiedError, match=r"did not answer within 500ms \(step timeout\) and was killed"):
            env.step(0)
        assert time.monotonic() - start >= 0.5  # not before the timeout; after it, however late
        assert _gone(pid), f"the hung worker {pid} still runs"
    finally:
        env.close()


def test_restart_on_crash(null_registry):
    envs = envhub.make_vec("null-env", 2, num_workers=1, registry=null_registry, restart_on_crash=True)
    try:
        envs.reset(seed=0)
        os.kill(envs.worker_pids[0], signal.SIGKILL)
        _, _, _, truncated, info = envs.step(np.zeros(2, dtype=np.int64))
        assert truncated.all()
        assert info["worker_restarted"].all() and info["_worker_restarted"].all()
        envs.step(np.zeros(2, dtype=np.int64))
    finally:
        envs.close()


def test_gil_is_released_while_waiting(null_registry):
    env = envhub.make("null-env", registry=null_registry, sleep_ms=300)
    try:
        env.reset(seed=0)
        done = threading.Event()

        def step():
            env.step(0)
            done.set()

        t = threading.Thread(target=step)
        t.start()
        spins = 0
        while not done.is_set():
            spins += 1  # pure Python work: runs only if the stepping thread let go of the GIL
        t.join()
        assert spins > 10_000
    finally:
        env.close()


def test_fork_gives_a_clear_error():
    env = envhub.make("gym-cartpole")
    env.reset(seed=0)
    obs_before = env.step(0)[0].copy()
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:  # the child: must refuse, and must not disturb the parent's worker
        os.close(read)
        try:
            env.step(0)
            result = "no error"
        except envhub.ForkError as e:
            result = "ForkError: " + str(e)
        except BaseException as e:
            result = f"{type(e).__name__}: {e}"
        env.close()
        del env
        os.write(write, result.encode())
        os._exit(0)
    os.close(write)
    with os.fdopen(read) as f:
        result = f.read()
    os.waitpid(pid, 0)
    try:
        assert result.startswith("ForkError"), result
        assert "fork" in result and "hint:" in result
        assert isinstance(envhub.ForkError("x"), envhub.InvalidStateError)
        obs, *_ = env.step(1)  # the parent's env still works
        assert obs.shape == obs_before.shape
    finally:
        env.close()


UNAVAILABLE = """\
import envhub, json
try:
    envhub.make("fake-env")
except ImportError as e:
    print(json.dumps({"type": type(e).__name__, "envhub": isinstance(e, envhub.EnvHubError),
                      "msg": str(e), "hint": e.hint, "adapter": e.adapter}))
"""


def test_unavailable_adapter_is_an_import_error_with_the_hint(tmp_path):
    """A worker binary whose `fakesim` adapter is missing its dependency (a stand-in that
    only answers `describe`): making one of its envs raises `AdapterUnavailableError`."""
    describe = [
        {
            "name": "fakesim",
            "frameworks": ["fakesim"],
            "requires": ["libfake 1.0"],
            "description": "a simulator that is not installed",
            "availability": {"status": "unavailable", "reason": "libfake.so not found", "hint": "pip install fake"},
            "envs": ["Fake-v0"],
        }
    ]
    worker = tmp_path / "envhub-worker"
    worker.write_text(f"#!/bin/sh\ncat <<'EOF'\n{json.dumps(describe)}\nEOF\n")
    worker.chmod(0o755)
    registry = tmp_path / "fake.yaml"
    registry.write_text(
        textwrap.dedent(
            """\
            environments:
              - id: fake-env
                name: Fake
                framework: fakesim
                env_id: Fake-v0
                robot_type: custom
                env_type: floor
            """
        )
    )
    env = dict(os.environ, ENVHUB_WORKER=str(worker), ENVHUB_REGISTRY=str(registry))
    out = subprocess.run([sys.executable, "-c", UNAVAILABLE], env=env, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["type"] == "AdapterUnavailableError" and got["envhub"]
    assert got["adapter"] == "fakesim" and got["hint"] == "pip install fake"
    assert "libfake.so not found" in got["msg"] and "hint: pip install fake" in got["msg"]


def test_missing_worker_binary(tmp_path):
    code = "import envhub\ntry:\n    envhub.make('gym-cartpole')\nexcept envhub.WorkerBinaryError as e:\n    print('ok', e)\n"
    env = dict(os.environ, ENVHUB_WORKER=str(tmp_path / "nowhere" / "envhub-worker"))
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=60)
    assert out.stdout.startswith("ok"), out.stdout + out.stderr
    assert "nowhere" in out.stdout


def test_envs_made_after_a_fork_work():
    """A forked child (multiprocessing's `fork`) makes and steps envs of its own, although the
    parent's thread that starts workers did not survive the fork."""
    import select

    env = envhub.make("gym-cartpole")
    env.reset(seed=0)
    read, write = os.pipe()
    pid = os.fork()
    if pid == 0:
        os.close(read)
        try:
            fresh = envhub.make("gym-cartpole")
            fresh.reset(seed=0)
            fresh.step(0)
            fresh.close()
            result = "stepped"
        except BaseException as e:
            result = f"{type(e).__name__}: {e}"
        os.write(write, result.encode())
        os._exit(0)
    os.close(write)
    try:
        ready, _, _ = select.select([read], [], [], 60)
        if not ready:
            os.kill(pid, signal.SIGKILL)
        result = os.read(read, 4096).decode() if ready else "no answer within 60 s"
        os.waitpid(pid, 0)
        assert result == "stepped", result
        env.step(1)  # the parent's env still works
    finally:
        os.close(read)
        env.close()
