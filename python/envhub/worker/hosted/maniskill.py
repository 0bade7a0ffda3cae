"""`maniskill` (aliases `mani_skill`, `sapien`): ManiSkill3 tasks on its CPU simulator."""

from __future__ import annotations

import glob
import os
import shutil
from typing import Any

from .base import EnvAdapter

VULKAN_HINT = (
    "SAPIEN (ManiSkill's engine) needs a Vulkan device even for state observations: a GPU driver, or, "
    "without a GPU, a recent Mesa CPU driver, lavapipe (Debian 12: `apt-get install -t bookworm-backports "
    "mesa-vulkan-drivers`, Mesa 25.0; bookworm's own Mesa 22.3 lacks descriptorBindingPartiallyBound, which "
    "SAPIEN requires); a driver outside the standard folders is chosen with VK_ICD_FILENAMES=<its icd .json>"
)

ASSET_HINT = (
    "download them with this interpreter first: `python -m mani_skill.utils.download_asset {env_id}` "
    "(or set MS_SKIP_ASSET_DOWNLOAD_PROMPT=1 to let the worker download them on first use; MS_ASSET_DIR "
    "chooses where they go)"
)


def _vulkan_icd() -> str | None:
    """Why no Vulkan driver is visible, or None when one may be (checked without loading
    one: an NVIDIA driver, an ICD file in a standard folder, or VK_ICD_FILENAMES)."""
    if os.environ.get("VK_ICD_FILENAMES") or os.environ.get("VK_DRIVER_FILES"):
        return None
    if shutil.which("nvidia-smi") is not None:
        return None  # SAPIEN supplies an NVIDIA ICD file itself when the driver has none
    data_dirs = os.environ.get("XDG_DATA_DIRS") or "/usr/local/share:/usr/share"
    folders = ["/etc/vulkan", os.path.expanduser("~/.local/share/vulkan")]
    folders += [os.path.join(d, "vulkan") for d in data_dirs.split(":") if d]
    if any(glob.glob(os.path.join(f, "icd.d", "*.json")) for f in folders):
        return None
    return "no Vulkan driver (no GPU driver's ICD file and no lavapipe, no VK_ICD_FILENAMES)"


def _no_prompt(env_id: str) -> Any:
    """ManiSkill's asset prompt, answered without a terminal: yes under
    MS_SKIP_ASSET_DOWNLOAD_PROMPT=1 (ManiSkill's own switch), else an error with the command."""

    def prompt_yes_no(message: str) -> bool:
        if os.environ.get("MS_SKIP_ASSET_DOWNLOAD_PROMPT") == "1":
            return True
        raise FileNotFoundError(f"{message.strip()} (no terminal to answer)\nhint: {ASSET_HINT.format(env_id=env_id)}")

    return prompt_yes_no


class ManiSkillAdapter(EnvAdapter):
    """ManiSkill3 tasks (`PickCube-v1`, ...) on the CPU simulator with state observations, one
    env per instance (the worker batches them); the entry's `kwargs` go to `gymnasium.make`
    (`obs_mode`, `control_mode`, `reward_mode`, `robot_uids`, ...)."""

    name = "maniskill"
    frameworks = ["maniskill"]
    requires = ["mani_skill", "sapien", "torch"]
    description = "ManiSkill3 tasks on the CPU simulator, state observations"
    install_hint = "pip install mani-skill torch  # then `python -m mani_skill.utils.download_asset <task>` if it asks"

    def availability(self) -> tuple[bool, str | None, str | None]:
        ok, reason, hint = super().availability()
        if not ok:
            return ok, reason, hint
        vulkan = _vulkan_icd()
        if vulkan is not None:
            return False, vulkan, VULKAN_HINT
        return True, None, None

    def make(self, env_id: str, config: Any) -> Any:
        import gymnasium as gym
        import mani_skill.envs  # noqa: F401 - registers the ManiSkill ids
        from mani_skill.utils import download_asset

        from .torch_to_numpy import TorchToNumpy

        kwargs = {"obs_mode": "state", "sim_backend": "cpu", **config.extra}
        num_envs = int(kwargs.pop("num_envs", 1))
        if num_envs != 1 or kwargs["sim_backend"] not in ("cpu", "physx_cpu"):
            raise NotImplementedError(
                f"`{env_id}` with num_envs={num_envs}, sim_backend={kwargs['sim_backend']!r}: the Python worker hosts "
                "one ManiSkill env per instance on the CPU simulator\n"
                "hint: use the session's `num_envs` and `num_workers` instead of `num_envs`/`sim_backend` in `extra`"
            )
        # ManiSkill asks on stdin before downloading a missing asset; a worker has no terminal.
        download_asset.prompt_yes_no = _no_prompt(env_id)
        try:
            env = gym.make(
                env_id,
                num_envs=1,
                render_mode=config.render_mode,
                max_episode_steps=config.max_episode_steps or None,
                **kwargs,
            )
        except RuntimeError as e:
            text = str(e)
            if any(s in text for s in ("vk::", "physical device", "rendering device")):
                raise RuntimeError(f"{text}\nhint: {VULKAN_HINT}") from e
            raise
        return TorchToNumpy(env, env_id)
