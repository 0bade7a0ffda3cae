"""`gymnasium` (alias `gym`): any registered Gymnasium id, Gymnasium-Robotics included."""

from __future__ import annotations

from typing import Any

from .base import EnvAdapter, missing_modules


class GymnasiumAdapter(EnvAdapter):
    """Any id in Gymnasium's registry, made with the entry's `kwargs` (config `extra`),
    `render_mode` and `max_episode_steps` (0 or None: the env's own default). Ids not in the
    registry are looked up again after registering Gymnasium-Robotics, when it is installed."""

    name = "gymnasium"
    frameworks = ["gymnasium"]
    requires = ["gymnasium"]
    description = "any registered Gymnasium env (Gymnasium-Robotics too), hosted in a Python worker"
    install_hint = "pip install 'gymnasium[all]' gymnasium-robotics"

    def make(self, env_id: str, config: Any) -> Any:
        import gymnasium as gym

        if env_id not in gym.registry and not missing_modules(["gymnasium_robotics"]):
            import gymnasium_robotics

            gym.register_envs(gymnasium_robotics)
        if env_id not in gym.registry:
            from difflib import get_close_matches

            close = get_close_matches(env_id, list(gym.registry), n=3)
            robotics = "" if not missing_modules(["gymnasium_robotics"]) else "; `gymnasium_robotics` is not installed"
            raise LookupError(
                f"Gymnasium has no env `{env_id}`{robotics}"
                + (f"; did you mean {' or '.join(f'`{c}`' for c in close)}?" if close else "")
                + "\nhint: `python -c 'import gymnasium; gymnasium.pprint_registry()'` lists the ids"
            )
        if _from_robotics(gym.registry[env_id]):
            from . import robotics_compat

            robotics_compat.apply()
        kwargs = dict(config.extra)
        limit = config.max_episode_steps or None  # 0 and None both mean the env's default
        return gym.make(env_id, render_mode=config.render_mode, max_episode_steps=limit, **kwargs)


    def make_vec(self, env_id: str, config: Any) -> Any:
        """With `vectorization_mode: vector_entry_point` in the entry's `kwargs`: the id's own
        vector env (`gymnasium.make_vec(..., vectorization_mode="vector_entry_point")`, e.g.
        `CartPoleVectorEnv`) holding all of the worker's envs; else None (one `make` per env)."""
        if "vectorization_mode" not in config.extra:
            return None
        kwargs = dict(config.extra)
        mode = kwargs.pop("vectorization_mode")
        if mode != VECTOR_ENTRY_POINT:
            raise ValueError(
                f"invalid `vectorization_mode` {mode!r} for `{env_id}`; the only valid value is "
                f"`{VECTOR_ENTRY_POINT}` (the id's own vector env serves all of a worker's envs; "
                "`sync`/`async` are what the worker does anyway with one env per instance)\n"
                f"hint: set `vectorization_mode: {VECTOR_ENTRY_POINT}` in the entry's kwargs, or remove it"
            )
        import gymnasium as gym

        spec = gym.registry.get(env_id)
        if spec is None or spec.vector_entry_point is None:
            with_entry = sorted(
                i for i, s in gym.registry.items() if s.vector_entry_point is not None and s.namespace != "envhub"
            )
            raise LookupError(
                f"`{env_id}` has no vector entry point in Gymnasium's registry, so "
                f"`vectorization_mode: {VECTOR_ENTRY_POINT}` cannot apply\n"
                f"hint: ids with one: {', '.join(with_entry)}; or remove `vectorization_mode` from the "
                "entry's kwargs to host one env per instance"
            )
        # Passed only when set: a vector entry point need not take them.
        if config.render_mode is not None:
            kwargs["render_mode"] = config.render_mode
        if config.max_episode_steps:
            kwargs["max_episode_steps"] = config.max_episode_steps
        return gym.make_vec(env_id, num_envs=config.num_envs, vectorization_mode=VECTOR_ENTRY_POINT, **kwargs)


#: The `vectorization_mode` (entry `kwargs`) that makes `GymnasiumAdapter.make_vec` serve the
#: id's own vector env.
VECTOR_ENTRY_POINT = "vector_entry_point"


def _from_robotics(spec: Any) -> bool:
    entry = spec.entry_point
    module = entry if isinstance(entry, str) else getattr(entry, "__module__", "")
    return module.startswith("gymnasium_robotics")
