"""`lerobot_libero`: LIBERO tasks as LeRobot 0.6.1's `LiberoEnv` presents them.

What a LeRobot policy trained on LeRobot's LIBERO data sees, made the way LeRobot makes it
(`lerobot/envs/libero.py`): LIBERO's `OffScreenRenderEnv` at LeRobot's camera size and
control rate, reset once when made; every reset seeds it, resets it (a hard reset, rebuilding
the scene, unless `hard_reset: false`), sets the task's fixed initial state number
`init_state_id` (env `i` of `n` starts at `i` and moves on by `n` at each reset), then takes 10
settling steps with `[0, 0, 0, 0, 0, 0, -1]` and sets the controller to relative or absolute
actions. Observation `{"pixels": {"image": agentview, "image2": wrist}, "robot_state": {"eef":
{pos, quat, mat}, "gripper": {qpos, qvel}, "joints": {pos, vel}}}`, images as robosuite
renders them (LeRobot's `LiberoProcessorStep` turns them upright in the policy's process);
the reset's info also carries the task's `task` and `task_description`; an episode ends at
success (`is_success` in every step's info) and is never truncated here:
LeRobot's rollout stops at the suite's horizon (`TASK_SUITE_MAX_STEPS`).

It runs in the LeRobot plugin's Python environment `lerobot-libero`, pinned as
`lerobot[libero]==0.6.1` installs LIBERO (hf-libero 0.1.4, robosuite 1.4.0, mujoco 3.8.1,
numpy 2.2.6, CPython 3.12), with the `libero` adapter's asset set-up and its caches of what a
hard reset rebuilds (the same observations, checked in tests/python/pyenv/test_suites.py).
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym

from .base import EnvAdapter
from .lerobot_rollout import FrozenAfterEnd, check_unknown, take_flag

#: LeRobot's horizons per suite (`TASK_SUITE_MAX_STEPS`; 500 for any other).
MAX_EPISODE_STEPS = {"libero_spatial": 280, "libero_object": 280, "libero_goal": 300, "libero_10": 520, "libero_90": 400}
DEFAULT_MAX_EPISODE_STEPS = 500
SETTLE_STEPS = 10
SETTLE_ACTION = (0, 0, 0, 0, 0, 0, -1)
CAMERAS = "agentview_image,robot0_eye_in_hand_image"
CAMERA_NAME_MAPPING = {"agentview_image": "image", "robot0_eye_in_hand_image": "image2"}
CONTROL_MODES = ("relative", "absolute")
OBS_TYPES = ("pixels", "pixels_agent_pos")
OPTIONS = [
    "suite",
    "task",
    "camera_name",
    "camera_name_mapping",
    "obs_type",
    "observation_height",
    "observation_width",
    "control_freq",
    "control_mode",
    "init_states",
    "hard_reset",
    "episode_length",
    "n_envs",
    "freeze_after_episode_end",
]


def cameras(value: Any) -> list[str]:
    """LeRobot's camera list from `a,b` or a list."""
    names = value.split(",") if isinstance(value, str) else list(value)
    names = [str(n).strip() for n in names if str(n).strip()]
    if not names:
        raise ValueError("camera_name names no camera")
    return names


def max_episode_steps(suite: str, episode_length: int | None) -> int:
    return MAX_EPISODE_STEPS.get(suite, DEFAULT_MAX_EPISODE_STEPS) if episode_length is None else int(episode_length)


