"""`envhub.Env`: one environment in a worker process, as a `gymnasium.Env`."""

from __future__ import annotations

import json
from typing import Any, SupportsFloat

import gymnasium
import numpy as np

from ..wire import info_tree as _info_tree
from ..wire import spaces as _spaces
from ..wire.config import EnvConfig, to_json
from .session import RegistryArg, check_seed, fps_metadata, start

__all__ = ["Env", "TimeLimitedByGymnasium"]


class Env(gymnasium.Env[Any, Any]):
    """One env of registry entry `registry_id`, hosted by its own worker process.

    Observations are writeable numpy arrays viewing the worker's shared memory; one you keep
    stays valid and unchanged. Episodes end with `terminated` or `truncated` (the entry's `max_episode_steps`
    applies); then call `reset`. Options the env takes go in `**extra`.
    """

    # The modes envhub can carry (for `gymnasium.make`'s check before making an env); an
    # instance lists only the mode it was made with (`check_env` re-makes envs with each).
    metadata: dict[str, Any] = {"render_modes": ["rgb_array"]}

    def __init__(
        self,
        registry_id: str,
        *,
        render_mode: str | None = None,
        max_episode_steps: int | None = None,
        seed: int | None = None,
        asset_path: str | None = None,
        registry: RegistryArg = None,
        step_timeout: float | None = None,
        restart_on_crash: bool = False,
        strict_actions: bool = False,
        **extra: Any,
    ) -> None:
        config = EnvConfig(
            render_mode=render_mode,
            seed=seed,
            max_episode_steps=max_episode_steps,
            num_envs=1,
            asset_path=asset_path,
            extra=extra,
            workers=1,
            autoreset_mode="disabled",
            strict_actions=strict_actions,
        )
        self._session = start(registry_id, config, registry, step_timeout, restart_on_crash)
        s = self._session
        self._codec = _spaces.Codec(
            s.observation_space_json, s.obs_leaves_json, s.action_space_json, s.action_leaves_json, None
        )
        self.observation_space = _spaces.to_gymnasium(json.loads(s.observation_space_json))
        self.action_space = _spaces.to_gymnasium(json.loads(s.action_space_json))
        self.render_mode = render_mode
        # Render modes are known per env only once one rendered: the adapter refuses a mode
        # it cannot draw when the env is made.
        self.metadata = {
            **self.metadata,
            "render_modes": [render_mode] if render_mode else [],
            **fps_metadata(s),
        }
        self.registry_id = registry_id
        # `seed=` seeds the first reset that is not given one (RoboSmith's make_env ignores it).
        self._first_seed = check_seed(seed)

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        """Starts an episode; `seed` reseeds the env (the first reset without one uses the
        `seed` the env was made with), `options` go to the env's reset."""
        seed = check_seed(seed)
        if seed is None:
            seed, self._first_seed = self._first_seed, None
        else:
            self._first_seed = None
        super().reset(seed=seed)
        obs, info = self._session.reset_single(seed, to_json(options) if options else None)
        return self._codec.obs(obs), _info_tree.decode(info)

    def step(self, action: Any) -> tuple[Any, SupportsFloat, bool, bool, dict[str, Any]]:
        """Advances one step. A continuous action outside the action space's bounds reaches
        the env, which clips it as Gymnasium's does (an `InvalidActionError` with
        `strict_actions`); NaN, infinity, a discrete action out of range or the wrong shape
        raise `InvalidActionError`."""
        obs, reward, terminated, truncated, info = self._session.step_single(self._codec.actions(action))
        return self._codec.obs(obs), reward, terminated, truncated, _info_tree.decode(info)

    def render(self) -> np.ndarray | None:
        """The current frame as a `(height, width, 3)` uint8 array when the env was made with
        `render_mode="rgb_array"` (an env that cannot render refuses that mode when made);
        `None` otherwise."""
        if self.render_mode is None:
            return None
        return self._session.render()[0]

    def close(self) -> None:
        """Stops the worker. Arrays already returned stay valid; closing twice is fine."""
        session = getattr(self, "_session", None)
        if session is not None:
            session.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception:
            pass

    @property
    def worker_pid(self) -> int:
        """Pid of the worker process."""
        return int(self._session.worker_pids[0])

    @property
    def adapter(self) -> str:
        """The adapter running this env."""
        return str(self._session.adapter)

    @property
    def max_episode_steps(self) -> int | None:
        """The episode limit applied, if any."""
        return self._session.max_episode_steps

    def __repr__(self) -> str:
        session = getattr(self, "_session", None)
        where = f" ({session.adapter}: {session.env_id})" if session is not None else ""
        return f"<envhub.Env {getattr(self, 'registry_id', '?')}{where}>"


# The largest limit a worker takes (`max_episode_steps` is a u32): in effect none, for envs
# whose limit Gymnasium's `TimeLimit` applies instead.
_NO_LIMIT = 2**32 - 1


class TimeLimitedByGymnasium(Env):
    """`Env` as `gymnasium.make` creates it for a spec with `max_episode_steps`: `make` wraps
    it in `TimeLimit` (the spec's limit, or the one passed to `make`, or none with -1), so
    the worker applies no limit of its own and episodes truncate exactly once, where
    Gymnasium's own env would."""

    def __init__(self, registry_id: str, **kwargs: Any) -> None:
        kwargs.setdefault("max_episode_steps", _NO_LIMIT)
        super().__init__(registry_id, **kwargs)
