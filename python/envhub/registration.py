"""Gymnasium ids for the registry: `gymnasium.make("envhub/<id>")` and
`gymnasium.make_vec("envhub/<id>", num_envs)` work once `envhub` is imported. It imports the
registry and Gymnasium only (the package root runs it, in workers too); the entry points name
the client classes, which Gymnasium imports when an id is made."""

from __future__ import annotations

from typing import Any

import gymnasium

from .client.registry import NAMESPACE, EnvEntry, EnvRegistry

__all__ = ["NAMESPACE", "register_envs"]


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
                    entry_point="envhub.client.env:TimeLimitedByGymnasium"
                    if limited
                    else "envhub.client.env:Env",
                    vector_entry_point="envhub.client.vector:VectorEnv",
                    kwargs={"registry_id": entry.id},
                    **fields,
                )
            except gymnasium.error.Error:
                continue  # an id Gymnasium cannot parse; envhub.make still works
        ids.append(gym_id)
    return ids
