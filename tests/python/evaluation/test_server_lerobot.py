"""LeRobot 0.6.1's async-inference policy server, unchanged, through envhub's `lerobot`
protocol client (`envhub eval --server lerobot://... --server-protocol lerobot`).

The server is started with LeRobot's own entry point (`python -m
lerobot.async_inference.policy_server`) in a CPython 3.12 interpreter with LeRobot 0.6.1
(the repository's `.venv-lerobot` when it has the server's gRPC dependencies, else one
the tests build, eval_peers.lerobot_peer_python), serving a small ACT policy saved with
LeRobot's `save_pretrained` (random weights, no download). An episode's requests through
envhub's client (grpcio alone in envhub's interpreter) get the action chunks LeRobot's own
`PolicyServer` computes in-process for the same observations; a server that is not there
fails the batch naming it; what the server answers is read by an unpickler that runs nothing
but LeRobot's `TimedAction` and torch's tensor rebuild.

Skips with the reason where grpcio (envhub's side) or that interpreter is missing; failures
instead under ENVHUB_LEROBOT_REQUIRED=1 or ENVHUB_PYENV_REQUIRED=1.
"""

from __future__ import annotations

import io
import os
import pickle
import socket
import subprocess
import time

import eval_peers
import lerobot_peer
import numpy as np
import pytest
from harness import REPO_ROOT, SUPPORT, import_envhub

import_envhub()

from envhub.evaluation.policy import Episode, PolicyError, Request, Task  # noqa: E402

REQUIRED = bool(os.environ.get("ENVHUB_LEROBOT_REQUIRED") or os.environ.get("ENVHUB_PYENV_REQUIRED"))


def _skip(reason: str) -> None:
    if REQUIRED:
        pytest.fail(f"{reason}, and ENVHUB_LEROBOT_REQUIRED is set")
    pytest.skip(reason)


@pytest.fixture(scope="module")
def grpc_here():
    try:
        import grpc  # noqa: F401
    except ImportError:
        _skip("grpcio is not installed in envhub's interpreter (pip install 'grpcio>=1.73')")


@pytest.fixture(scope="module")
def lerobot(grpc_here) -> str:
    python = eval_peers.lerobot_peer_python(REPO_ROOT)
    if python is None:
        _skip(f"no LeRobot 0.6.1 interpreter with its policy server here: {eval_peers.LAST_REASON}")
    return python


def test_finding_the_server_leaves_nothing_where_it_runs(grpc_here, tmp_path, monkeypatch) -> None:
    """Importing LeRobot's policy server opens a log under `./logs`; the probe that looks for
    an interpreter with it runs elsewhere, so a test run writes nothing into the checkout."""
    monkeypatch.chdir(tmp_path)
    if eval_peers.lerobot_peer_python(REPO_ROOT) is None:
        _skip(f"no LeRobot 0.6.1 interpreter with its policy server here: {eval_peers.LAST_REASON}")
    assert list(tmp_path.iterdir()) == []


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def served(lerobot, tmp_path_factory):
    """The test policy saved, and LeRobot's policy server on a free port."""
    work = tmp_path_factory.mktemp("lerobot-server")
    folder = work / "policy"
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    made = subprocess.run(
        [lerobot, str(SUPPORT / "eval_peers.py"), "lerobot-make-policy", str(folder)],
        capture_output=True, text=True, timeout=600, env=env, cwd=work,
    )
    assert made.returncode == 0, made.stderr[-3000:]
    port = _free_port()
    proc = subprocess.Popen(
        [lerobot, "-m", "lerobot.async_inference.policy_server", "--host=127.0.0.1", f"--port={port}",
         "--fps=30", "--inference_latency=0", "--obs_queue_timeout=30"],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env, cwd=work,
    )
    deadline = time.monotonic() + 180
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            time.sleep(0.5)
    if proc.poll() is not None or time.monotonic() >= deadline:
        proc.kill()
        pytest.fail(f"LeRobot's policy server did not listen on {port} (exit code {proc.poll()})")
    yield {"port": port, "folder": folder, "work": work, "env": env}
    proc.kill()
    proc.wait(timeout=30)


def observation(rng: np.random.Generator) -> dict[str, np.ndarray]:
    h, w = lerobot_peer.LEROBOT_CAMERA
    return {
        "front_image": rng.integers(0, 256, (h, w, 3), dtype=np.uint8),
        "state": rng.standard_normal(lerobot_peer.LEROBOT_STATE),
    }


