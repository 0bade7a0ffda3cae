"""`--env.type=envhub`: LeRobot's `EnvConfig` for envhub's catalog.

For LIBERO and Meta-World the features, `features_map`, frame rate, horizons and env
processors are those of LeRobot's own `LiberoEnv` / `MetaworldEnv` configs, made with the same
settings (the configs import nothing of the suites); for any other entry they follow from the
entry's observation space (see `convert.py`), read from a one-env session.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig, LiberoEnv, MetaworldEnv
from lerobot.utils.constants import ACTION

from . import tasks as _tasks
from .convert import Converter
from .vector import LeRobotVectorEnv

__all__ = ["EnvhubEnv"]


@EnvConfig.register_subclass("envhub")
@dataclass
class EnvhubEnv(EnvConfig):
    """`--env.task`: a LIBERO suite (`libero_spatial` or the catalog's `libero-spatial`;
    comma-separated for several), Meta-World tasks (`push-v3`, a catalog entry such as
    `metaworld-push`, LeRobot's difficulty groups `easy` ... or the catalog's `metaworld-mt10`),
    or any other catalog entry or benchmark (`mujoco-hopper`, `dm-control`).

    `--env.hub`: where the envs run (`local`, `all` live hubs, or hub names, comma-separated);
    `--env.workers`: worker processes per task (default: at least one per core, at most one
    per env, as many as keep every core busy through a batch: 5 envs on 2 cores get 3);
    `--env.step_timeout`: seconds a reset or step may take before its worker counts as hung;
    `--env.registry`: more registry files. The LIBERO options are LeRobot's `LiberoEnv`'s;
    `--env.episode_length` (where the rollout stops) applies to every suite."""

    task: str | None = None
    fps: int = 0  # 0: the suite's (LIBERO 20, Meta-World 80, an entry's render_fps)
    hub: str | None = None
    workers: int | None = None
    # Seconds a reset or step may take before its worker counts as hung (LIBERO's hard resets
    # of several envs per worker take tens of seconds on a busy machine; LeRobot's own envs
    # have no bound).
    step_timeout: float = 600.0
    registry: list[str] = field(default_factory=list)
    # LeRobot's LIBERO options (the same names and defaults as its `LiberoEnv`).
    task_ids: list[int] | None = None
    episode_length: int | None = None
    obs_type: str = "pixels_agent_pos"
    camera_name: str = "agentview_image,robot0_eye_in_hand_image"
    init_states: bool = True
    hard_reset: bool = True
    camera_name_mapping: dict[str, str] | None = None
    observation_height: int = 360
    observation_width: int = 360
    control_mode: str = "relative"

    def __post_init__(self) -> None:
        self._plan: _tasks.Plan | None = None
        self._converter: Converter | None = None
        if self.episode_length is not None and (isinstance(self.episode_length, bool) or self.episode_length <= 0):
            raise ValueError(f"--env.episode_length must be a positive number of steps; got {self.episode_length}")
        if not self.task:
            return
        plan = self.plan()
        if plan.kind == "libero":
            own = self._lerobot_libero()
        elif plan.kind == "metaworld":
            own = MetaworldEnv(obs_type=self.obs_type)
        else:
            own = None
        if own is not None:
            self.features = dict(own.features)
            self.features_map = dict(own.features_map)
            self.fps = self.fps or own.fps
            return
        first = next(iter(plan.groups.values()))[0]
        probe = self._session(first, 1, use_async=False, render=False)
        try:
            self._converter = Converter(probe._ensure().single_observation_space)
            action = probe._ensure().single_action_space
            fps = probe._ensure().metadata.get("render_fps")
        finally:
            probe.close()
        features, mapping = self._converter.features()
        self.features = {ACTION: PolicyFeature(type=FeatureType.ACTION, shape=tuple(action.shape)), **features}
        self.features_map = mapping
        self.fps = self.fps or int(round(fps or 30))

    def _lerobot_libero(self) -> LiberoEnv:
        return LiberoEnv(
            task=self.task or "libero_10",
            task_ids=self.task_ids,
            fps=self.fps or 20,
            episode_length=self.episode_length,
            obs_type=self.obs_type,
            camera_name=self.camera_name,
            init_states=self.init_states,
            hard_reset=self.hard_reset,
            camera_name_mapping=self.camera_name_mapping,
            observation_height=self.observation_height,
            observation_width=self.observation_width,
            control_mode=self.control_mode,
        )

    def plan(self) -> _tasks.Plan:
        if getattr(self, "_plan", None) is None:
            from envhub.evaluation.catalog import Catalog

            self._plan = _tasks.resolve(self.task, Catalog(self.registry_files()), self.task_ids)
        return self._plan  # type: ignore[return-value]

    def registry_files(self) -> list[str]:
        return _tasks.registry_files(list(self.registry))

    @property
    def gym_kwargs(self) -> dict[str, Any]:
        return {}

    def _hubs(self) -> Any:
        if not self.hub:
            return None
        names = [h.strip() for h in self.hub.split(",") if h.strip()]
        return names[0] if names == ["all"] else names

    def _session(self, task: _tasks.Task, n_envs: int, use_async: bool, render: bool = True) -> LeRobotVectorEnv:
        """One task's vector env. LeRobot freezes an ended episode's env with asynchronous envs
        of more than one env (`_LazyAsyncVectorEnv`), and not otherwise: the adapters do the
        same, so every later reset starts where LeRobot's would."""
        kind = self.plan().kind
        freeze = use_async and n_envs > 1
        options = dict(task.options)
        common = dict(
            registry=self.registry_files(),
            workers=self.workers,
            hubs=self._hubs(),
            step_timeout=self.step_timeout,
            description=task.description,
            name=task.name,
            render=render,
        )
        if kind == "libero":
            options.update(
                n_envs=n_envs,
                camera_name=self.camera_name,
                obs_type=self.obs_type,
                observation_height=self.observation_height,
                observation_width=self.observation_width,
                control_freq=self.fps or 20,
                control_mode=self.control_mode,
                init_states=self.init_states,
                hard_reset=self.hard_reset,
                episode_length=self.episode_length,
                freeze_after_episode_end=freeze,
            )
            if self.camera_name_mapping is not None:
                options["camera_name_mapping"] = dict(self.camera_name_mapping)
            from envhub.worker.hosted.lerobot_libero import max_episode_steps

            steps = max_episode_steps(options["suite"], self.episode_length)
            return LeRobotVectorEnv(
                task.entry, n_envs, options=options, max_episode_steps=steps, render_fps=80, **common
            )
        if kind == "metaworld":
            options.update(obs_type=self.obs_type, freeze_after_episode_end=freeze)
            return LeRobotVectorEnv(
                task.entry, n_envs, options=options, max_episode_steps=self._horizon(task), render_fps=80, **common
            )
        return LeRobotVectorEnv(
            task.entry,
            n_envs,
            options=options,
            max_episode_steps=self._horizon(task),
            render_fps=self.fps or 30,
            convert=self._converter,
            success_key="success",
            passes_rollout_option=False,
            **common,
        )

    def _horizon(self, task: _tasks.Task) -> int | None:
        """Where LeRobot's rollout stops: `--env.episode_length` (LeRobot's LIBERO option,
        taken for every suite here), else the task's own horizon."""
        return task.max_episode_steps if self.episode_length is None else int(self.episode_length)

    def create_envs(self, n_envs: int, use_async_envs: bool = False) -> dict[str, dict[int, Any]]:
        """`{group: {task_id: vector env}}`, one envhub session per task, started on first use."""
        if not self.task:
            raise ValueError("--env.task is required with --env.type=envhub")
        if not isinstance(n_envs, int) or n_envs <= 0:
            raise ValueError(f"n_envs must be a positive int; got {n_envs}")
        out: dict[str, dict[int, Any]] = {}
        for group, group_tasks in self.plan().groups.items():
            ids = self.task_ids if self.plan().kind == "libero" and self.task_ids is not None else None
            numbers = sorted({int(t) for t in ids}) if ids is not None else list(range(len(group_tasks)))
            out[group] = {
                number: self._session(task, n_envs, use_async_envs) for number, task in zip(numbers, group_tasks)
            }
        return out

    def get_env_processors(self) -> Any:
        if self.task and self.plan().kind == "libero":
            return self._lerobot_libero().get_env_processors()
        return super().get_env_processors()
