"""Policy servers in subprocesses for the evaluation's server tests: the peers' environment
(vla-eval and openpi-client from PyPI, `eval_peers.peer_python`, built once with uv), a server
on the port it printed, and what a logging server says it was sent."""

from __future__ import annotations

import json
import os
import pickle
import selectors
import subprocess
import time
from pathlib import Path

import eval_peers
import numpy as np
import pytest
from harness import SUPPORT

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
BOTH = {"send_wrist_image": True, "send_state": True}


@pytest.fixture(scope="module")
def peers() -> str:
    python = eval_peers.peer_python()
    if python is None:
        reason = f"the peers' environment (vla-eval, openpi-client) cannot be built: {eval_peers.LAST_REASON}"
        if REQUIRED:
            pytest.fail(f"{reason}, and ENVHUB_PYENV_REQUIRED is set")
        pytest.skip(reason)
    return python


class Server:
    """A policy server in a subprocess, on the port it printed."""

    def __init__(self, python: str, *args: str, env: dict | None = None) -> None:
        self.proc = subprocess.Popen(
            [python, str(SUPPORT / "eval_peers.py"), *args],
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            text=True,
            env=env,
        )
        selector = selectors.DefaultSelector()
        selector.register(self.proc.stdout, selectors.EVENT_READ)
        deadline = time.monotonic() + 60
        line = ""
        while time.monotonic() < deadline and not line.startswith("PORT"):
            if selector.select(timeout=max(0.0, deadline - time.monotonic())):
                line = self.proc.stdout.readline()
                if not line:
                    break
        selector.close()
        if not line.startswith("PORT"):
            self.stop()
            raise RuntimeError(f"the {args[0]} server did not start (exit code {self.proc.returncode})")
        self.url = f"ws://127.0.0.1:{int(line.split()[1])}"

    def stop(self) -> None:
        self.proc.kill()
        self.proc.wait(timeout=10)


def read_log(path: Path) -> list:
    out = []
    if not path.exists():
        return out
    with open(path, "rb") as f:
        while True:
            try:
                out.append(pickle.load(f))
            except EOFError:
                return out


def assert_same(got, want, where: str = "") -> None:
    """Equal as the server sees them: the same keys in the same order, and arrays of the
    same dtype, shape and bytes."""
    if isinstance(want, dict):
        assert isinstance(got, dict) and list(got) == list(want), (where, list(got), list(want))
        for key in want:
            assert_same(got[key], want[key], f"{where}.{key}")
    elif isinstance(want, np.ndarray):
        assert isinstance(got, np.ndarray), (where, type(got))
        assert (got.dtype, got.shape) == (want.dtype, want.shape), (where, got.dtype, got.shape, want.dtype, want.shape)
        assert got.tobytes() == want.tobytes(), (where, got, want)
    else:
        assert type(got) is type(want) and got == want, (where, got, want)


def logging_server(python: str, log: Path, params: dict, env: dict | None = None) -> Server:
    return Server(python, "vla-eval-logging", "--log", str(log), "--params", json.dumps(params), env=env)


# HalfCheetah, short: the same per-episode results whoever computes the actions.
CHEETAH = {
    "name": "cheetah-short",
    "entries": ["mujoco-half-cheetah"],
    "episodes_per_task": 3,
    "init": {"seed_start": 0},
    "horizon": 40,
    "success": {"rule": "none"},
}


def evaluate_or_skip():
    try:
        from envhub.evaluation import evaluate
    except ImportError as exc:
        pytest.skip(f"envhub.evaluation.evaluate is not here yet ({exc})")
    import envhub
    from harness import mujoco_or_skip

    mujoco_or_skip(envhub)
    return evaluate
