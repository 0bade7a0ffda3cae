"""The Python worker: `python -m envhub.worker describe | serve --job JSON`.

Started by the hub for Python-hosted adapters (see `envhub.hosted`). `describe` prints the
adapters this interpreter can host, as JSON; `serve` creates a job's envs here and hands
them to the Rust serve loop in `envhub._envhub.serve_worker`, which speaks the same
shared-memory protocol as the Rust `envhub-worker`: actions arrive as read-only numpy views
of the request sample, each observation is copied once into the response sample.

Anything the envs print goes to stderr: stdout carries only the one ready line.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import traceback
from typing import Any

import numpy as np

from . import _envhub
from ._spaces import _Leaf, _tree, from_gymnasium
from .config import EnvConfig
from .hosted import all_adapters


class HostedEnv:
    """One env, as `serve_worker` drives it: results are written into the slots it gives."""

    def __init__(self, env: Any, obs_desc: dict[str, Any], act_desc: dict[str, Any]) -> None:
        self.env = env
        self.obs_tree = _tree(obs_desc, json.loads(_envhub.space_leaves_json(json.dumps(obs_desc))))
        self.act_tree = _tree(act_desc, json.loads(_envhub.space_leaves_json(json.dumps(act_desc))))

    def _write(self, node: Any, value: Any, buf: np.ndarray) -> None:
        if isinstance(node, _Leaf):
            dst = buf[node.offset : node.offset + node.nbytes].view(node.dtype).reshape(node.shape)
            dst[...] = value
            return
        kind, children = node
        if kind == "dict":
            for key, child in children:
                self._write(child, value[key], buf)
        else:
            for i, child in enumerate(children):
                self._write(child, value[i], buf)

    def _read(self, node: Any, buf: np.ndarray) -> Any:
        if isinstance(node, _Leaf):
            return buf[node.offset : node.offset + node.nbytes].view(node.dtype).reshape(node.shape)
        kind, children = node
        if kind == "dict":
            return {key: self._read(child, buf) for key, child in children}
        return tuple(self._read(child, buf) for child in children)

    def reset_into(self, seed: int | None, options: str | None, out: memoryview) -> str | None:
        obs, info = self.env.reset(seed=seed, options=json.loads(options) if options else None)
        self._write(self.obs_tree, obs, np.frombuffer(out, dtype=np.uint8))
        return info_json(info)

    def step_into(self, action: memoryview, out: memoryview) -> tuple[float, bool, bool, str | None]:
        act = self._read(self.act_tree, np.frombuffer(action, dtype=np.uint8))
        obs, reward, terminated, truncated, info = self.env.step(act)
        self._write(self.obs_tree, obs, np.frombuffer(out, dtype=np.uint8))
        return float(reward), bool(terminated), bool(truncated), info_json(info)

    def render_rgb(self) -> tuple[int, int, bytes] | None:
        frame = self.env.render()
        if frame is None:
            return None
        a = np.ascontiguousarray(frame, dtype=np.uint8)
        return int(a.shape[0]), int(a.shape[1]), a[..., :3].tobytes()

    def close(self) -> None:
        self.env.close()


def _info_value(v: Any) -> Any:
    if isinstance(v, (bool, np.bool_)):
        return bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    if isinstance(v, (float, np.floating)):
        return float(v)
    if isinstance(v, str):
        return v
    if isinstance(v, (np.ndarray, list, tuple)):
        a = np.asarray(v)
        if a.dtype.kind in "biuf" and a.ndim <= 1 and a.size <= 64:
            return [float(x) for x in a.reshape(-1)]
    return None


def info_json(info: dict[str, Any] | None) -> str | None:
    """The info values that travel (numbers, flags, text, short numeric vectors) as JSON."""
    if not info:
        return None
    out = {}
    for k, v in info.items():
        value = _info_value(v)
        if value is not None:
            out[str(k)] = value
    return json.dumps(out) if out else None


def _has_time_limit(env: Any) -> bool:
    import gymnasium as gym

    while env is not None:
        if isinstance(env, gym.wrappers.TimeLimit):
            return True
        env = getattr(env, "env", None)
    return False


def describe() -> list[dict[str, Any]]:
    """Every adapter this interpreter can host, as the hub's catalog reads it."""
    out = []
    for adapter, name, error in all_adapters():
        if adapter is None:
            out.append(
                {
                    "name": name,
                    "frameworks": [],
                    "requires": [],
                    "description": f"user adapter `{name}`",
                    "availability": {
                        "status": "unavailable",
                        "reason": f"cannot import `{name}`: {error}",
                        "hint": "check the import path in `adapters:` (envhub.yaml) or ENVHUB_ADAPTERS, and that its module is on PYTHONPATH",
                    },
                    "envs": [],
                }
            )
        else:
            out.append(adapter.describe())
    return out


