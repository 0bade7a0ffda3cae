"""`isaac_lab` (aliases `isaaclab`, `isaac_gym`): Isaac Lab tasks; needs an NVIDIA GPU."""

from __future__ import annotations

import shutil
from typing import Any

import numpy as np

from .base import EnvAdapter, missing_modules
from .torch_to_numpy import to_numpy


def _gpu() -> str | None:
    """Why no usable NVIDIA GPU is visible, or None when one is."""
    if shutil.which("nvidia-smi") is None and not _has_device_file():
        return "no NVIDIA GPU (no `nvidia-smi`, no /dev/nvidia0)"
    return None


def _has_device_file() -> bool:
    import os

    return os.path.exists("/dev/nvidia0")


class IsaacLabAdapter(EnvAdapter):
    """Isaac Lab tasks (`Isaac-Cartpole-v0`, ...). Available only with Isaac Lab and an
    NVIDIA GPU. Isaac Lab is vectorised inside the simulator: one simulator per worker holds
    all of the worker's envs (`make_vec`, with the session's `num_envs`)."""

    name = "isaac_lab"
    frameworks = ["isaac_lab"]
    requires = ["isaaclab", "torch"]
    description = "Isaac Lab tasks on the GPU (needs Isaac Sim), hosted in a Python worker"
    install_hint = "pip install 'isaaclab[isaacsim,all]' --extra-index-url https://pypi.nvidia.com  (needs an NVIDIA GPU and driver)"

    def availability(self) -> tuple[bool, str | None, str | None]:
        ok, reason, hint = super().availability()
        if not ok:
            return ok, reason, hint
        gpu = _gpu()
        if gpu is not None:
            return False, gpu, "run on a machine with an NVIDIA GPU and driver"
        return True, None, None

    def make_vec(self, env_id: str, config: Any) -> Any:
        if missing_modules(["isaaclab"]):
            raise ImportError("Isaac Lab is not installed")
        extra = dict(config.extra)
        asked = extra.pop("num_envs", None)
        if asked is not None and int(asked) != config.num_envs:
            raise ValueError(
                f"`{env_id}`: `num_envs: {asked}` in the entry's kwargs differs from this worker's "
                f"{config.num_envs} envs\nhint: set the count on the session (`make_vec(id, num_envs=...)`); "
                "each worker's simulator holds its share"
            )
        if config.max_episode_steps:
            raise ValueError(
                f"`{env_id}`: Isaac Lab sets the episode length in its env cfg (`episode_length_s`), "
                "not with `max_episode_steps`\nhint: leave `max_episode_steps` unset"
            )
        from isaaclab.app import AppLauncher

        AppLauncher(headless=True)
        import gymnasium as gym
        import isaaclab_tasks  # noqa: F401 - registers the Isaac ids
        from isaaclab_tasks.utils import parse_env_cfg

        cfg = parse_env_cfg(env_id, num_envs=config.num_envs)
        return IsaacLabVectorEnv(gym.make(env_id, cfg=cfg, render_mode=config.render_mode, **extra))


class IsaacLabVectorEnv:
    """An Isaac Lab env as a Gymnasium `VectorEnv` over numpy: actions go to the simulator's
    device as torch tensors; observations, rewards, flags and info come back as numpy arrays
    with the leading `num_envs` axis (never squeezed).

    Isaac Lab resets finished envs inside `step` and returns the new episode's first
    observation without the last one: same-step autoreset without `final_obs`. It says so in
    `metadata`, so the worker refuses next_step and disabled sessions rather than misreport
    episodes; same_step sessions get no final observations (final mask 0)."""

    def __init__(self, env: Any) -> None:
        from gymnasium.vector import AutoresetMode

        self.env = env
        unwrapped = env.unwrapped
        self.num_envs = int(unwrapped.num_envs)
        self.device = unwrapped.device
        self.single_observation_space = unwrapped.single_observation_space
        self.single_action_space = unwrapped.single_action_space
        self.spec = getattr(env, "spec", None)
        self.metadata = {**getattr(env, "metadata", {}), "autoreset_mode": AutoresetMode.SAME_STEP}

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict[str, Any] | None = None) -> Any:
        if isinstance(seed, list):
            raise ValueError("Isaac Lab seeds its whole simulation with one int seed")
        if options and "reset_mask" in options:
            raise ValueError("Isaac Lab resets its envs itself; it takes no `reset_mask`")
        obs, info = self.env.reset(seed=seed, options=options)
        return to_numpy(obs, False), to_numpy(info, False)

    def step(self, actions: Any) -> Any:
        import torch

        # A writable copy: torch does not take read-only arrays (the request's view is one).
        act = torch.from_numpy(np.array(actions)).to(self.device)
        obs, reward, terminated, truncated, info = self.env.step(act)
        return tuple(to_numpy(v, False) for v in (obs, reward, terminated, truncated, info))

    def render(self) -> Any:
        # One viewport of the whole scene, not one frame per env: it comes back as env 0's.
        frame = self.env.render()
        return None if frame is None else (to_numpy(frame, False),) + (None,) * (self.num_envs - 1)

    def close(self) -> None:
        self.env.close()
