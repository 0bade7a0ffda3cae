"""Gymnasium ids for the registry: `gymnasium.make("envhub/<id>")` and
`gymnasium.make_vec("envhub/<id>", num_envs)` work once `envhub` is imported."""

from __future__ import annotations

import gymnasium

from .registry import EnvRegistry

__all__ = ["NAMESPACE", "register_envs"]

NAMESPACE = "envhub"


def register_envs(registry: EnvRegistry | None = None) -> list[str]:
    """Registers `envhub/<id>` with Gymnasium for every entry of `registry` (default: the
    one found the usual way) and returns the Gymnasium ids. Ids already registered keep
    their registration. The episode limit is applied by the worker, so the specs carry no
    `max_episode_steps` (Gymnasium would add a second `TimeLimit`)."""
    registry = registry if registry is not None else EnvRegistry()
    ids = []
    for entry in registry:
        gym_id = f"{NAMESPACE}/{entry.id}"
        if gym_id not in gymnasium.registry:
            try:
                gymnasium.register(
                    id=gym_id,
                    entry_point="envhub.env:Env",
                    vector_entry_point="envhub.vector:VectorEnv",
                    kwargs={"registry_id": entry.id},
                )
            except gymnasium.error.Error:
                continue  # an id Gymnasium cannot parse; envhub.make still works
        ids.append(gym_id)
    return ids