def make_envs(job: dict[str, Any]) -> tuple[list[HostedEnv], dict[str, Any], dict[str, Any], int | None]:
    """Creates a job's envs; raises with a message that names the adapter and env."""
    name, env_id = job["adapter"], job["env_id"]
    found = [a for a, n, _ in all_adapters() if a is not None and n == name]
    if not found:
        names = ", ".join(n for _, n, _ in all_adapters())
        raise LookupError(f"this Python worker has no adapter `{name}`\nhint: it hosts: {names}")
    adapter = found[0]
    ok, reason, hint = adapter.availability()
    if not ok:
        raise RuntimeError(f"adapter `{name}` is unavailable: {reason}\nhint: {hint}")
    c = job["config"]
    config = EnvConfig(
        render_mode=c.get("render_mode"),
        seed=c.get("seed"),
        max_episode_steps=c.get("max_episode_steps"),
        num_envs=c.get("num_envs", 1),
        asset_path=c.get("asset_path"),
        extra=dict(c.get("extra") or {}),
        workers=c.get("workers"),
        autoreset_mode=c.get("autoreset_mode", "next_step"),
    )
    raw = []
    for _ in range(int(job["num_envs"])):
        env = adapter.make(env_id, config)
        if config.max_episode_steps and not _has_time_limit(env):
            import gymnasium as gym

            env = gym.wrappers.TimeLimit(env, config.max_episode_steps)
        raw.append(env)
    obs_desc = from_gymnasium(raw[0].observation_space)
    act_desc = from_gymnasium(raw[0].action_space)
    spec = getattr(raw[0], "spec", None)
    limit = config.max_episode_steps or getattr(spec, "max_episode_steps", None)
    return [HostedEnv(e, obs_desc, act_desc) for e in raw], obs_desc, act_desc, limit


def serve(job_json: str) -> int:
    # The ready line goes to the original stdout; everything printed later goes to stderr.
    reply_fd = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    job = json.loads(job_json)
    try:
        envs, obs_desc, act_desc, limit = make_envs(job)
    except Exception as e:  # noqa: BLE001 - reported to the client, with the traceback
        detail = "".join(traceback.format_exception(e)).rstrip()
        message = f"cannot make `{job.get('env_id')}` with adapter `{job.get('adapter')}`: {e}\n{detail}"
        os.write(reply_fd, (json.dumps({"error": message}) + "\n").encode())
        return 0
    _envhub.serve_worker(job_json, json.dumps(obs_desc), json.dumps(act_desc), limit, envs, reply_fd)
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m envhub.worker", description="envhub Python worker")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("describe", help="print the adapters this interpreter hosts, as JSON")
    s = sub.add_parser("serve", help="serve a job (JSON) over shared memory")
    s.add_argument("--job", required=True)
    args = parser.parse_args(argv)
    if args.command == "describe":
        print(json.dumps(describe()))
        return 0
    return serve(args.job)


if __name__ == "__main__":
    sys.exit(main())
