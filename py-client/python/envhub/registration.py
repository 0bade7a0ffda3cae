"""Gymnasium ids for the registry: `gymnasium.make("envhub/<id>")` and
`gymnasium.make_vec("envhub/<id>", num_envs)` work once `envhub` is imported."""

from __future__ import annotations

from typing import Any

import gymnasium

from .env import Env
from .registry import EnvEntry, EnvRegistry

__all__ = ["NAMESPACE", "register_envs"]

NAMESPACE = "envhub"

# The largest limit a worker takes (`max_episode_steps` is a u32): in effect none, for envs
# whose limit Gymnasium's `TimeLimit` applies instead.
_NO_LIMIT = 2**32 - 1


class _TimeLimitedByGymnasium(Env):
    """`Env` as `gymnasium.make` creates it for a spec with `max_episode_steps`: `make` wraps
    it in `TimeLimit` (the spec's limit, or the one passed to `make`, or none with -1), so
    the worker applies no limit of its own and episodes truncate exactly once, where
    Gymnasium's own env would."""

    def __init__(self, registry_id: str, **kwargs: Any) -> None:
        kwargs.setdefault("max_episode_steps", _NO_LIMIT)
        super().__init__(registry_id, **kwargs)


def _spec_fields(entry: EnvEntry) -> dict[str, Any]:
    """The spec fields known without starting a worker: the entry's `max_episode_steps`, else
    the env's own default. For a Gymnasium env id that default, and `reward_threshold` and
    `nondeterministic`, are those Gymnasium registers for it: the native adapters implement
    those ids with Gymnasium's limits, and the Gymnasium-hosted adapter runs them through
    `gymnasium.make`. Other frameworks' defaults are known only to their worker, so their
    specs carry only what the entry says."""
    fields: dict[str, Any] = {}
    if entry.framework.lower() in ("gymnasium", "gym"):
        native = gymnasium.registry.get(entry.env_id)
        if native is not None:
            fields = {
                "max_episode_steps": native.max_episode_steps,
                "reward_threshold": native.reward_threshold,
                "nondeterministic": native.nondeterministic,
            }
    if entry.max_episode_steps:
        fields["max_episode_steps"] = entry.max_episode_steps
    return fields


def register_envs(registry: EnvRegistry | None = None) -> list[str]:
    """Registers `envhub/<id>` with Gymnasium for every entry of `registry` (default: the
    one found the usual way) and returns the Gymnasium ids. Ids already registered keep
    their registration. A spec carries `max_episode_steps` where envhub knows the limit
    (see `_spec_fields`); then `gymnasium.make` applies it with `TimeLimit` and the worker
    applies none, while `gymnasium.make_vec` passes it to the worker."""
    registry = registry if registry is not None else EnvRegistry()
    ids = []
    for entry in registry:
        gym_id = f"{NAMESPACE}/{entry.id}"
        if gym_id not in gymnasium.registry:
            fields = _spec_fields(entry)
            limited = fields.get("max_episode_steps") is not None
            try:
                gymnasium.register(
                    id=gym_id,
                    entry_point=f"envhub.registration:{_TimeLimitedByGymnasium.__name__}"
                    if limited
                    else "envhub.env:Env",
                    vector_entry_point="envhub.vector:VectorEnv",
                    kwargs={"registry_id": entry.id},
                    **fields,
                )
            except gymnasium.error.Error:
                continue  # an id Gymnasium cannot parse; envhub.make still works
        ids.append(gym_id)
    return ids
