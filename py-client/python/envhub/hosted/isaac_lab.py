"""`isaac_lab` (aliases `isaaclab`, `isaac_gym`): Isaac Lab tasks; needs an NVIDIA GPU."""

from __future__ import annotations

import shutil
from typing import Any

from .base import EnvAdapter, missing_modules


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
    NVIDIA GPU; `num_envs` in `extra` sets the simulator's own vectorisation."""

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

    def make(self, env_id: str, config: Any) -> Any:
        if missing_modules(["isaaclab"]):
            raise ImportError("Isaac Lab is not installed")
        extra = dict(config.extra)
        num_envs = int(extra.pop("num_envs", 1))
        if num_envs != 1:
            raise NotImplementedError(
                f"`{env_id}` with num_envs={num_envs} inside Isaac Lab: the Python worker hosts one env per instance\n"
                "hint: use the session's `num_envs` (workers × envs) instead of `extra.num_envs` for now"
            )
        from isaaclab.app import AppLauncher

        AppLauncher(headless=True)
        import gymnasium as gym
        import isaaclab_tasks  # noqa: F401 - registers the Isaac ids
        from isaaclab_tasks.utils import parse_env_cfg

        from .torch_to_numpy import TorchToNumpy

        cfg = parse_env_cfg(env_id, num_envs=num_envs)
        return TorchToNumpy(gym.make(env_id, cfg=cfg, render_mode=config.render_mode, **extra))
