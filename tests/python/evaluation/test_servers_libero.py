"""LIBERO end to end: what envhub sends a policy server is what the server's own harness
sends, for the same episode (libero-spatial task 0, init state 0, a few steps).

- vla-eval: `vla-eval run --no-docker` (vla-eval 0.8.0's own harness: its LIBERO benchmark
  and sync runner, the server's HELLO params merged into the benchmark's) and `envhub eval`
  against the same logging vla-eval server program (a `PredictModelServer` asking for
  `send_wrist_image` and `send_state`, recording what it is given): the same observations,
  key for key in the same order, arrays of the same dtype, shape and bytes.
- OpenPI: OpenPI's LIBERO example's episode (its `eval_libero` loop reproduced for one
  episode: openpi-client's own `image_tools` and `WebsocketClientPolicy`, the example's
  seeding, waiting steps, state and replanning) and `envhub eval` with `replan_steps=5`
  send a logging OpenPI server the same request frames, byte for byte.

Both harnesses run in an interpreter with envhub's LIBERO packages at the same versions plus
vla-eval and openpi-client (eval_peers.libero_peer_python), built once with uv. Skips with
the reason where LIBERO's catalog environment or that interpreter cannot be built; failures
instead under ENVHUB_LIBERO_REQUIRED / ENVHUB_SUITES_REQUIRED (and ENVHUB_PYENV_REQUIRED for
the interpreter).
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import eval_peers
import pytest
from harness import SUPPORT, import_envhub
from policy_servers import (
    BOTH,
    Server,
    assert_same,
    logging_server,
    peers,  # noqa: F401 - a fixture
    read_log,
)

import_envhub()

from envhub.evaluation.catalog import Catalog  # noqa: E402
from envhub.evaluation.servers import connect  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_PYENV_REQUIRED"))
LIBERO_REQUIRED = bool(os.environ.get("ENVHUB_LIBERO_REQUIRED") or os.environ.get("ENVHUB_SUITES_REQUIRED"))


HORIZON = 3


def libero_python() -> str:
    from envhub._cli import BINARY

    def skip(reason: str) -> None:
        if LIBERO_REQUIRED:
            pytest.fail(f"{reason}, and ENVHUB_LIBERO_REQUIRED is set")
        pytest.skip(reason)

    done = subprocess.run([str(BINARY), "env", "sync", "libero"], capture_output=True, text=True, timeout=1800)
    import re

    found = re.search(r"^libero: (?:built|ready) in [0-9.]+ s \((.*)\)$", done.stdout, re.M)
    if done.returncode != 0 or not found:
        skip(f"LIBERO's Python environment cannot be built here: {(done.stderr or done.stdout)[-1500:]}")
    python = os.path.join(found.group(1), "bin", "python")
    peer = eval_peers.libero_peer_python(python)
    if peer is None:
        reason = f"LIBERO with vla-eval and openpi-client cannot be built here: {eval_peers.LAST_REASON}"
        if REQUIRED or LIBERO_REQUIRED:
            pytest.fail(reason)
        pytest.skip(reason)
    return peer


@pytest.fixture(scope="module")
def libero_peer(peers) -> str:
    return libero_python()


def envhub_episode(policy, tmp_path: Path, name: str, horizon: int) -> dict:
    from envhub.evaluation import evaluate

    decl = dict(Catalog().declared["libero-spatial"])
    results = evaluate(
        {**decl, "name": "libero-spatial", "horizon": horizon},
        policy,
        tasks=["0"],
        episodes=1,
        out=tmp_path / name,
        progress=False,
    )
    assert results["summary"]["errors"] == 0, [e["error"] for e in results["episodes"]]
    return results


def test_vla_eval_harness_and_envhub_send_the_same(libero_peer, tmp_path) -> None:
    env = eval_peers.libero_peer_env(libero_peer)
    # vla-eval's own harness: its LIBERO benchmark and sync runner, the server's params merged.
    theirs = tmp_path / "vla-eval.pkl"
    server = logging_server(libero_peer, theirs, BOTH, env=env)
    try:
        config = {
            "server": {"url": server.url},
            "output_dir": str(tmp_path / "vla-eval-out"),
            "benchmarks": [
                {
                    "benchmark": "vla_eval.benchmarks.libero.benchmark:LIBEROBenchmark",
                    "episodes_per_task": 1,
                    "max_tasks": 1,
                    "params": {"suite": "libero_spatial", "max_steps": HORIZON},
                }
            ],
        }
        (tmp_path / "vla-eval.yaml").write_text(json.dumps(config))
        vla = str(Path(libero_peer).parent / "vla-eval")
        done = subprocess.run(
            [vla, "run", "--no-docker", "-c", str(tmp_path / "vla-eval.yaml")],
            capture_output=True, text=True, timeout=1800, env=env, cwd=tmp_path,
        )
        assert done.returncode == 0, (done.stdout[-3000:], done.stderr[-3000:])
    finally:
        server.stop()
    # envhub, the same episode, against the same server program.
    ours = tmp_path / "envhub.pkl"
    server = logging_server(libero_peer, ours, BOTH, env=env)
    try:
        results = envhub_episode(connect("vla-eval", server.url, timeout=120), tmp_path, "envhub-vla", HORIZON)
    finally:
        server.stop()
    want, got = read_log(theirs), read_log(ours)
    assert len(want) == HORIZON, len(want)
    assert len(got) == len(want), (len(got), len(want))
    for step, (g, w) in enumerate(zip(got, want)):
        assert_same(g, w, f"step {step}")
    assert results["policy"]["layout"]["params"] == BOTH


def test_openpi_example_and_envhub_send_the_same_bytes(libero_peer, tmp_path) -> None:
    env = eval_peers.libero_peer_env(libero_peer)
    replan, horizon = 5, 7  # two requests: steps 0 and 5
    theirs = tmp_path / "example.pkl"
    server = Server(libero_peer, "openpi-logging", "--log", str(theirs), "--chunk", str(replan), env=env)
    try:
        done = subprocess.run(
            [libero_peer, str(SUPPORT / "eval_peers.py"), "openpi-libero-example", "--url", server.url,
             "--max-steps", str(horizon), "--chunk", str(replan)],
            capture_output=True, text=True, timeout=1800, env=env,
        )
        assert done.returncode == 0, done.stderr[-3000:]
    finally:
        server.stop()
    ours = tmp_path / "envhub.pkl"
    server = Server(libero_peer, "openpi-logging", "--log", str(ours), "--chunk", str(replan), env=env)
    try:
        policy = connect("openpi", server.url, timeout=120, replan_steps=replan)
        envhub_episode(policy, tmp_path, "envhub-openpi", horizon)
    finally:
        server.stop()
    want, got = read_log(theirs), read_log(ours)
    assert len(want) == 2 and len(got) == 2, (len(want), len(got))
    for step, (g, w) in enumerate(zip(got, want)):
        assert g == w, f"request {step}: {len(g)} bytes from envhub, {len(w)} from the example"
