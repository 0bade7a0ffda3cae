"""The policy servers of the evaluation's tests, run inside the peers' environment by
`eval_peers.py vla-eval|openpi|...` (see there): vla-eval's and OpenPI's servers serving the
reference policies, servers that log what they are sent, and OpenPI's LIBERO example client."""

from __future__ import annotations

import os

import numpy as np
from eval_peers import ACTION_DIM, HORIZON, linear_action, linear_chunk, reference_action, reference_chunk


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
