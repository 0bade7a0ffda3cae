"""Hubs as processes for the tests: `envhub serve` as a local daemon (`daemon`), and two hubs
on loopback (`two_hubs`), each with its own iceoryx2 namespace, multicast off and explicit
endpoints, so nothing shortcuts through this machine's shared memory. A test module takes a
fixture by importing it (`from hub_daemons import daemon  # noqa: F401`)."""

from __future__ import annotations

import os
import select
import socket
import subprocess
import textwrap
from collections.abc import Iterator
from pathlib import Path

import pytest
from harness import REPO_ROOT

ENVHUB_BIN = REPO_ROOT / "target" / "release" / "envhub"

DAEMON_REGISTRY = textwrap.dedent(
    """\
    environments:
      - id: mysim-echo
        name: My simulator echo
        framework: mysim
        env_id: Echo-v0
        robot_type: custom
        env_type: floor
        kwargs: {gain: 2}
    """
)


@pytest.fixture
def daemon(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[subprocess.Popen[str]]:
    """`envhub serve` over a registry with `mysim-echo`, started without any user adapter;
    this process's clients use it (ENVHUB_HUB)."""
    if not ENVHUB_BIN.is_file():
        message = f"{ENVHUB_BIN} is not built; run `make py-install`"
        if os.environ.get("ENVHUB_PY_REQUIRED"):
            pytest.fail(message)
        pytest.skip(message)
    registry = tmp_path / "registry.yaml"
    registry.write_text(DAEMON_REGISTRY)
    socket = tmp_path / "hub.sock"
    env = {k: v for k, v in os.environ.items() if k not in ("ENVHUB_ADAPTERS", "PYTHONPATH")}
    env["ENVHUB_REGISTRY"] = f"@default:{registry}"
    proc = subprocess.Popen(
        [str(ENVHUB_BIN), "serve", "--local-only", "--socket", str(socket)],
        env=env,
        cwd=REPO_ROOT,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 60)
        line = proc.stdout.readline() if ready else ""
        assert "listening on" in line, f"the daemon said {line!r} (exit status {proc.poll()})"
        monkeypatch.setenv("ENVHUB_HUB", str(socket))
        # `register` edits this process's environment: undo it after the test.
        monkeypatch.delenv("ENVHUB_ADAPTERS", raising=False)
        monkeypatch.setenv("PYTHONPATH", os.environ.get("PYTHONPATH", ""))
        yield proc
    finally:
        proc.kill()
        proc.wait(timeout=10)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Hub:
    def __init__(self, name: str, tmp: Path) -> None:
        self.name = name
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        self.namespace = f"pyhub_{name}_{os.getpid()}_"
        env = {k: v for k, v in os.environ.items() if k not in ("ENVHUB_ADAPTERS", "ENVHUB_CONNECT")}
        env.update(ENVHUB_NAMESPACE=self.namespace, ENVHUB_MULTICAST="0")
        self.proc = subprocess.Popen(
            [str(ENVHUB_BIN), "serve", "--socket", str(tmp / f"{name}.sock"), "--name", name]
            + ["--listen", self.endpoint],
            env=env,
            cwd=REPO_ROOT,
            stdout=subprocess.PIPE,
            text=True,
        )
        # The hub prints three lines once it is up (or exits: end of file).
        said = ""
        for _ in range(3):
            said += self.proc.stdout.readline()
        assert "on the network" in said, f"hub {name} said {said!r} (exit status {self.proc.poll()})"

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait(timeout=10)
        for path in Path("/dev/shm").glob(f"*{self.namespace}*"):
            path.unlink(missing_ok=True)


@pytest.fixture
def two_hubs(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Iterator[tuple[Hub, Hub]]:
    if not ENVHUB_BIN.is_file():
        message = f"{ENVHUB_BIN} is not built; run `make py-install`"
        if os.environ.get("ENVHUB_PY_REQUIRED"):
            pytest.fail(message)
        pytest.skip(message)
    a = Hub("pya", tmp_path)
    b = Hub("pyb", tmp_path)
    monkeypatch.setenv("ENVHUB_CONNECT", f"{a.endpoint},{b.endpoint}")
    monkeypatch.setenv("ENVHUB_MULTICAST", "0")
    try:
        yield a, b
    finally:
        a.stop()
        b.stop()
