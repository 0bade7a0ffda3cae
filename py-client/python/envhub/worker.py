"""The Python worker: `python -m envhub.worker describe | serve --job JSON`.

Started by the hub for Python-hosted adapters (see `envhub.hosted`). `describe` prints the
adapters this interpreter can host, as JSON; `serve` creates a job's envs here and hands
them to the Rust serve loop in `envhub._envhub.serve_worker`, which speaks the same
shared-memory protocol as the Rust `envhub-worker`: each env gets its own copy of its action
(the request sample is reused by the next request, and an env may keep its action), each
observation is copied once into the response sample.

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

import numpy as np

from . import _envhub
from ._batched import env_value as _env_value
from ._pickled import Encoded
from ._spaces import _Leaf, _tree, from_gymnasium
from .config import EnvConfig
from .hosted import all_adapters


def _space_tree(desc: dict[str, Any]) -> Any:
    return _tree(desc, json.loads(_envhub.space_leaves_json(json.dumps(desc))))


def _write(node: Any, value: Any, buf: np.ndarray) -> None:
    """Copies `value` into the bytes `buf` (last axis: one value's bytes; any leading axes,
    such as a batch of envs, are kept), leaf by leaf."""
    if isinstance(node, _Leaf):
        dst = buf[..., node.offset : node.offset + node.nbytes].view(node.dtype).reshape(buf.shape[:-1] + node.shape)
        dst[...] = value
        return
    kind, children = node
    if kind == "dict":
        for key, child in children:
            _write(child, value[key], buf)
    else:
        for i, child in enumerate(children):
            _write(child, value[i], buf)


def _read(node: Any, buf: np.ndarray) -> Any:
    """The value in the bytes `buf` (shaped as for `_write`), as numpy views of them."""
    if isinstance(node, _Leaf):
        return buf[..., node.offset : node.offset + node.nbytes].view(node.dtype).reshape(buf.shape[:-1] + node.shape)
    kind, children = node
    if kind == "dict":
        return {key: _read(child, buf) for key, child in children}
    return tuple(_read(child, buf) for child in children)


def _whole(node: Any) -> _Leaf | None:
    """The leaf when a space is one array at offset 0, else None."""
    return node if isinstance(node, _Leaf) and node.offset == 0 else None


def _rgb(frame: Any) -> tuple[int, int, bytes] | None:
    if frame is None:
        return None
    a = np.ascontiguousarray(frame, dtype=np.uint8)
    return int(a.shape[0]), int(a.shape[1]), a[..., :3].tobytes()


class HostedEnv:
    """One env, as `serve_worker` drives it: results are written into the slots it gives."""

    def __init__(self, env: Any, obs_desc: dict[str, Any], act_desc: dict[str, Any]) -> None:
        self.env = env
        self.obs_tree = _space_tree(obs_desc)
        self.act_tree = _space_tree(act_desc)
        # One array leaf (most spaces): its bytes are viewed in one step, not walked.
        self.obs_leaf = _whole(self.obs_tree)
        self.act_leaf = _whole(self.act_tree)

    def _write_obs(self, obs: Any, out: memoryview) -> None:
        leaf = self.obs_leaf
        if leaf is None:
            _write(self.obs_tree, obs, np.frombuffer(out, dtype=np.uint8))
        else:
            np.frombuffer(out, dtype=leaf.dtype, count=leaf.nbytes // leaf.dtype.itemsize).reshape(leaf.shape)[...] = obs

    def reset_into(self, seed: int | None, options: str | None, out: memoryview) -> Encoded | str | None:
        obs, info = self.env.reset(seed=seed, options=json.loads(options) if options else None)
        self._write_obs(obs, out)
        return _info_out(info)

    def step_into(self, action: memoryview, out: memoryview) -> tuple[float, bool, bool, Encoded | str | None]:
        # A copy the env owns: `action` views the request sample, which the next request
        # overwrites, and envs may keep their action ("previous action" features).
        leaf = self.act_leaf
        if leaf is None:
            act = _read(self.act_tree, np.frombuffer(action, dtype=np.uint8).copy())
        else:
            act = np.frombuffer(action, dtype=leaf.dtype, count=leaf.nbytes // leaf.dtype.itemsize).reshape(leaf.shape).copy()
        obs, reward, terminated, truncated, info = self.env.step(act)
        self._write_obs(obs, out)
        return float(reward), bool(terminated), bool(truncated), _info_out(info)

    def render_rgb(self) -> tuple[int, int, bytes] | None:
        return _rgb(self.env.render())

    def close(self) -> None:
        self.env.close()


class HostedVectorEnv:
    """A vector env (Gymnasium 1.x `VectorEnv` contract) holding all of a worker's envs, as
    `serve_vector_worker` drives it. It steps every env at once and autoresets them itself, so
    it is served only under the autoreset mode it declares. Each result is copied once, for
    the whole batch, into the response block it is given; actions are a copy of the request
    block that the vector env owns."""

    def __init__(self, env: Any, env_id: str, obs_desc: dict[str, Any], act_desc: dict[str, Any]) -> None:
        self.env = env
        self.env_id = env_id
        self.num_envs = int(env.num_envs)
        self.obs_tree = _space_tree(obs_desc)
        self.act_tree = _space_tree(act_desc)

    def _rows(self, block: memoryview) -> np.ndarray:
        """A block as `[num_envs, bytes of one env's value]`."""
        return np.frombuffer(block, dtype=np.uint8).reshape(self.num_envs, -1)

    def reset_into(
        self, selected: list[bool], seeds: list[int | None], options: str | None, obs: memoryview
    ) -> str | None:
        mask = np.asarray(selected, dtype=np.bool_)
        if not mask.any():
            return None  # the session reset only other workers' envs
        opts = json.loads(options) if options else {}
        partial = not mask.all()
        if partial:
            opts["reset_mask"] = mask  # Gymnasium 1.x: reset only these envs
        seed = _vector_seed(seeds, mask)
        try:
            values, info = self.env.reset(seed=seed, options=opts or None)
        except Exception as e:
            if partial:
                raise RuntimeError(
                    f"`{self.env_id}`'s vector env cannot reset some of its envs alone: it rejected "
                    f"`options['reset_mask']` ({type(e).__name__}: {e})\n"
                    "hint: reset every env at once (no `reset_mask`)"
                ) from e
            if isinstance(seed, list):
                raise RuntimeError(
                    f"`{self.env_id}`'s vector env rejected per-env seeds {seed} ({type(e).__name__}: {e})\n"
                    "hint: reset with one int seed (env i gets seed + i, as Gymnasium does) or none"
                ) from e
            raise
        if partial and "reset_mask" in opts:
            # Gymnasium's vector envs take the mask out of the options; this one did not look.
            raise RuntimeError(
                f"`{self.env_id}`'s vector env ignored `options['reset_mask']` and reset all its "
                f"{self.num_envs} envs: it cannot reset some of them alone\n"
                "hint: reset every env at once (no `reset_mask`)"
            )
        _write(self.obs_tree, values, self._rows(obs))
        return vector_info_json(info, self.num_envs)

    def step_into(
        self,
        actions: memoryview,
        obs: memoryview,
        rewards: memoryview,
        terminated: memoryview,
        truncated: memoryview,
        final_obs: memoryview | None,
        final_mask: memoryview,
    ) -> str | None:
        # One copy of the batch's actions per step, which the vector env owns (as for `HostedEnv`).
        values, reward, term, trunc, info = self.env.step(_read(self.act_tree, self._rows(actions).copy()))
        _write(self.obs_tree, values, self._rows(obs))
        np.frombuffer(rewards, dtype=np.float64)[:] = reward
        np.frombuffer(terminated, dtype=np.uint8)[:] = term
        np.frombuffer(truncated, dtype=np.uint8)[:] = trunc
        info = dict(info or {})
        finals, has_final = info.pop("final_obs", None), info.pop("_final_obs", None)
        if final_obs is not None and finals is not None and has_final is not None:
            # same_step: the episode's last observation of each env that finished (absent
            # when the simulator does not report it: that env's final mask stays 0).
            rows, flags = self._rows(final_obs), np.frombuffer(final_mask, dtype=np.uint8)
            for i in np.flatnonzero(has_final):
                _write(self.obs_tree, _env_value(finals, int(i)), rows[i])
                flags[i] = 1
        return vector_info_json(info, self.num_envs)

    def render_rgb(self, selected: list[bool]) -> list[tuple[int, int, bytes] | None]:
        frames = self.env.render()
        return [_rgb(None if frames is None else frames[i]) for i, s in enumerate(selected) if s]

    def close(self) -> None:
        self.env.close()


def _vector_seed(seeds: list[int | None], mask: np.ndarray) -> int | list[int | None] | None:
    """The `seed` argument of a vector env's reset: None when no env is seeded, one int when
    the envs get `s, s + 1, ...` (what an int seed means to Gymnasium's vector envs, and what
    `envhub`'s `reset(seed=s)` sends), else one seed (or None) per env."""
    chosen = [s if m else None for s, m in zip(seeds, mask, strict=True)]
    if all(s is None for s in chosen):
        return None
    first = chosen[0]
    if first is not None and chosen == [first + i for i in range(len(chosen))]:
        return first
    return chosen


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


def _info_out(info: dict[str, Any] | None) -> Encoded | str | None:
    """An env's info as `serve_worker` reads it: the drop-in's already plain dict as it is
    (read value by value in Rust, no text), else `info_json`."""
    if type(info) is Encoded:
        return info or None
    return info_json(info)


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


def _env_infos(info: dict[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium's batched vector info (`key`: a value per env, `_key`: which envs have it;
    nested dicts alike) as one info dict per env. Values without a leading axis of `n`
    describe the whole batch, not an env, and are left out."""
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, value in info.items():
        key = str(key)
        if key.startswith("_") and key[1:] in info:
            continue
        mask = info.get(f"_{key}")
        if isinstance(value, dict):
            for i, sub in enumerate(_env_infos(value, n)):
                if sub and (mask is None or mask[i]):
                    out[i][key] = sub
            continue
        if isinstance(value, np.ndarray):
            batched = value.ndim > 0 and value.shape[0] == n
        else:
            batched = isinstance(value, (list, tuple)) and len(value) == n
        if not batched:
            continue
        for i in range(n):
            if mask is None or mask[i]:
                v = _info_value(value[i])
                if v is not None:
                    out[i][key] = v
    return out


def vector_info_json(info: dict[str, Any] | None, n: int) -> str | None:
    """A vector env's info as the info section (`[{...}, ...]`, one object per env, with
    what `info_json` keeps), or None when no env has any."""
    if not info:
        return None
    per_env = _env_infos(info, n)
    return json.dumps(per_env) if any(per_env) else None


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
    from .vector import _RUST_MODES, _autoreset_mode

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
    fps = (getattr(env, "metadata", None) or {}).get("render_fps")
    try:
        fps = float(fps)
    except (TypeError, ValueError):
        return None
    return fps if math.isfinite(fps) and fps > 0 else None


def serve(job_json: str) -> int:
    # The ready line goes to the original stdout; everything printed later goes to stderr.
    reply_fd = os.dup(1)
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    job = json.loads(job_json)
    try:
        batch, obs_desc, act_desc, limit = make_batch(job)
    except Exception as e:
        detail = "".join(traceback.format_exception(e)).rstrip()
        message = f"cannot make `{job.get('env_id')}` with adapter `{job.get('adapter')}`: {e}\n{detail}"
        os.write(reply_fd, (json.dumps({"error": message}) + "\n").encode())
        return 0
    spaces = (json.dumps(obs_desc), json.dumps(act_desc))
    if isinstance(batch, HostedVectorEnv):
        fps = render_fps(batch.env)
        _envhub.serve_vector_worker(job_json, *spaces, limit, batch, reply_fd, render_fps=fps)
    else:
        fps = render_fps(batch[0].env)
        _envhub.serve_worker(job_json, *spaces, limit, batch, reply_fd, render_fps=fps)
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
