"""Stable-Baselines3: envhub's vector envs as an SB3 `VecEnv`.

    import envhub.sb3
    from stable_baselines3 import PPO
    PPO("MlpPolicy", envhub.sb3.make_vec("mujoco-ant", 8)).learn(100_000)

SB3 is imported only here, and only when it is installed: `import envhub` never needs it.
With SB3 installed the object is a `stable_baselines3.common.vec_env.VecEnv` (so SB3 uses it
as it is, and its wrappers such as `VecMonitor` and `VecNormalize` apply); without it, the
same methods on a plain object (`VecAdapter`), which is how envhub's tests check the contract
on a machine without SB3 (and torch).

SB3's contract, as its `DummyVecEnv` keeps it: `reset()` returns only the observations (infos
in `reset_infos`); `step_wait()` returns observations, float32 rewards, `dones`
(terminated or truncated) and one info dict per env, with `TimeLimit.truncated` always and,
for a finished env, `terminal_observation` (its last observation; the returned one is
already the next episode's first). envhub's session runs in `same_step` autoreset mode for
this, so nothing is stepped twice.
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from typing import Any

import numpy as np

from .client.vector import VectorEnv
from .wire.batched import env_info as _env_info
from .wire.batched import env_value as _env_value
from .wire.errors import InvalidConfigError, InvalidStateError

__all__ = ["VecAdapter", "make_vec", "wrap"]


class VecAdapter:
    """SB3's `VecEnv` methods over an envhub vector env made with `autoreset_mode="same_step"`
    (`make_vec` makes one). Without SB3 installed this is a plain object with the same
    methods; `make_vec` returns a subclass that is also SB3's `VecEnv` when SB3 is there."""

    def __init__(self, venv: VectorEnv) -> None:
        from gymnasium.vector import AutoresetMode

        if venv.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise InvalidConfigError(
                f"SB3 resets a finished env in the step that ends it, but this vector env autoresets "
                f"`{venv.metadata.get('autoreset_mode')}`\nhint: make it with autoreset_mode=\"same_step\" "
                "(envhub.sb3.make_vec does)"
            )
        self.venv = venv
        self.num_envs = int(venv.num_envs)
        self.observation_space = venv.single_observation_space
        self.action_space = venv.single_action_space
        self.render_mode = venv.render_mode
        self.reset_infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        self._seeds: list[int | None] = [None] * self.num_envs
        self._options: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        self._actions: Any = None

    # SB3's VecEnv ----------------------------------------------------------------------------

    def reset(self) -> Any:
        """Resets every env (with the seeds of `seed()` and options of `set_options()`, each
        used once); returns the observations, infos go to `reset_infos`."""
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = self._options[0] if self._options else {}
        if any(o != options for o in self._options):
            raise InvalidConfigError(
                "envhub resets every env with the same options, but `set_options` gave them different ones\n"
                "hint: pass one dict to `set_options` (it applies to every env)"
            )
        obs, info = self.venv.reset(seed=seeds, options=options or None)
        self.reset_infos = [_env_info(info, i) for i in range(self.num_envs)]
        self._seeds = [None] * self.num_envs
        self._options = [{} for _ in range(self.num_envs)]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Records the actions `step_wait` steps the envs with."""
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """Steps every env: observations, rewards, dones, one info dict per env."""
        if self._actions is None:
            raise InvalidStateError("`step_wait` without a prior `step_async`")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, info = self.venv.step(actions)
        dones = terminated | truncated
        n = self.num_envs
        if not info:
            infos = [{} for _ in range(n)]
        elif "_final_obs" in info:
            # same_step: the finished envs' step infos are in `final_info`; the rest of their
            # info is the new episode's reset info.
            finished = info["_final_obs"]
            infos = []
            for i in range(n):
                if finished[i]:
                    step_info = _env_info(info["final_info"], i) if "final_info" in info else {}
                    step_info["terminal_observation"] = _env_value(info["final_obs"], i)
                    self.reset_infos[i] = _env_info(info, i, skip=("final_obs", "final_info"))
                    infos.append(step_info)
                else:
                    infos.append(_env_info(info, i, skip=("final_obs", "final_info")))
        else:
            infos = [_env_info(info, i) for i in range(n)]
        for i in range(n):
            infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            if dones[i] and "terminal_observation" not in infos[i]:
                raise InvalidStateError(
                    f"env {i} finished without its final observation; this session cannot give SB3 "
                    "its `terminal_observation`\nhint: use envhub.sb3.make_vec"
                )
        return obs, rewards.astype(np.float32), dones, infos

    def step(self, actions: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """`step_async` then `step_wait`."""
        self.step_async(actions)
        return self.step_wait()

    def seed(self, seed: int | None = None) -> Sequence[int | None]:
        """Seeds the next `reset`: env `i` with `seed + i` (a random `seed` if None)."""
        if seed is None:
            seed = int(np.random.randint(0, np.iinfo(np.uint32).max, dtype=np.uint32))
        self._seeds = [seed + i for i in range(self.num_envs)]
        return self._seeds

    def set_options(self, options: list[dict[str, Any]] | dict[str, Any] | None = None) -> None:
        """Options for the next `reset` (one dict for every env)."""
        if options is None:
            options = {}
        self._options = [dict(o) for o in options] if isinstance(options, list) else [dict(options)] * self.num_envs

    def close(self) -> None:
        """Stops the workers."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """The attribute of each env of `indices`: any attribute over
        `envhub.AsyncVectorEnv`; else `render_mode`, `metadata`, `observation_space`,
        `action_space` (known to this process), others raising `AttributeError`, as SB3
        expects of an attribute the envs lack."""
        if hasattr(self.venv, "call"):  # envhub.AsyncVectorEnv reaches its envs
            values = self.venv.get_attr(attr_name)
            return [values[i] for i in self._indices(indices)]
        known = {
            "render_mode": self.venv.render_mode,
            "metadata": self.venv.metadata,
            "observation_space": self.observation_space,
            "action_space": self.action_space,
        }
        if attr_name not in known:
            raise AttributeError(
                f"`get_attr({attr_name!r})`: envhub's envs live in worker processes, which exchange only "
                f"reset, step and render with this process; known here: {', '.join(known)}"
            )
        return [known[attr_name] for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Sets the attribute of the envs of `indices` (over `envhub.AsyncVectorEnv`;
        refused otherwise: the envs live in worker processes)."""
        if hasattr(self.venv, "call"):
            chosen = set(self._indices(indices))
            current = self.venv.get_attr(attr_name) if len(chosen) < self.num_envs else [None] * self.num_envs
            self.venv.set_attr(attr_name, [value if i in chosen else current[i] for i in range(self.num_envs)])
            return
        raise InvalidStateError(
            f"`set_attr({attr_name!r})` cannot reach envhub's envs (they live in worker processes)\n"
            "hint: pass the value as an env option when making the vector env"
        )

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
        """Calls the method of the envs of `indices` (over `envhub.AsyncVectorEnv`; else
        `render` only)."""
        if hasattr(self.venv, "call"):
            values = self.venv.call(method_name, *args, **kwargs)
            return [values[i] for i in self._indices(indices)]
        if method_name == "render":
            frames = self.venv.render() or (None,) * self.num_envs
            return [frames[i] for i in self._indices(indices)]
        raise InvalidStateError(
            f"`env_method({method_name!r})` cannot reach envhub's envs: their workers exchange only reset, "
            "step and render with this process\nhint: do the work inside the env and report it in `info`"
        )

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        """False for each env: SB3's wrappers never reach envhub's workers."""
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """One RGB frame per env (`render_mode="rgb_array"`)."""
        if self.venv.render_mode != "rgb_array":
            warnings.warn(f"the render mode is {self.venv.render_mode}, not rgb_array: no images", stacklevel=2)
            return [None] * self.num_envs
        return list(self.venv.render() or [None] * self.num_envs)

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    @property
    def unwrapped(self) -> VecAdapter:
        return self

    def __repr__(self) -> str:
        return f"envhub.sb3 VecEnv over {self.venv!r}"


