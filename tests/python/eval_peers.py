"""The peers of the evaluation's tests, from PyPI, in a Python environment of their own:
vla-eval (its model-server base classes and server), openpi-client (its msgpack + numpy
wire) and Playwright (the report's browser test). `peer_python()` builds it once with uv
into the cache folder and returns its interpreter.

Run as a script inside that environment it is a policy server:
    python eval_peers.py vla-eval|openpi [--chunk K] [--batch B]
serving `reference_action` (`linear_action` for an observation without images) on 127.0.0.1 (a free port, printed as `PORT n`). A task text
that names a misbehaviour makes the server do it: `stall` (never answers), `disconnect`
(closes the connection), `malformed` (answers something that is not an action), `error`
(its policy raises), `exit` (the process exits).
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


# -- the servers (run inside the peers' environment) ----------------------------------------


def _misbehaviour(text: str) -> str | None:
    for word in ("stall", "disconnect", "malformed", "error", "exit"):
        if word in text:
            return word
    return None


def serve_vla_eval(chunk: int | None, batch: int, action_dim: int) -> None:
    """A vla-eval model server written with vla-eval's own base class, served by vla-eval."""
    import anyio
    import websockets
    from vla_eval.model_servers.predict import PredictModelServer
    from vla_eval.model_servers.serve import serve_async

    class Reference(PredictModelServer):
        def _act(self, obs):
            if "images" not in obs:  # a state-vector benchmark: the linear policy
                return {"actions": linear_action(obs["states"], self.action_dim)}
            image, state, text = obs["images"]["agentview"], obs["states"], obs["task_description"]
            if chunk:
                return {"actions": reference_chunk(image, state, text, chunk)}
            return {"actions": reference_action(image, state, text)}

        def predict(self, obs, ctx):
            return self._act(obs)

        def predict_batch(self, obs_batch, ctx_batch):
            return [self._act(obs) for obs in obs_batch]

        async def on_episode_start(self, config, ctx):
            self.tasks[ctx.session_id] = config["task"]
            await super().on_episode_start(config, ctx)

        async def on_observation(self, obs, ctx):
            if obs.get("task_description", "").startswith("echo"):
                # Answers with what EPISODE_START said of the task, and the step it is at.
                task = self.tasks[ctx.session_id]
                fields = [
                    task["task_id"],
                    task["episode_idx"],
                    task.get("init_state", -1),
                    task.get("level", -1),
                ]
                await ctx.send_action(
                    {"actions": np.array([*fields, len(task["name"]), ctx.step, 0], np.float32)}
                )
                return
            trouble = _misbehaviour(obs.get("task_description", ""))
            if trouble == "stall":
                await anyio.sleep(3600)
            elif trouble == "disconnect":
                # vla-eval's server ends the connection's handler on this.
                raise websockets.exceptions.ConnectionClosed(None, None)
            elif trouble == "malformed":
                await ctx.send_action({"actions": "seven floats"})
                return
            elif trouble == "error":
                raise ValueError("the reference policy refuses this task")
            elif trouble == "exit":
                os._exit(3)
            await super().on_observation(obs, ctx)

    async def main() -> None:
        server = Reference(chunk_size=chunk, max_batch_size=batch, max_wait_time=0.005)
        server.tasks = {}
        server.action_dim = action_dim
        async with anyio.create_task_group() as tg:
            port = await tg.start(serve_async, server, "127.0.0.1", 0)
            print(f"PORT {port}", flush=True)

    anyio.run(main)


def serve_openpi(action_dim: int) -> None:
    """An OpenPI-protocol server as OpenPI's `serve_policy.py` runs one: openpi-client's
    msgpack_numpy over websockets, metadata first, a traceback as text on failure."""
    import asyncio
    import traceback

    import websockets.asyncio.server
    import websockets.frames
    from openpi_client import base_policy, msgpack_numpy

    class Reference(base_policy.BasePolicy):
        def infer(self, obs):
            text = obs["prompt"]
            if _misbehaviour(text) == "error":
                raise ValueError("the reference policy refuses this task")
            if "observation/image" not in obs:  # a state-vector benchmark: the linear policy
                return {"actions": linear_chunk(obs["observation/state"], action_dim)}
            return {"actions": reference_chunk(obs["observation/image"], obs["observation/state"], text)}

    policy = Reference()
    metadata = {"policy": "reference", "action_horizon": HORIZON, "action_dim": ACTION_DIM}

    async def handler(ws) -> None:
        packer = msgpack_numpy.Packer()
        await ws.send(packer.pack(metadata))
        while True:
            try:
                obs = msgpack_numpy.unpackb(await ws.recv())
                trouble = _misbehaviour(obs.get("prompt", ""))
                if trouble == "stall":
                    await asyncio.sleep(3600)
                elif trouble == "disconnect":
                    await ws.close()
                    return
                elif trouble == "malformed":
                    await ws.send(packer.pack({"action": np.zeros((2, 3, 4))}))
                    continue
                elif trouble == "exit":
                    os._exit(3)
                action = policy.infer(obs)
                action["server_timing"] = {"infer_ms": 0.0}
                await ws.send(packer.pack(action))
            except websockets.ConnectionClosed:
                return
            except Exception:
                await ws.send(traceback.format_exc())
                await ws.close(
                    code=websockets.frames.CloseCode.INTERNAL_ERROR, reason="Internal server error."
                )
                return

    async def main() -> None:
        async with websockets.asyncio.server.serve(
            handler, "127.0.0.1", 0, compression=None, max_size=None
        ) as server:
            print(f"PORT {server.sockets[0].getsockname()[1]}", flush=True)
            await server.serve_forever()

    asyncio.run(main())


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser()
    parser.add_argument("protocol", choices=["vla-eval", "openpi"])
    parser.add_argument("--chunk", type=int, default=None)
    parser.add_argument("--batch", type=int, default=1)
    parser.add_argument("--action-dim", type=int, default=ACTION_DIM)
    args = parser.parse_args()
    if args.protocol == "vla-eval":
        serve_vla_eval(args.chunk, args.batch, args.action_dim)
    else:
        serve_openpi(args.action_dim)