class LeRobotLiberoAdapter(EnvAdapter):
    """A LIBERO task by suite (`libero_spatial`, or the option `suite`) and the option `task`
    (an index), LeRobot's conventions. Options as LeRobot's `LiberoEnv` config: `observation_height`/`_width`
    (360), `control_freq` (20), `camera_name`, `camera_name_mapping`, `obs_type`,
    `init_states`, `hard_reset`, `control_mode`, `episode_length`; `n_envs` (the session's
    envs: the stride of `init_state_id`) and `freeze_after_episode_end`."""

    name = "lerobot_libero"
    frameworks = ["lerobot_libero"]
    requires = ["libero", "robosuite", "bddl", "torch"]
    description = "LIBERO as LeRobot 0.6.1's LiberoEnv presents it (init states, settling steps, nested observation)"
    install_hint = "it runs in the LeRobot plugin's python env `lerobot-libero` (integrations/lerobot)"

    def availability(self) -> tuple[bool, str | None, str | None]:
        from .libero import LiberoAdapter

        return LiberoAdapter().availability()

    def make(self, env_id: str, config: Any) -> Any:
        options = dict(config.extra)
        check_unknown(options, OPTIONS, "lerobot_libero")
        freeze = take_flag(options, "freeze_after_episode_end")
        if config.render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode must be `rgb_array` or none, not {config.render_mode!r}")
        suite, sep, in_id = env_id.partition("/")
        suite = str(options.pop("suite", suite))
        task = options.pop("task", int(in_id) if sep and in_id.isdigit() else 0)
        if isinstance(task, bool) or not isinstance(task, int):
            raise TypeError(f"option `task` must be a task index, not {task!r}")
        n_envs = options.pop("n_envs", config.num_envs)
        env = LeRobotLiberoEnv(suite, task, episode_index=int(config.env_index or 0), n_envs=int(n_envs), **options)
        return FrozenAfterEnd(env) if freeze else env


def _suite(name: str) -> Any:
    from libero.libero import benchmark

    suites = benchmark.get_benchmark_dict()
    if name not in suites:
        raise LookupError(f"LIBERO has no suite `{name}`\nhint: suites: {', '.join(sorted(suites))}")
    return suites[name]()


def _init_states(suite: Any, task_id: int) -> Any:
    """The task's fixed initial states, read from LIBERO's files as LeRobot reads them."""
    from pathlib import Path

    import torch
    from libero.libero import get_libero_path

    task = suite.tasks[task_id]
    path = Path(get_libero_path("init_states")) / task.problem_folder / Path(task.init_states_file).name
    return torch.load(path, weights_only=False)  # LIBERO's own files (numpy arrays pickled)


