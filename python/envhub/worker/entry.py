"""The Python worker: `python -m envhub.worker describe | serve --job JSON`.

Started by the hub for Python-hosted adapters (see `envhub.worker.hosted`). `describe` prints the
adapters this interpreter can host, as JSON; `serve` creates a job's envs here and hands
them, as one `HostedBatch`, to the Rust serve loop in `envhub._envhub.serve_worker`, which
speaks the same shared-memory protocol as the Rust `envhub-worker` and calls into Python
once per request for the whole batch. The batch's actions are copied once per step into an
array the envs own (the request sample is reused by the next request, and an env may keep
its action); each env gets a view of its row. Each observation is copied once, into its row
of the batch slot; the drop-in's infos go into typed columns of the slot where they fit
(`envhub._info_columns`).

An adapter whose `make_vec` returns a vector env (one object stepping all of the worker's
envs, as Isaac Lab and Gymnasium's `vector_entry_point` envs do) is served whole instead,
through `envhub._envhub.serve_vector_worker` and `HostedVectorEnv`.

Anything the envs print goes to stderr: stdout carries only the one ready line.
"""


from __future__ import annotations

import argparse
import json
import math
import os
import sys
import traceback
from typing import Any

from .. import _envhub
from ..wire.config import EnvConfig
from ..wire.spaces import from_gymnasium
from .batch import HostedBatch, HostedEnv, HostedVectorEnv
from .hosted import all_adapters


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


def _vector_autoreset_mode(env: Any, env_id: str, session_mode: str) -> None:
    """Raises unless the vector env declares the session's autoreset mode: it resets its
    envs itself, so the worker cannot serve another mode without misreporting episodes."""
    from ..wire.autoreset import RUST_MODES as _RUST_MODES
    from ..wire.autoreset import autoreset_mode as _autoreset_mode

    declared = (getattr(env, "metadata", None) or {}).get("autoreset_mode")
    if declared is None:
        raise ValueError(
            f"`{env_id}`'s vector env ({type(env).__name__}) declares no `metadata['autoreset_mode']`, "
            "so when it resets finished envs is unknown\nhint: set `metadata['autoreset_mode']` to a "
            "`gymnasium.vector.AutoresetMode` in the vector env (or in its adapter's wrapper)"
        )
    own = _RUST_MODES[_autoreset_mode(declared)]
    if own != session_mode:
        raise ValueError(
            f"`{env_id}`'s vector env autoresets `{own}` (its metadata['autoreset_mode']), but this "
            f"session asks for `{session_mode}`; it resets its envs itself, so the worker cannot change that\n"
            f'hint: make the session with autoreset_mode="{own}", e.g. envhub.make_vec(id, n, autoreset_mode="{own}")'
        )


def make_batch(
    job: dict[str, Any],
) -> tuple[list[HostedEnv] | HostedVectorEnv, dict[str, Any], dict[str, Any], int | None]:
    """Creates a job's envs: the adapter's vector env for all of them when its `make_vec`
    returns one, else one `make` per env. Raises with a message that names the adapter and
    env."""
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
    num_envs = int(job["num_envs"])
    config = EnvConfig(
        render_mode=c.get("render_mode"),
        seed=c.get("seed"),
        max_episode_steps=c.get("max_episode_steps"),
        num_envs=num_envs,
        asset_path=c.get("asset_path"),
        extra=dict(c.get("extra") or {}),
        workers=c.get("workers"),
        autoreset_mode=c.get("autoreset_mode", "next_step"),
        strict_actions=bool(c.get("strict_actions", False)),
    )
    vector = adapter.make_vec(env_id, config)
    if vector is not None:
        try:
            got = int(vector.num_envs)
            if got != num_envs:
                raise ValueError(
                    f"`{name}.make_vec` returned a vector env of {got} envs for a worker of {num_envs}\n"
                    "hint: build it with `num_envs=config.num_envs`"
                )
            _vector_autoreset_mode(vector, env_id, config.autoreset_mode)
            obs_desc = from_gymnasium(vector.single_observation_space)
            act_desc = from_gymnasium(vector.single_action_space)
        except BaseException:
            vector.close()
            raise
        spec = getattr(vector, "spec", None)
        limit = config.max_episode_steps or getattr(spec, "max_episode_steps", None)
        hosted = HostedVectorEnv(vector, env_id, obs_desc, act_desc)
        return hosted, obs_desc, act_desc, limit
    raw = []
    for i in range(num_envs):
        config.env_index = int(job.get("env_offset", 0)) + i
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


def render_fps(env: Any) -> float | None:
    """The env's `metadata["render_fps"]` as a number, or None where it declares none (or
    something that is not a positive number)."""
    fps: Any = (getattr(env, "metadata", None) or {}).get("render_fps")
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        return None
    return fps if math.isfinite(fps) and fps > 0 else None


def serve(job_json: str, reply_fd: int | None = None) -> int:
    """Makes the job's envs and serves them; the one ready (or error) line goes to
    `reply_fd` (default: the original stdout; everything printed later goes to stderr)."""
    if reply_fd is None:
        reply_fd = os.dup(1)
        os.dup2(2, 1)
        sys.stdout = sys.stderr
    job = json.loads(job_json)
    try:
        batch, obs_desc, act_desc, limit = make_batch(job)
    except Exception as e:
        detail = "".join(traceback.format_exception(type(e), e, e.__traceback__)).rstrip()
        message = f"cannot make `{job.get('env_id')}` with adapter `{job.get('adapter')}`: {e}\n{detail}"
        os.write(reply_fd, (json.dumps({"error": message}) + "\n").encode())
        return 0
    spaces = (json.dumps(obs_desc), json.dumps(act_desc))
    if isinstance(batch, HostedVectorEnv):
        fps = render_fps(batch.env)
        _envhub.serve_vector_worker(job_json, *spaces, limit, batch, reply_fd, render_fps=fps)
    else:
        fps = render_fps(batch[0].env)
        mode = (job.get("config") or {}).get("autoreset_mode", "next_step")
        hosted = HostedBatch(batch, mode, int(job.get("info_row_bytes") or 0))
        _envhub.serve_worker(job_json, *spaces, limit, hosted, reply_fd, render_fps=fps)
    return 0


def refusal(hub_protocol: str | None) -> str | None:
    """Why this worker must not serve the hub that started it (which passes its worker protocol
    in `ENVHUB_WORKER_PROTOCOL`): they speak different versions. None when they agree."""
    own = getattr(_envhub, "WORKER_PROTOCOL", None)
    if hub_protocol is None or hub_protocol == str(own):
        return None
    here = os.path.dirname(os.path.abspath(_envhub.__file__ or ""))
    return (
        f"this worker speaks envhub worker protocol {own} (envhub {_envhub.__version__} at `{here}`, "
        f"interpreter `{sys.executable}`), the hub that started it speaks {hub_protocol}; "
        "hint: start hub and worker from one envhub install (a `PYTHONPATH` may lead to another)"
    )


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m envhub.worker", description="envhub Python worker")
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("describe", help="print the adapters this interpreter hosts, as JSON")
    s = sub.add_parser("serve", help="serve a job (JSON) over shared memory")
    s.add_argument("--job", required=True)
    args = parser.parse_args(argv)
    refused = refusal(os.environ.get("ENVHUB_WORKER_PROTOCOL"))
    if refused is not None:
        if args.command == "describe":
            print(f"error: {refused}", file=sys.stderr)
            return 2
        print(json.dumps({"error": refused}), flush=True)
        return 0
    if args.command == "describe":
        print(json.dumps(describe()))
        return 0
    return serve(args.job)


