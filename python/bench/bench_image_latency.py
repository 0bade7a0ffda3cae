"""Camera frames from another interpreter (issue 20): the time from the end of an env's
render to a numpy array of its frame in the client, per env, through envhub (the frame
written into the shared-memory batch slot, viewed in place) against OpenPI's way (the
frames packed with msgpack, numpy arrays as bytes plus dtype and shape, sent over a
websocket on loopback, unpacked into arrays viewing the received message), in one run.

    .venv/bin/python python/bench/bench_image_latency.py [--shape 224 224 3] [--envs 1 8] [--steps 300]

The env "renders" by filling its frame (a fresh array each step, as a renderer returns) and
then writes the render's end (CLOCK_MONOTONIC, which every process on the machine shares,
in ns) into the frame's first 8 bytes; the client reads it back from the array it got. For a
batch of N envs, "last render → view" is measured from the last env's render end (the
transport of the whole batch), and "per env" divides it by N; "mean over envs" is the mean
of each env's own render end to the view (it includes the rendering of the envs after it in
its worker). Medians over `--steps` steps; the websocket server answers one message per
step carrying every env's frame (OpenPI's client sends one observation dict per call).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from typing import Any

import gymnasium as gym
import numpy as np

CLOCK = time.CLOCK_MONOTONIC


def now_ns() -> int:
    return time.clock_gettime_ns(CLOCK)


class StampedCamera(gym.Env):
    """An env whose observation is a camera frame stamped with the end of its render."""

    metadata = {"render_modes": []}

    def __init__(self, shape: tuple[int, ...] = (224, 224, 3)) -> None:
        self.observation_space = gym.spaces.Box(0, 255, shape, np.uint8)
        self.action_space = gym.spaces.Discrete(2)
        self.pattern = np.random.default_rng(0).integers(0, 255, shape, dtype=np.uint8)

    def render_frame(self) -> np.ndarray:
        frame = self.pattern.copy()  # a renderer hands back a new frame each time
        frame.reshape(-1)[:8].view(np.int64)[0] = now_ns()
        return frame

    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        super().reset(seed=seed)
        return self.render_frame(), {}

    def step(self, action: Any) -> Any:
        return self.render_frame(), 0.0, False, False, {}


def stamps(frames: np.ndarray) -> np.ndarray:
    n = frames.shape[0]
    return np.ascontiguousarray(frames.reshape(n, -1)[:, :8]).view(np.int64)[:, 0]


# OpenPI's way: msgpack with numpy arrays as {dtype, shape, bytes} --------------------------


def _pack_array(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return {b"__ndarray__": True, b"data": obj.tobytes(), b"dtype": obj.dtype.str, b"shape": obj.shape}
    return obj


def _unpack_array(obj: dict) -> Any:
    if b"__ndarray__" in obj:
        return np.frombuffer(obj[b"data"], dtype=np.dtype(obj[b"dtype"])).reshape(obj[b"shape"])
    return obj


def serve(port: int, num_envs: int, shape: tuple[int, ...]) -> None:
    """The env side: a websocket server that steps its envs for each request and answers
    with their frames."""
    import msgpack
    from websockets.sync.server import serve as ws_serve

    envs = [StampedCamera(shape) for _ in range(num_envs)]
    packer = msgpack.Packer(default=_pack_array)

    def handler(ws: Any) -> None:
        for message in ws:
            actions = msgpack.unpackb(message)
            frames = np.stack([env.step(a)[0] for env, a in zip(envs, actions, strict=True)])
            ws.send(packer.pack({"observation/image": frames}))

    with ws_serve(handler, "127.0.0.1", port, max_size=None, compression=None) as server:
        print("ready", flush=True)
        server.serve_forever()


def openpi_latency(num_envs: int, shape: tuple[int, ...], steps: int) -> list[int]:
    import socket

    import msgpack
    from websockets.sync.client import connect

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cmd = [sys.executable, __file__, "--serve", str(port), "--envs", str(num_envs), "--shape", *map(str, shape)]
    server = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
    try:
        assert server.stdout is not None and server.stdout.readline().strip() == "ready"
        out = []
        with connect(f"ws://127.0.0.1:{port}", max_size=None, compression=None) as ws:
            for t in range(steps + 20):
                ws.send(msgpack.packb([0] * num_envs))
                frames = msgpack.unpackb(ws.recv(), object_hook=_unpack_array)["observation/image"]
                end = now_ns()
                if t >= 20:
                    out.append(end - stamps(frames))
        return out
    finally:
        server.terminate()
        server.wait(10)


def envhub_latency(num_envs: int, shape: tuple[int, ...], steps: int) -> list[np.ndarray]:
    import envhub

    envs = envhub.AsyncVectorEnv([lambda: StampedCamera(shape) for _ in range(num_envs)], num_workers=1)
    try:
        envs.reset(seed=0)
        actions = np.zeros(num_envs, np.int64)
        out = []
        for t in range(steps + 20):
            frames = envs.step(actions)[0]
            end = now_ns()
            if t >= 20:
                out.append(end - stamps(frames))
        assert envs._session.obs_bytes_copied == 0
        return out
    finally:
        envs.close()


def summary(lat: list[np.ndarray], n: int) -> dict[str, float]:
    last = np.array([x.min() for x in lat]) / 1e3  # from the last render's end
    mean = np.array([x.mean() for x in lat]) / 1e3
    return {
        "last_render_to_view_us": round(float(np.median(last)), 1),
        "per_env_us": round(float(np.median(last)) / n, 1),
        "mean_over_envs_us": round(float(np.median(mean)), 1),
    }


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--shape", type=int, nargs="+", default=[224, 224, 3])
    p.add_argument("--envs", type=int, nargs="+", default=[1, 8])
    p.add_argument("--steps", type=int, default=300)
    p.add_argument("--serve", type=int, help=argparse.SUPPRESS)
    args = p.parse_args()
    shape = tuple(args.shape)
    if args.serve:
        serve(args.serve, args.envs[0], shape)
        return
    rows = []
    for n in args.envs:
        ours = summary(envhub_latency(n, shape, args.steps), n)
        theirs = summary(openpi_latency(n, shape, args.steps), n)
        rows.append({"envs": n, "shape": list(shape), "envhub": ours, "openpi_style": theirs})
        print(json.dumps(rows[-1]), flush=True)
    print("\n| envs | envhub last render → view µs | per env | OpenPI-style (websocket + msgpack) µs | per env | ratio |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        a, b = r["envhub"], r["openpi_style"]
        ratio = b["last_render_to_view_us"] / max(a["last_render_to_view_us"], 1e-9)
        print(
            f"| {r['envs']} | {a['last_render_to_view_us']} | {a['per_env_us']} | "
            f"{b['last_render_to_view_us']} | {b['per_env_us']} | {ratio:.1f}× |"
        )


if __name__ == "__main__":
    main()
