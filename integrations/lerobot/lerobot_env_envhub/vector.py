"""`LeRobotVectorEnv`: one envhub session per LeRobot task, with what `lerobot-eval`'s rollout
asks of a vector env (`call("_max_episode_steps")`, `call("task_description")`, `call("render")`,
`metadata["render_fps"]`, success in the step's info).

The session starts on first use and stops at `close()`, and starts again on the next use, as
LeRobot's own lazy asynchronous envs do: `lerobot-eval` closes each task's envs once it has
evaluated them, `lerobot-train` closes them after every evaluation.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from .workers import balanced_workers

#: Reset-info keys the LIBERO adapter reports its task by; LeRobot's reset info has neither.
TASK_KEYS = ("task_description", "task")
NEW_ROLLOUT_OPTION = "lerobot_new_rollout"
#: Seconds a worker may take to start (`ENVHUB_START_TIMEOUT`, where the user sets none).
START_TIMEOUT_S = 900


class LeRobotVectorEnv(gym.vector.VectorEnv):
    """`n_envs` envs of catalog entry `entry` (made with `options`) in an envhub session.

    `convert` turns the session's observations into LeRobot's layout (None: they are in it
    already, the LIBERO and Meta-World adapters'); `success_key` names the info key copied to
    `is_success` (None: the envs report `is_success` themselves); `passes_rollout_option`
    says whether the envs take LeRobot's `lerobot_new_rollout` reset option.
    """

    def __init__(
        self,
        entry: str,
        n_envs: int,
        *,
        options: dict[str, Any],
        registry: list[str],
        max_episode_steps: int | None,
        render_fps: float,
        description: str | None = None,
        name: str | None = None,
        workers: int | None = None,
        hubs: Any = None,
        step_timeout: float | None = None,
        convert: Callable[[Any], Any] | None = None,
        success_key: str | None = None,
        passes_rollout_option: bool = True,
        render: bool = True,
    ) -> None:
        self.entry = entry
        self.num_envs = int(n_envs)
        self.options = dict(options)
        self.registry = registry
        self.workers = workers
        self.step_timeout = step_timeout
        self.hubs = hubs
        self.render_mode = "rgb_array" if render else None
        self.metadata = {"render_fps": render_fps, "autoreset_mode": AutoresetMode.NEXT_STEP}
        self._max_episode_steps = max_episode_steps
        self._description = description
        self._name = name
        self._convert = convert
        self._success_key = success_key
        self._passes_rollout_option = passes_rollout_option
        self._vec: Any = None
        self._spaces: tuple[Any, Any] | None = None
        self.closed = False

    # The session ------------------------------------------------------------------------------

    def _workers(self) -> int | None:
        """`--env.workers`, else as many workers as keep this machine's cores busy through a
        batch (5 envs on 2 cores: 3 workers, not 2 of 3 and 2 envs), counting the cores this
        process may run on (a Slurm job's, not the node's). On hubs elsewhere: each
        hub's own default."""
        if self.workers or self.hubs:
            return self.workers
        from envhub.wire.cores import usable_cores

        return balanced_workers(self.num_envs, usable_cores())

    def _ensure(self) -> Any:
        if self._vec is None:
            import envhub

            # A suite's first worker in a fresh environment compiles its bytecode (LIBERO its
            # numba caches too): minutes on a busy machine, past envhub's default 120 s.
            os.environ.setdefault("ENVHUB_START_TIMEOUT", str(START_TIMEOUT_S))
            self._vec = envhub.make_vec(
                self.entry,
                self.num_envs,
                num_workers=self._workers(),
                autoreset_mode="next_step",
                render_mode=self.render_mode,
                registry=self.registry,
                hubs=self.hubs,
                step_timeout=self.step_timeout,
                **self.options,
            )
            self.closed = False
            if self._max_episode_steps is None:
                self._max_episode_steps = self._vec.max_episode_steps
            if self._max_episode_steps is None:
                raise ValueError(
                    f"`{self.entry}` has no episode limit, and LeRobot's rollout needs one\n"
                    "hint: give the entry `max_episode_steps` in a registry file (--env.registry)"
                )
        return self._vec

    def _space(self, single: bool, observation: bool) -> Any:
        if self._spaces is None:
            vec = self._ensure()
            obs = vec.single_observation_space
            if self._convert is not None:
                obs = self._convert.space(obs)  # type: ignore[attr-defined]
            self._spaces = (obs, vec.single_action_space)
        space = self._spaces[0 if observation else 1]
        return space if single else gym.vector.utils.batch_space(space, self.num_envs)

    @property
    def single_observation_space(self) -> Any:  # type: ignore[override]
        return self._space(True, True)

    @property
    def observation_space(self) -> Any:  # type: ignore[override]
        return self._space(False, True)

    @property
    def single_action_space(self) -> Any:  # type: ignore[override]
        return self._space(True, False)

    @property
    def action_space(self) -> Any:  # type: ignore[override]
        return self._space(False, False)

    # Gymnasium's VectorEnv ----------------------------------------------------------------------

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None) -> tuple[Any, dict[str, Any]]:
        vec = self._ensure()
        options = dict(options or {})
        if not self._passes_rollout_option:
            options.pop(NEW_ROLLOUT_OPTION, None)
        if seed is not None and not isinstance(seed, int):
            seed = [None if s is None else int(s) for s in seed]
        obs, info = vec.reset(seed=seed, options=options or None)
        info = dict(info)
        self._learn_task(info)
        return self._obs(obs), self._info(info)

    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self._ensure().step(actions)
        return self._obs(obs), reward, terminated, truncated, self._info(dict(info))

    def render(self) -> tuple[Any, ...] | None:
        return self._ensure().render()

    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """What LeRobot asks every env for: `_max_episode_steps`, `task_description`, `task`
        (each the same for the envs of a task) and `render`."""
        if name == "render":
            return tuple(self.render() or ())
        if name == "_max_episode_steps":
            self._ensure()
            return (self._max_episode_steps,) * self.num_envs
        if name in ("task_description", "task"):
            value = self._description if name == "task_description" else self._name
            if value is None:
                raise AttributeError(f"`{name}` of `{self.entry}` is known after the first reset")
            return (value,) * self.num_envs
        raise AttributeError(f"the envs of `{self.entry}` have no `{name}` that LeRobot's plugin serves")

    def get_attr(self, name: str) -> tuple[Any, ...]:
        return self.call(name)

    def close(self, **kwargs: Any) -> None:
        """Stops the session; the next use starts a new one."""
        if self._vec is not None:
            vec, self._vec = self._vec, None
            vec.close()
        self.closed = True

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    def __repr__(self) -> str:
        return f"<LeRobotVectorEnv {self.entry} {self.options}: {self.num_envs} envs>"

    # ---------------------------------------------------------------------------------------------

    def _learn_task(self, info: dict[str, Any]) -> None:
        """Takes the task's name and text out of a reset's info (the LIBERO adapter reports
        them there; LeRobot's envs hold them as attributes)."""
        for key in TASK_KEYS:
            values = info.pop(key, None)
            mask = info.pop(f"_{key}", None)
            if values is None:
                continue
            picked = [v for v, m in zip(values, mask if mask is not None else [True] * len(values)) if m]
            if picked and key == "task_description" and self._description is None:
                self._description = str(picked[0])
            if picked and key == "task" and self._name is None:
                self._name = str(picked[0])

    def _obs(self, obs: Any) -> Any:
        return obs if self._convert is None else self._convert(obs)

    def _info(self, info: dict[str, Any]) -> dict[str, Any]:
        if self._success_key is not None and self._success_key in info and "is_success" not in info:
            info["is_success"] = np.asarray(info[self._success_key], dtype=bool)
        return info