def test_lerobots_server_gives_what_it_computes_in_process(lerobot, served) -> None:
    from envhub.evaluation.servers import connect

    url = (
        f"lerobot://127.0.0.1:{served['port']}?policy_type=act&pretrained={served['folder']}"
        f"&actions_per_chunk={lerobot_peer.LEROBOT_CHUNK}"
    )
    task = Task("bench", "bench/0", "bench-entry", "pick the cube", 0)
    episode = Episode(task, 0)
    rng = np.random.default_rng(7)
    requests = [Request(0, episode, step, observation(rng)) for step in range(0, 12, lerobot_peer.LEROBOT_CHUNK)]
    with connect("lerobot", url, timeout=300) as policy:
        policy.start(0, episode)
        chunks = [policy.act([r])[0] for r in requests]
        sent = [policy._raw(r)[::-1] for r in requests]  # (features, raw observation)
        described = policy.describe()
    assert described["protocol"] == "lerobot" and described["server"]["policy_type"] == "act"
    # The raw observation LeRobot's robot client would send: state entries by name, the
    # camera by its name, the task's text.
    features, raw = sent[0]
    assert features["observation.state"]["names"] == [f"state.{i}" for i in range(lerobot_peer.LEROBOT_STATE)]
    assert features["observation.images.front"]["shape"] == (*lerobot_peer.LEROBOT_CAMERA, 3)
    assert raw["task"] == "pick the cube"
    inputs, outputs = served["work"] / "in.pkl", served["work"] / "out.pkl"
    inputs.write_bytes(pickle.dumps(sent))
    ref = subprocess.run(
        [lerobot, str(SUPPORT / "eval_peers.py"), "lerobot-reference", str(served["folder"]), str(inputs), str(outputs)],
        capture_output=True, text=True, timeout=600, env=served["env"], cwd=served["work"],
    )
    assert ref.returncode == 0, ref.stderr[-3000:]
    want = pickle.loads(outputs.read_bytes())
    assert len(chunks) == len(want) == 3
    for got, expected in zip(chunks, want):
        assert got.shape == (lerobot_peer.LEROBOT_CHUNK, lerobot_peer.LEROBOT_ACTION) and got.dtype == np.float32
        # The same torch ops in two processes: equal to float32's rounding.
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)
    assert not np.allclose(chunks[0], chunks[1])  # the observations steer the policy


# robosuite's Lift with cameras, a few steps: LeRobot's server drives an envhub evaluation.
LIFT = {
    "name": "lift-lerobot",
    "entries": ["robosuite-lift-camera"],
    "episodes_per_task": 2,
    "init": {"seed_start": 0},
    "horizon": 6,
    "success": {"rule": "none"},
}


def test_lerobots_server_drives_an_envhub_evaluation(lerobot, served, tmp_path) -> None:
    """`evaluate` (what `envhub eval --server lerobot://... --server-protocol lerobot` runs)
    on robosuite Lift's camera and end-effector state, the policy's actions from LeRobot's
    server, chunks of 4 executed one action a step."""
    from envhub.evaluation import evaluate
    from envhub.evaluation.servers import connect

    url = (
        f"lerobot://127.0.0.1:{served['port']}?policy_type=act&pretrained={served['folder']}"
        f"&actions_per_chunk={lerobot_peer.LEROBOT_CHUNK}&images=agentview_image:front"
        "&state=robot0_eef_pos,robot0_gripper_qpos"
    )
    try:
        results = evaluate(LIFT, connect("lerobot", url, timeout=300), num_envs=2, progress=False, out=tmp_path / "run")
    except Exception as exc:  # the suite's environment missing here: said by the adapter
        if "robosuite" in str(exc) and ("unavailable" in str(exc) or "not available" in str(exc)):
            _skip(f"robosuite is not available here: {exc}")
        raise
    assert [e["error"] for e in results["episodes"]] == [None, None]
    assert [e["length"] for e in results["episodes"]] == [6, 6]
    assert results["policy"]["protocol"] == "lerobot"


def test_a_server_that_is_not_there_fails_the_batch_naming_it(grpc_here) -> None:
    from envhub.evaluation.servers import connect

    port = _free_port()
    with connect("lerobot", f"lerobot://127.0.0.1:{port}?policy_type=act&pretrained=/nowhere", timeout=2) as policy:
        episode = Episode(Task("bench", "bench/0", "bench-entry", "x", 0), 0)
        with pytest.raises(PolicyError, match=f"the LeRobot server at lerobot://127.0.0.1:{port} "):
            policy.act([Request(0, episode, 0, {"state": np.zeros(3)})])


def test_a_url_without_the_policy_is_an_error(grpc_here) -> None:
    from envhub.evaluation.servers import connect

    with pytest.raises(ValueError, match="needs policy_type and pretrained"):
        connect("lerobot", "lerobot://127.0.0.1:8080")
    with pytest.raises(ValueError, match=r"unknown LeRobot server options \['chunk'\]"):
        connect("lerobot", "lerobot://127.0.0.1:8080?policy_type=act&pretrained=x&chunk=3")


def test_the_answer_runs_nothing_but_timed_actions() -> None:
    """A server's answer naming anything but TimedAction and torch's tensor rebuild is
    refused before it runs."""
    from envhub.evaluation.servers.lerobot import _ActionUnpickler

    class Evil:
        def __reduce__(self):
            return (os.system, ("echo owned",))

    with pytest.raises(pickle.UnpicklingError, match="names posix.system, which envhub does not load"):
        _ActionUnpickler(io.BytesIO(pickle.dumps([Evil()]))).load()