class LeRobotLiberoEnv(gym.Env):
    """One LIBERO task, reset and stepped as LeRobot's `LiberoEnv`."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 80}

    def __init__(
        self,
        suite_name: str,
        task_id: int,
        *,
        episode_index: int = 0,
        n_envs: int = 1,
        camera_name: Any = CAMERAS,
        camera_name_mapping: dict[str, str] | None = None,
        obs_type: str = "pixels_agent_pos",
        observation_height: int = 360,
        observation_width: int = 360,
        control_freq: int = 20,
        control_mode: str = "relative",
        init_states: bool = True,
        hard_reset: bool = True,
        episode_length: int | None = None,
    ) -> None:
        import numpy as np

        from . import render_contexts, sensor_checks
        from .libero import ensure_config, use_assets

        if obs_type not in OBS_TYPES:
            raise ValueError(f"unknown obs_type `{obs_type}`\nhint: one of {', '.join(OBS_TYPES)}")
        if control_mode not in CONTROL_MODES:
            raise ValueError(f"unknown control_mode `{control_mode}`\nhint: one of {', '.join(CONTROL_MODES)}")
        if control_freq <= 0:
            raise ValueError(f"control_freq must be positive, got {control_freq}")
        if not hard_reset and not init_states:
            raise ValueError("hard_reset: false needs init_states: true")
        os.environ.setdefault("MUJOCO_GL", "egl")
        os.environ.setdefault("PYOPENGL_PLATFORM", os.environ["MUJOCO_GL"])
        ensure_config()
        use_assets()
        from libero.libero import get_libero_path
        from libero.libero.envs import OffScreenRenderEnv

        # What a hard reset rebuilds, kept (the same observations; see the `libero` adapter).
        render_contexts.install(scenes_repeat=True)
        sensor_checks.install()
        sensor_checks.freeze_imports()

        suite = _suite(suite_name)
        if not 0 <= task_id < len(suite.tasks):
            raise LookupError(f"LIBERO suite `{suite_name}` has no task {task_id}\nhint: tasks 0..{len(suite.tasks) - 1}")
        task = suite.get_task(task_id)
        self.task_id = task_id
        self.task = task.name
        self.task_description = task.language
        self.camera_name = cameras(camera_name)
        self.camera_name_mapping = dict(camera_name_mapping or CAMERA_NAME_MAPPING)
        missing = [c for c in self.camera_name if c not in self.camera_name_mapping]
        if missing:
            raise ValueError(f"camera_name_mapping names no image for {missing}")
        self.obs_type = obs_type
        self.control_mode = control_mode
        self.render_mode = "rgb_array"
        self._init_states = _init_states(suite, task_id) if init_states else None
        self.init_state_id = episode_index
        self._stride = n_envs
        self._max_episode_steps = max_episode_steps(suite_name, episode_length)
        bddl = os.path.join(get_libero_path("bddl_files"), task.problem_folder, task.bddl_file)
        self._env = OffScreenRenderEnv(
            bddl_file_name=bddl,
            camera_heights=observation_height,
            camera_widths=observation_width,
            control_freq=control_freq,
            hard_reset=hard_reset,
        )
        self._env.reset()

        image = gym.spaces.Box(0, 255, (observation_height, observation_width, 3), np.uint8)
        spaces: dict[str, gym.Space] = {
            "pixels": gym.spaces.Dict({self.camera_name_mapping[c]: image for c in self.camera_name})
        }
        if obs_type == "pixels_agent_pos":

            def vec(*shape: int) -> gym.Space:
                return gym.spaces.Box(-np.inf, np.inf, shape, np.float64)

            spaces["robot_state"] = gym.spaces.Dict(
                {
                    "eef": gym.spaces.Dict({"pos": vec(3), "quat": vec(4), "mat": vec(3, 3)}),
                    "gripper": gym.spaces.Dict({"qpos": vec(2), "qvel": vec(2)}),
                    "joints": gym.spaces.Dict({"pos": vec(7), "vel": vec(7)}),
                }
            )
        self.observation_space = gym.spaces.Dict(spaces)
        self.action_space = gym.spaces.Box(-1.0, 1.0, (7,), np.float32)

    def _obs(self, raw: dict[str, Any]) -> dict[str, Any]:
        images = {self.camera_name_mapping[c]: raw[c] for c in self.camera_name}
        if self.obs_type == "pixels":
            return {"pixels": images}
        return {
            "pixels": images,
            "robot_state": {
                "eef": {
                    "pos": raw["robot0_eef_pos"],
                    "quat": raw["robot0_eef_quat"],
                    "mat": self._env.robots[0].controller.ee_ori_mat,
                },
                "gripper": {"qpos": raw["robot0_gripper_qpos"], "qvel": raw["robot0_gripper_qvel"]},
                "joints": {"pos": raw["robot0_joint_pos"], "vel": raw["robot0_joint_vel"]},
            },
        }

    def render(self) -> Any:
        """The first camera's image, both axes flipped (LeRobot's video frames)."""
        raw = self._env.env._get_observations()
        return raw[self.camera_name[0]][::-1, ::-1]

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self._env.seed(seed)
        raw = self._env.reset()
        if self._init_states is not None:
            raw = self._env.set_init_state(self._init_states[self.init_state_id % len(self._init_states)])
            self.init_state_id += self._stride
        for _ in range(SETTLE_STEPS):
            raw, _, _, _ = self._env.step(list(SETTLE_ACTION))
        for robot in self._env.robots:
            robot.controller.use_delta = self.control_mode == "relative"
        # LeRobot's reset info is `{"is_success": False}`; the task's name and text ride along
        # for the LeRobot plugin, whose interpreter has no LIBERO to read them from.
        return self._obs(raw), {"is_success": False, "task": self.task, "task_description": self.task_description}

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        if action.ndim != 1:
            raise ValueError(f"expected a 1-d action, got shape {action.shape}")
        raw, reward, done, info = self._env.step(action)
        success = self._env.check_success()
        info.update({"task": self.task, "task_id": self.task_id, "done": done, "is_success": success})
        return self._obs(raw), reward, done or success, False, info

    def close(self) -> None:
        self._env.close()
