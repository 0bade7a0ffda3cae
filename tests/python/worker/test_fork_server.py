"""Warm workers: the workers of a suite's Python environment fork from a fork server of that
environment, started on the first session that needs it and reused by this process's later
sessions (the embedded hub, or an `envhub serve` daemon for all its clients), with the same
trajectories as workers started cold (`ENVHUB_WARM_WORKERS=0`).

The environment is pyenv/test_pyenv.py's Gymnasium one on another CPython (same description, so
the same cached venv: built once by whichever test runs first). Without uv, that CPython or
PyPI this skips with the reason; under ENVHUB_PYENV_REQUIRED=1 that is a failure.
"""

from __future__ import annotations

import os
import select
import subprocess
import sys
import time
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


def start_daemon(registry: str, folder: Path) -> subprocess.Popen[str]:
    env = {k: v for k, v in os.environ.items() if k not in ("ENVHUB_ADAPTERS", "ENVHUB_WARM_WORKERS")}
    env["ENVHUB_REGISTRY"] = f"@default:{registry}"
    proc = subprocess.Popen(
        [str(ENVHUB_BIN), "serve", "--local-only", "--socket", str(folder / "hub.sock")],
        env=env,
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    ready, _, _ = select.select([proc.stdout], [], [], 120)
    line = proc.stdout.readline() if ready else ""
    assert "listening on" in line, f"the daemon said {line!r} (exit status {proc.poll()})"
    return proc


CLIENT_THAT_DIES = """
import os, sys
import envhub
envs = envhub.make_vec("cartpole-warm", 2, num_workers=1, registry=sys.argv[1])
envs.reset(seed=0)
print(" ".join(map(str, envs.worker_pids)), flush=True)
os._exit(0)
"""


def test_a_daemons_sessions_fork_from_its_warm_server(registry, monkeypatch, tmp_path) -> None:
    """`envhub serve` keeps a suite's fork server for its clients' later sessions: workers are
    forked by a server that is the daemon's child, step as cold ones do, and go when the
    client that asked for them goes."""
    daemon = start_daemon(registry, tmp_path)
    try:
        monkeypatch.delenv("ENVHUB_WARM_WORKERS", raising=False)
        monkeypatch.setenv("ENVHUB_HUB", str(tmp_path / "hub.sock"))
        servers = set()
        rollouts = []
        for _ in range(2):
            envs = envhub.make_vec("cartpole-warm", 4, num_workers=2, registry=registry)
            try:
                servers |= {parent(p) for p in envs.worker_pids}
                rollouts.append(rollout(envs))
            finally:
                envs.close()
        assert len(servers) == 1, f"one fork server for both sessions: {servers}"
        (server,) = servers
        assert parent(server) == daemon.pid, "the fork server is the daemon's child"
        assert b"forkserver" in Path(f"/proc/{server}/cmdline").read_bytes().split(b"\0")
        monkeypatch.setenv("ENVHUB_WARM_WORKERS", "0")
        cold = envhub.make_vec("cartpole-warm", 4, num_workers=2, registry=registry)
        try:
            rollouts.append(rollout(cold))
        finally:
            cold.close()
        assert rollouts[0] == rollouts[1] == rollouts[2]

        # A client that dies: the daemon kills the workers forked for it.
        env = {**os.environ, "ENVHUB_HUB": str(tmp_path / "hub.sock")}
        env.pop("ENVHUB_WARM_WORKERS", None)
        out = subprocess.run(
            [sys.executable, "-c", CLIENT_THAT_DIES, registry],
            env=env,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert out.returncode == 0, out.stderr[-2000:]
        pids = [int(p) for p in out.stdout.split()]
        assert {parent(p) for p in pids if Path(f"/proc/{p}").exists()} <= {server}
        deadline = time.monotonic() + 60  # a hang bound: the kill is immediate
        while any(alive(p) for p in pids) and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not any(alive(p) for p in pids), "the dead client's warm workers were not stopped"
        assert daemon.poll() is None
    finally:
        daemon.kill()
        daemon.wait(timeout=10)


def alive(pid: int) -> bool:
    """Whether `pid` runs (a zombie left for its fork server to reap counts as gone)."""
    try:
        return "State:\tZ" not in Path(f"/proc/{pid}/status").read_text()
    except FileNotFoundError:
        return False