_SB3_CLASS: type | None = None


def _sb3_class() -> type | None:
    """`VecAdapter` that is also SB3's `VecEnv`, or None without SB3."""
    global _SB3_CLASS
    if _SB3_CLASS is None:
        try:
            from stable_baselines3.common.vec_env import VecEnv as SB3VecEnv
        except ImportError:
            return None

        class VecEnv(VecAdapter, SB3VecEnv):
            """An envhub vector env as SB3's `VecEnv`."""

            def __init__(self, venv: VectorEnv) -> None:
                VecAdapter.__init__(self, venv)
                SB3VecEnv.__init__(self, self.num_envs, self.observation_space, self.action_space)

            def render(self, mode: str | None = None) -> Any:
                return SB3VecEnv.render(self, mode)

        VecEnv.__module__ = __name__
        _SB3_CLASS = VecEnv
    return _SB3_CLASS


def wrap(venv: VectorEnv) -> VecAdapter:
    """An envhub vector env (made with `autoreset_mode="same_step"`) as SB3's `VecEnv`
    (a plain `VecAdapter` when SB3 is not installed)."""
    cls = _sb3_class() or VecAdapter
    return cls(venv)


def make_vec(id: str, num_envs: int, num_workers: int | None = None, **kwargs: Any) -> VecAdapter:
    """`num_envs` envs of registry entry `id` as SB3's `VecEnv` (options as
    `envhub.make_vec`'s, except `autoreset_mode`, which SB3 fixes to `same_step`)."""
    if "autoreset_mode" in kwargs:
        raise InvalidConfigError("SB3 fixes the autoreset mode (`same_step`); leave `autoreset_mode` out")
    return wrap(VectorEnv(id, num_envs, num_workers, "same_step", **kwargs))
