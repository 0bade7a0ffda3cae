"""Starting a session of envs (shared by `Env` and `VectorEnv`)."""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from typing import Any

from .. import _envhub
from ..wire.config import EnvConfig
from ..wire.errors import InvalidConfigError
from .registry import EnvRegistry

RegistryArg = EnvRegistry | _envhub.Registry | str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None


def registry_of(registry: RegistryArg) -> Any:
    """The compiled registry for a `registry=` argument (`None`: found the usual way)."""
    if registry is None:
        return None
    if isinstance(registry, EnvRegistry):
        return registry._inner
    if isinstance(registry, _envhub.Registry):
        return registry
    return EnvRegistry(registry)._inner


def start(
    registry_id: str,
    config: EnvConfig,
    registry: RegistryArg,
    step_timeout: float | None,
    restart_on_crash: bool,
    pool_bytes: int | None = None,
    adapter: str | None = None,
    hubs: HubsArg = None,
    info_row_bytes: int = 0,
    remote_lanes: int = 1,
) -> Any:
    """Starts the workers of `config.num_envs` envs of entry `registry_id` (with `adapter`:
    of that adapter's env id `registry_id`, no registry involved). `info_row_bytes`: typed
    info columns of that many bytes per env in the batch slots (`envhub._info_columns`).
    `remote_lanes`: sessions each remote hub's slice is opened as (see `make_vec`)."""
    if not isinstance(registry_id, str):
        raise InvalidConfigError(f"the env id must be a string, got {type(registry_id).__name__}")
    if isinstance(config.num_envs, bool) or not isinstance(config.num_envs, int) or config.num_envs < 1:
        raise InvalidConfigError(f"invalid num_envs: {config.num_envs!r}; use a positive integer")
    config.seed = check_seed(config.seed)
    return _envhub.make_session(
        registry_id,
        config.num_envs,
        config.to_json(),
        registry=registry_of(registry),
        step_timeout=step_timeout,
        restart_on_crash=restart_on_crash,
        pool_bytes=pool_bytes,
        adapter=adapter,
        hubs=placement(hubs),
        info_row_bytes=info_row_bytes,
        remote_lanes=remote_lanes,
    )


HubsArg = str | Sequence[str] | Mapping[str, int] | None


def placement(hubs: HubsArg) -> str | None:
    """A `hubs=` argument as the placement string the hub parses: `None`/`"local"` (this
    machine), `"all"` (every live hub), names (`["box1", "box2", "local"]`: spread by cores)
    or counts (`{"box1": 48, "local": 16}`)."""
    if hubs is None or isinstance(hubs, str):
        return hubs
    if isinstance(hubs, Mapping):
        for name, count in hubs.items():
            if not isinstance(name, str) or isinstance(count, bool) or not isinstance(count, int) or count < 0:
                raise InvalidConfigError(
                    f"invalid hubs entry {name!r}: {count!r}; map hub names to env counts, e.g. {{'box1': 48, 'local': 16}}"
                )
        return ",".join(f"{name}:{count}" for name, count in hubs.items())
    names = list(hubs)
    if not names or not all(isinstance(n, str) for n in names):
        raise InvalidConfigError(
            f"invalid hubs: {hubs!r}; use 'local', 'all', a list of hub names, or a dict of hub names to env counts"
        )
    return ",".join(names)


def check_seed(seed: Any) -> int | None:
    """A reset seed: `None` or a non-negative integer (numpy integers too)."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not hasattr(seed, "__index__") or seed.__index__() < 0:
        raise InvalidConfigError(f"invalid seed: {seed!r}; use a non-negative integer or None")
    return int(seed.__index__())


def fps_metadata(session: Any) -> dict[str, Any]:
    """`{"render_fps": n}` for a session whose env declares its frame rate (Gymnasium's
    `metadata["render_fps"]`, an int where it is whole, as Gymnasium's envs give it), else
    `{}`."""
    fps = session.render_fps
    if fps is None:
        return {}
    return {"render_fps": int(fps) if float(fps).is_integer() else float(fps)}
