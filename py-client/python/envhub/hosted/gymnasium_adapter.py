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


def _from_robotics(spec: Any) -> bool:
    entry = spec.entry_point
    module = entry if isinstance(entry, str) else getattr(entry, "__module__", "")
    return module.startswith("gymnasium_robotics")
