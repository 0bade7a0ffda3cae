"""`make`, `make_vec` and RoboSmith's `make_env`."""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium
from gymnasium.vector import AutoresetMode

from .env import Env
from .registry import NAMESPACE, EnvEntry
from .session import HubsArg, RegistryArg
from .vector import VectorEnv

__all__ = ["make", "make_env", "make_vec"]


def _with_spec(env: Env, registry_id: str, kwargs: dict[str, Any]) -> Env:
    """Gives `env` the spec `gymnasium.make` would, so tools that re-create envs from
    `env.spec` (such as `check_env`) work."""
    try:
        spec = gymnasium.spec(f"{NAMESPACE}/{registry_id}")
    except gymnasium.error.Error:
        return env
    env.spec = dataclasses.replace(spec, kwargs={**spec.kwargs, **kwargs})
    return env


def make(
    id: str,
    *,
    render_mode: str | None = None,
    max_episode_steps: int | None = None,
    seed: int | None = None,
    asset_path: str | None = None,
    registry: RegistryArg = None,
    step_timeout: float | None = None,
    restart_on_crash: bool = False,
    strict_actions: bool = False,
    **extra: Any,
) -> Env:
    """One env of registry entry `id` in its own worker process (a `gymnasium.Env`).

    `extra` holds the env's own options (merged over the entry's `kwargs`); `registry` a
    registry (or YAML path) to use instead of the one found the usual way. Continuous actions
    outside the action space's bounds reach the env as in Gymnasium; `strict_actions=True`
    refuses them (NaN and infinite actions are refused either way).
    """
    env = Env(
        id,
        render_mode=render_mode,
        max_episode_steps=max_episode_steps,
        seed=seed,
        asset_path=asset_path,
        registry=registry,
        step_timeout=step_timeout,
        restart_on_crash=restart_on_crash,
        strict_actions=strict_actions,
        **extra,
    )
    if registry is None:
        given = {
            "render_mode": render_mode,
            "max_episode_steps": max_episode_steps,
            "seed": seed,
            "asset_path": asset_path,
            "step_timeout": step_timeout,
        }
        kwargs = {k: v for k, v in given.items() if v is not None}
        if restart_on_crash:
            kwargs["restart_on_crash"] = True
        if strict_actions:
            kwargs["strict_actions"] = True
        _with_spec(env, id, {**kwargs, **extra})
    return env


def make_vec(
    id: str,
    num_envs: int,
    num_workers: int | None = None,
    autoreset_mode: str | AutoresetMode = "next_step",
    *,
    render_mode: str | None = None,
    max_episode_steps: int | None = None,
    seed: int | None = None,
    asset_path: str | None = None,
    registry: RegistryArg = None,
    step_timeout: float | None = None,
    restart_on_crash: bool = False,
    pool_bytes: int | None = None,
    strict_actions: bool = False,
    hubs: HubsArg = None,
    batch_size: int | None = None,
    remote_lanes: int = 1,
    **extra: Any,
) -> VectorEnv:
    """`num_envs` envs of registry entry `id` over `num_workers` worker processes (a
    `gymnasium.vector.VectorEnv`; default: one worker per core, at most one per env).
    `pool_bytes` caps the shared memory that results kept alive by arrays may hold (512 MiB
    by default); past it, results are copies. `strict_actions=True` refuses continuous
    actions outside the action space's bounds.

    `hubs` places the envs on other machines' hubs (`envhub serve`, reached as
    `envhub.yaml`'s `zenoh:` and `ENVHUB_CONNECT` say): `"all"` live hubs, a list of names
    (`"local"` is this machine; envs spread in proportion to cores) or a dict of counts
    (`{"box1": 48, "local": 16}`). `num_workers` then applies per machine.

    `batch_size` gives EnvPool's asynchronous contract: after `async_reset()`, `recv()`
    returns exactly `batch_size` envs, the first to finish (`info["env_id"]`), and
    `send(actions, env_id)` steps them again.

    `remote_lanes` opens each remote hub's slice as that many sessions, each taking requests
    of its own, so that with `send`/`recv` one steps while another's results travel (at most
    one per env, and per worker when `num_workers` is given; default 1)."""
    return VectorEnv(
        id,
        num_envs,
        num_workers,
        autoreset_mode,
        render_mode=render_mode,
        max_episode_steps=max_episode_steps,
        seed=seed,
        asset_path=asset_path,
        registry=registry,
        step_timeout=step_timeout,
        restart_on_crash=restart_on_crash,
        pool_bytes=pool_bytes,
        strict_actions=strict_actions,
        hubs=hubs,
        batch_size=batch_size,
        remote_lanes=remote_lanes,
        **extra,
    )


def make_env(
    entry: EnvEntry | str,
    render_mode: str | None = None,
    max_episode_steps: int | None = None,
    seed: int | None = None,
    **extra: Any,
) -> Env:
    """RoboSmith's `make_env`: an env for a registry entry (or id), from the registry the
    entry came from. `seed` seeds the first reset; `max_episode_steps` 0 or `None` keeps
    the entry's limit; `extra` holds the env's options."""
    registry_id = entry.id if isinstance(entry, EnvEntry) else entry
    registry = entry._registry if isinstance(entry, EnvEntry) else None
    return Env(
        registry_id,
        render_mode=render_mode,
        max_episode_steps=max_episode_steps,
        seed=seed,
        registry=registry,
        **extra,
    )
