"""`lerobot_metaworld`: Meta-World tasks as LeRobot 0.6.1's `MetaworldEnv` presents them.

What a LeRobot policy trained on LeRobot's Meta-World data sees, made the way LeRobot makes
it (`lerobot/envs/metaworld.py`): the task's env from `metaworld.MT1(task, seed=42)` with
its first train task, the `corner2` camera moved to LeRobot's position and its frames turned
right side up (both axes flipped), goals drawn from the reset seed (`seeded_rand_vec`).
Observation `{"pixels": (480, 480, 3) uint8, "agent_pos": the first 4 state values}` (or only
`pixels` with `obs_type: pixels`); an episode ends at success, with `final_info` in the
step's info and the env reset at once, as LeRobot's does. It runs in the LeRobot plugin's
Python environment `lerobot-metaworld`, pinned as LeRobot 0.6.1's own lock pins Meta-World
(metaworld 3.0.0, mujoco 3.8.1), so the episodes are LeRobot's own.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym

from .base import EnvAdapter
from .lerobot_rollout import FrozenAfterEnd, check_unknown, take_flag

#: LeRobot moves this camera and flips its frames; other cameras are used as they are.
CORNER2 = "corner2"
CORNER2_POS = (0.75, 0.075, 0.7)
#: MT1's tasks end at 500 steps (`max_path_length`), LeRobot's `_max_episode_steps`.
MAX_EPISODE_STEPS = 500
OBS_TYPES = ("pixels", "pixels_agent_pos")
OPTIONS = ["task", "camera_name", "obs_type", "freeze_after_episode_end"]


def task_name(env_id: str) -> str:
    """`push-v3` for `push-v3` or LeRobot's `metaworld-push-v3`."""
    name = env_id.removeprefix("metaworld-")
    if not name:
        raise LookupError(f"invalid Meta-World task `{env_id}`\nhint: a task name such as `push-v3`")
    return name


class LeRobotMetaWorldAdapter(EnvAdapter):
    """Meta-World by task name (`push-v3`, or the option `task`), LeRobot's conventions. Options: `camera_name`
    (`corner2`), `obs_type` (`pixels_agent_pos` or `pixels`), `freeze_after_episode_end`
    (what `lerobot-eval` does with asynchronous envs)."""

    name = "lerobot_metaworld"
    frameworks = ["lerobot_metaworld"]
    requires = ["metaworld", "mujoco"]
    description = "Meta-World as LeRobot 0.6.1's MetaworldEnv presents it (corner2 camera, 4-d agent_pos)"
    install_hint = "it runs in the LeRobot plugin's python env `lerobot-metaworld` (integrations/lerobot)"

    def make(self, env_id: str, config: Any) -> Any:
        options = dict(config.extra)
        check_unknown(options, OPTIONS, "lerobot_metaworld")
        freeze = take_flag(options, "freeze_after_episode_end")
        if config.render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be `rgb_array` or none, not {config.render_mode!r}")
        os.environ.setdefault("MUJOCO_GL", "egl")
        env = LeRobotMetaWorldEnv(
            task_name(str(options.pop("task", env_id))),
            camera_name=str(options.get("camera_name", CORNER2)),
            obs_type=str(options.get("obs_type", "pixels_agent_pos")),
        )
        return FrozenAfterEnd(env) if freeze else env


class LeRobotMetaWorldEnv(gym.Env):
    """One Meta-World task, stepped as LeRobot's `MetaworldEnv` steps it."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 80}

    def __init__(self, task: str, camera_name: str = CORNER2, obs_type: str = "pixels_agent_pos") -> None:
        import metaworld
        import numpy as np

        if obs_type not in OBS_TYPES:
            raise ValueError(f"unknown obs_type `{obs_type}`\nhint: one of {', '.join(OBS_TYPES)}")
        benchmark = metaworld.MT1(task, seed=42)
        env = benchmark.train_classes[task](render_mode="rgb_array", camera_name=camera_name)
        env.set_task(benchmark.train_tasks[0])
        if camera_name == CORNER2:
            env.model.cam_pos[2] = list(CORNER2_POS)
        env.reset()
        # Goals drawn at every reset, from the generator the reset seed seeds.
        env._freeze_rand_vec = False
        env.seeded_rand_vec = True
        self._env = env
        self._last_frame: Any = None
        self.task = task
        self.camera_name = camera_name
        self.obs_type = obs_type
        self.render_mode = "rgb_array"
        self._max_episode_steps = MAX_EPISODE_STEPS
        height, width = int(env.height), int(env.width)
        spaces: dict[str, gym.Space] = {"pixels": gym.spaces.Box(0, 255, (height, width, 3), np.uint8)}
        if obs_type == "pixels_agent_pos":
            spaces["agent_pos"] = gym.spaces.Box(-1000.0, 1000.0, (4,), np.float64)
        self.observation_space = gym.spaces.Dict(spaces)
        self.action_space = gym.spaces.Box(-1, 1, (4,), np.float32)

    def _frame(self) -> Any:
        import numpy as np

        image = self._env.render()
        return np.flip(image, (0, 1)) if self.camera_name == CORNER2 else image

    def _obs(self, state: Any) -> dict[str, Any]:
        self._last_frame = self._frame().copy()
        obs = {"pixels": self._last_frame}
        if self.obs_type == "pixels_agent_pos":
            obs["agent_pos"] = state[:4]
        return obs

    def render(self) -> Any:
        """The frame of the last observation: the simulator has not moved since, and MuJoCo
        would draw the same pixels again (LeRobot's env draws them twice a step; software
        rendering is most of a step's cost)."""
        if self._last_frame is None:
            self._last_frame = self._frame().copy()
        return self._last_frame

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is not None:
            self._env.seed(seed)
        state, _ = self._env.reset(seed=seed)
        return self._obs(state), {"is_success": False}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if action.ndim != 1:
            raise ValueError(f"expected a 1-d action, got shape {action.shape}")
        state, reward, done, truncated, info = self._env.step(action)
        success = bool(info.get("success", 0))
        terminated = done or success
        info.update({"task": self.task, "done": done, "is_success": success})
        obs = self._obs(state)
        if terminated:
            info["final_info"] = {"task": self.task, "done": bool(done), "is_success": success}
            self.reset()
        return obs, reward, terminated, truncated, info

    def close(self) -> None:
        self._env.close()
