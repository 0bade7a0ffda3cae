"""Warm workers: the workers of a suite's Python environment fork from a fork server of that
environment, started on the first session that needs it and reused by this process's later
sessions (the embedded hub), with the same trajectories as workers started cold
(`ENVHUB_WARM_WORKERS=0`).

The environment is pyenv/test_pyenv.py's Gymnasium one on another CPython (same description, so
the same cached venv: built once by whichever test runs first). Without uv, that CPython or
PyPI this skips with the reason; under ENVHUB_PYENV_REQUIRED=1 that is a failure.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from harness import REPO_ROOT, import_envhub

envhub = import_envhub()

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
ENVHUB_BIN = REPO_ROOT / "target" / "release" / "envhub"
VERSIONS = [v for v in ("3.12", "3.10", "3.13") if v != f"{sys.version_info[0]}.{sys.version_info[1]}"]


def registry_text(v: str) -> str:
    name = "py" + v.replace(".", "")
    return f"""python_envs:
  {name}:
    python: "{v}"
    requirements: ["gymnasium==1.2.0"]
    env: {{ENVHUB_TEST_MARK: "{name}"}}
environments:
  - id: cartpole-warm
    name: CartPole in a suite environment
    framework: gymnasium
    env_id: CartPole-v1
    adapter: gymnasium
    robot_type: custom
    env_type: floor
    python_env: {name}
"""


def skip_or_fail(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_PYENV_REQUIRED is set")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def registry(tmp_path_factory) -> str:
    if not ENVHUB_BIN.is_file():
        skip_or_fail(f"{ENVHUB_BIN} is not built; run `make py-install`")
    path = tmp_path_factory.mktemp("warm") / "registry.yaml"
    for v in VERSIONS:
        path.write_text(registry_text(v))
        out = subprocess.run(
            [str(ENVHUB_BIN), "--registry", str(path), "env", "sync", "py" + v.replace(".", "")],
            check=False,
            capture_output=True,
            text=True,
            timeout=600,
        )
        if out.returncode == 0:
            return str(path)
        if "not on this machine" not in out.stderr:
            skip_or_fail(f"`envhub env sync` failed: {out.stderr.strip()[-2000:]}")
    skip_or_fail(f"none of CPython {VERSIONS} is on this machine")
    raise AssertionError("unreachable")


def parent(pid: int) -> int:
    status = Path(f"/proc/{pid}/status").read_text()
    return int(next(line.split()[1] for line in status.splitlines() if line.startswith("PPid:")))


def rollout(envs, steps: int = 200) -> list[bytes]:
    obs, _ = envs.reset(seed=4)
    out = [obs.tobytes()]
    rng = np.random.default_rng(2)
    for _ in range(steps):
        obs, rew, term, trunc, _ = envs.step(rng.integers(0, 2, envs.num_envs))
        out.append(obs.tobytes() + rew.tobytes() + term.tobytes() + trunc.tobytes())
    return out


def test_workers_fork_from_one_warm_server_and_step_as_cold_ones(registry, monkeypatch) -> None:
    monkeypatch.delenv("ENVHUB_WARM_WORKERS", raising=False)
    first = envhub.make_vec("cartpole-warm", 4, num_workers=2, registry=registry)
    try:
        servers = {parent(p) for p in first.worker_pids}
        assert len(servers) == 1 and os.getpid() not in servers, servers
        (server,) = servers
        assert parent(server) == os.getpid(), "the fork server is this process's child"
        cmdline = Path(f"/proc/{server}/cmdline").read_bytes().split(b"\0")
        assert b"forkserver" in cmdline, cmdline
        warm = rollout(first)
    finally:
        first.close()
    # A later session of this process: forked from the same server.
    second = envhub.make_vec("cartpole-warm", 4, num_workers=2, registry=registry)
    try:
        assert {parent(p) for p in second.worker_pids} == {server}
        assert rollout(second) == warm
    finally:
        second.close()
    monkeypatch.setenv("ENVHUB_WARM_WORKERS", "0")
    cold = envhub.make_vec("cartpole-warm", 4, num_workers=2, registry=registry)
    try:
        assert {parent(p) for p in cold.worker_pids} == {os.getpid()}, "started cold"
        assert rollout(cold) == warm
    finally:
        cold.close()


def test_a_killed_server_is_replaced(registry, monkeypatch) -> None:
    monkeypatch.delenv("ENVHUB_WARM_WORKERS", raising=False)
    envs = envhub.make_vec("cartpole-warm", 2, num_workers=1, registry=registry)
    (server,) = {parent(p) for p in envs.worker_pids}
    envs.close()
    os.kill(server, 9)
    envs = envhub.make_vec("cartpole-warm", 2, num_workers=1, registry=registry)
    try:
        (again,) = {parent(p) for p in envs.worker_pids}
        assert again != server
        envs.reset(seed=0)
        envs.step(np.zeros(2, dtype=np.int64))
    finally:
        envs.close()
