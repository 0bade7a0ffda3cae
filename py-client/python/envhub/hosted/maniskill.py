"""`maniskill` (aliases `mani_skill`, `sapien`): ManiSkill3 tasks on its CPU simulator."""

from __future__ import annotations

from typing import Any

from .base import EnvAdapter


class ManiSkillAdapter(EnvAdapter):
    """ManiSkill3 tasks (`PickCube-v1`, ...) on the CPU simulator with state observations, one
    env per instance (the worker batches them); the entry's `kwargs` go to `gymnasium.make`."""

    name = "maniskill"
    frameworks = ["maniskill"]
    requires = ["mani_skill", "sapien", "torch"]
    description = "ManiSkill3 tasks on the CPU simulator, state observations"
    install_hint = "pip install mani-skill torch  # then `python -m mani_skill.utils.download_asset <task>` if it asks"

    def make(self, env_id: str, config: Any) -> Any:
        import gymnasium as gym
        import mani_skill.envs  # noqa: F401 - registers the ManiSkill ids

        from .torch_to_numpy import TorchToNumpy

        kwargs = {"obs_mode": "state", "sim_backend": "cpu", "num_envs": 1, **config.extra}
        env = gym.make(
            env_id,
            render_mode=config.render_mode,
            max_episode_steps=config.max_episode_steps or None,
            **kwargs,
        )
        return TorchToNumpy(env)
